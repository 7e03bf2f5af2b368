"""Codec benchmark: KVP frames encoded+decoded per second, KRL E6POS parsed+formatted per second.

* Frames: one client-side exchange = ``encode_read`` of ``$POS_ACT`` + ``decode_reply`` of its
  E6POS reply; the peer is py-openshowvar's own codec on the same bytes
  (``_pack_read_req`` + ``_read_rsp``, what its ``read`` does around the socket calls).
* KRL: ``parse_value(text, "E6POS")`` + ``format_value`` of the result (KRC4-exact text). No peer:
  py-openshowvar and JOpenShowVar hand back raw text.

    .venv/bin/python bench/codec.py [--quick] [--repeat 5]
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import Row, median, repeat_main

from pyopenshowvar.krl import format_value, parse_value
from pyopenshowvar.protocol import Mode, Reply, decode_reply, encode_read, encode_reply

try:
    import py_openshowvar
except ImportError:  # optional peer
    py_openshowvar = None

E6POS = (
    "{E6POS: X 525.000000, Y 0.0, Z 890.000000, A 0.0, B 90.0000000, C 0.0, S 2, T 2, "
    "E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)


def _rate(fn: Callable[[], object], seconds: float) -> float:
    fn()
    n = 0
    t0 = time.perf_counter()
    while True:
        for _ in range(100):
            fn()
        n += 100
        dt = time.perf_counter() - t0
        if dt >= seconds:
            return n / dt


def run(quick: bool, repeat: int) -> tuple[list[Row], dict[str, Any]]:
    seconds = 0.05 if quick else 0.5
    reply_frame = encode_reply(Reply(7, Mode.READ, E6POS.encode("latin-1")))

    def ours_frames() -> None:
        encode_read(7, "$POS_ACT")
        decode_reply(reply_frame)

    peer_fn: Callable[[], object] | None = None
    if py_openshowvar is not None:
        peer = py_openshowvar.openshowvar.__new__(py_openshowvar.openshowvar)  # no socket
        peer.varname = b"$POS_ACT"

        def peer_frames() -> None:
            peer.msg_id = 7
            peer._pack_read_req()
            peer.rsp = reply_frame
            peer._read_rsp(False)

        peer_fn = peer_frames

    def krl() -> None:
        format_value(parse_value(E6POS, "E6POS"))

    ours, theirs, krl_rates = [], [], []
    for _ in range(repeat):
        ours.append(_rate(ours_frames, seconds))
        if peer_fn is not None:
            theirs.append(_rate(peer_fn, seconds))
        krl_rates.append(_rate(krl, seconds))
    rows = [
        Row(
            "frames: read request encoded + E6POS reply decoded",
            median(ours),
            "exchanges/s",
            peer=median(theirs) if theirs else None,
            peer_name="py-openshowvar codec",
            runs=ours,
            note="" if theirs else "py-openshowvar not installed: peer skipped",
        ),
        Row(
            "KRL: E6POS text parsed + formatted (KRC4-exact)",
            median(krl_rates),
            "values/s",
            runs=krl_rates,
            note="no peer: py-openshowvar / JOpenShowVar return raw text",
        ),
    ]
    return rows, {}


def main() -> None:
    repeat_main(__doc__, "Codec (median of {repeat} runs)", "codec", run, repeat=5)


if __name__ == "__main__":
    main()
