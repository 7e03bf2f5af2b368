"""Soak: 10 clients at full speed plus one abusive client against the emulator, for 10 minutes.

The emulator (``bench/_emu_server.py``: ``kukavarproxy-emu`` options, the simulated robot
running its default program) runs in its own process. Around it, each in its own process:

* 10 well-behaved clients at full speed, 16 requests in flight each: every batch writes the
  client's own INT variable and reads it back, and reads ``$OV_PRO``, ``$AXIS_ACT``,
  ``$POS_ACT`` and ``$TORQUE_AXIS_ACT[3]``; every reply's id, status and (where known) value
  is checked;
* one abusive client that takes turns, ``--turn`` seconds each, at the abusers of
  :mod:`kukavarproxy_emu.abuse`: garbage frames, a client that never reads its replies, reads
  of distinct 65 000-character names, pipelined write/whole-array-read pairs, 64 KB mode-3
  frames;
* the bystander (:func:`kukavarproxy_emu.abuse.run_probe`): one request at a time, every 5 ms,
  each timed and its value checked.

Printed: emulator RSS at the start (warmed up, load not yet running), its maximum while
sampled every 10 s, and at the end; bystander p50/p99/max; wrong values; requests served
(emulator counter) and IPO tick lateness. Like every benchmark it asserts nothing.

    .venv/bin/python bench/soak.py                 # 10 minutes
    .venv/bin/python bench/soak.py --seconds 60    # shorter
    .venv/bin/python bench/soak.py --quick         # 6 s smoke run, numbers meaningless
"""

from __future__ import annotations

import asyncio
import multiprocessing as mp
import socket
import sys
import tempfile
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import EmuProcess, Row, base_parser, machine_info, print_rows, write_json

from kukavarproxy_emu.abuse import (
    AbuseTally,
    costly_pipeline,
    garbage,
    long_names,
    mode3_flood,
    non_reader,
    run_probe,
)
from pyopenshowvar.protocol import ReplyDecoder, encode_read, encode_write

CLIENTS = 10
DEPTH = 16
READS = ("$OV_PRO", "$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[3]")
CONFIG = (
    "DEFDAT $CONFIG\nDECL INT ABUSE_PROBE=0\nDECL INT ABUSE_WORDS[32000]\n"
    + "".join(f"DECL INT SOAK_{i}=0\n" for i in range(CLIENTS))
    + "ENDDAT\n"
)


def _worker(host: str, port: int, index: int, seconds: float, out: Any) -> None:
    """One full-speed client: DEPTH requests per batch, every reply checked."""
    sock = socket.create_connection((host, port), timeout=10)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    decoder = ReplyDecoder()
    var = f"SOAK_{index}"
    done = wrong = 0
    n = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        n += 1
        value = str(n)
        frames = [encode_write(0, var, value), encode_read(1, var)]
        frames += [encode_read(k, READS[k % len(READS)]) for k in range(2, DEPTH)]
        sock.sendall(b"".join(frames))
        replies: list[Any] = []
        while len(replies) < DEPTH:
            data = sock.recv(262_144)
            if not data:
                raise ConnectionError("closed by the emulator")
            replies.extend(decoder.feed_replies(data))
        for k, reply in enumerate(replies):
            bad = reply.msg_id != k or not reply.ok
            if k < 2 or READS[k % len(READS)] == "$OV_PRO":
                bad = bad or reply.text != (value if k < 2 else "100")
            wrong += bad
        done += DEPTH
    sock.close()
    out.put((done, wrong))


def _abuser(host: str, port: int, seconds: float, turn: float, out: Any) -> None:
    """The abusive client: each kind of abuse for ``turn`` seconds, round robin."""

    def words(h: str, p: int, t: AbuseTally) -> Any:
        return mode3_flood(h, p, t, name="ABUSE_WORDS")

    kinds = [garbage, non_reader, long_names, costly_pipeline, words]
    tally = AbuseTally()

    async def run() -> None:
        end = time.monotonic() + seconds
        i = 0
        while time.monotonic() < end:
            task = asyncio.create_task(kinds[i % len(kinds)](host, port, tally))
            await asyncio.sleep(min(turn, max(0.0, end - time.monotonic())))
            task.cancel()
            try:
                await task
            except (asyncio.CancelledError, OSError, ConnectionError, TimeoutError):
                pass
            i += 1

    asyncio.run(run())
    out.put(asdict(tally))


def _probe(host: str, port: int, seconds: float, out: Any) -> None:
    out.put(asdict(run_probe(host, port, seconds, "ABUSE_PROBE")))


def run(seconds: float, turn: float) -> tuple[list[Row], dict[str, Any]]:
    ctx = mp.get_context("fork")
    with tempfile.TemporaryDirectory() as tmp:
        dat = Path(tmp) / "soak.dat"
        dat.write_text(CONFIG)
        with EmuProcess("--config", str(dat)) as emu:
            time.sleep(1.0)  # warmed up: robot running, nothing connected
            start = emu.query("stats")
            workers_q, abuse_q, probe_q = ctx.Queue(), ctx.Queue(), ctx.Queue()
            procs = [
                ctx.Process(target=_worker, args=(emu.host, emu.port, i, seconds, workers_q))
                for i in range(CLIENTS)
            ]
            procs.append(
                ctx.Process(target=_abuser, args=(emu.host, emu.port, seconds, turn, abuse_q))
            )
            procs.append(ctx.Process(target=_probe, args=(emu.host, emu.port, seconds, probe_q)))
            for p in procs:
                p.start()
            emu.query("reset")
            peak = start["rss_mb"]
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                time.sleep(min(10.0, max(0.0, end - time.monotonic())))
                peak = max(peak, emu.query("stats")["rss_mb"])
            served = [workers_q.get(timeout=60) for _ in range(CLIENTS)]
            abuse = abuse_q.get(timeout=60)
            probe = probe_q.get(timeout=60)
            for p in procs:
                p.join(10)
            time.sleep(0.5)  # the abusive client's connections are gone
            final = emu.query("stats")
    requests = final["requests"] - start["requests"]
    rows = [
        Row("emulator RSS at the start (warmed up)", start["rss_mb"], "MB"),
        Row("emulator RSS, maximum sampled every 10 s", peak, "MB"),
        Row(
            "emulator RSS at the end",
            final["rss_mb"],
            "MB",
            note=f"growth {final['rss_mb'] - start['rss_mb']:+.1f} MB (bound: 50 MB)",
        ),
        Row("bystander round trip p50", probe["p50_ms"], "ms"),
        Row("bystander round trip p99", probe["p99_ms"], "ms", target=("ours", "<=", 20.0)),
        Row("bystander round trip max", probe["max_ms"], "ms", target=("ours", "<=", 100.0)),
        Row(
            "wrong values (bystander + full-speed clients)",
            probe["wrong"] + sum(w for _, w in served),
            "",
            target=("ours", "<=", 0.0),
            note=f"bystander: {probe['requests']} requests, {probe['errors']} errors",
        ),
        Row(
            "requests served (emulator counter)",
            requests,
            "",
            note=f"{requests / seconds:,.0f} requests/s; full-speed clients "
            f"{sum(d for d, _ in served):,}",
        ),
    ]
    if final["jitter"] is not None:
        j = final["jitter"]
        rows.append(
            Row(
                "IPO tick lateness p99 / max",
                j["p99_ms"],
                "ms",
                note=f"max {j['max_ms']:.1f} ms over {j['count']} ticks, {j['overruns']} overruns",
            )
        )
    extra = {"seconds": seconds, "turn": turn, "abuse": abuse, "probe": probe,
             "machine": machine_info()}  # fmt: skip
    return rows, extra


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--seconds", type=float, default=None, help="soak duration (default 600)")
    ap.add_argument("--turn", type=float, default=20.0, help="seconds per kind of abuse")
    args = ap.parse_args()
    seconds = args.seconds or (6.0 if args.quick else 600.0)
    turn = min(args.turn, seconds / 5)
    rows, extra = run(seconds, turn)
    m = extra["machine"]
    print(f"{m['date']}  {m['cpu']} x{m['cores']}  load {m['load']}")
    print_rows(f"Soak: {CLIENTS} full-speed clients + 1 abusive client, {seconds:.0f} s", rows)
    print(f"  abusive client: {extra['abuse']}")
    write_json(args.json, "soak", rows, extra)


if __name__ == "__main__":
    main()
