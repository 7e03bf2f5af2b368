"""Latency-profile fidelity: reply times of the ``kvp`` profile for paced and back-to-back clients.

The emulator runs with ``--latency kvp --no-robot`` in a subprocess (its own core); one client
sends reads of ``$AXIS_ACT`` and writes of ``MYINT``, either back to back (the next request as
soon as the reply is in) or paced (``--gap`` ms of sleep between a reply and the next request, as
a client with its own control loop does). The profile's medians are 2.3 ms (read) and 3.3 ms
(write) with a 1.5 ms floor; the figures show how close each pacing comes, and the smallest RTT
seen (never below the floor if replies are not sent early).

    .venv/bin/python bench/latency_pacing.py [--quick] [--n 400] [--gap 2.0]
"""

from __future__ import annotations

import socket
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import EmuProcess, Row, base_parser, machine_info, print_rows, write_json

from pyopenshowvar.protocol import encode_read, encode_write

FLOOR_MS = 1.5


def _recv_reply(sock: socket.socket) -> None:
    head = b""
    while len(head) < 4:
        chunk = sock.recv(4 - len(head))
        if not chunk:
            raise ConnectionError("emulator closed the connection")
        head += chunk
    need = int.from_bytes(head[2:4], "big")
    body = b""
    while len(body) < need:
        chunk = sock.recv(need - len(body))
        if not chunk:
            raise ConnectionError("emulator closed the connection")
        body += chunk


def measure(host: str, port: int, n: int, gap_s: float) -> dict[str, list[float]]:
    """RTTs (ms) of alternating reads and writes, with ``gap_s`` between reply and request."""
    out: dict[str, list[float]] = {"read": [], "write": []}
    with socket.create_connection((host, port), timeout=5.0) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        for i in range(2 * n):
            kind = "read" if i % 2 else "write"
            frame = encode_read(i, "$AXIS_ACT") if i % 2 else encode_write(i, "MYINT", str(i))
            if gap_s:
                time.sleep(gap_s)
            start = time.perf_counter()
            sock.sendall(frame)
            _recv_reply(sock)
            out[kind].append((time.perf_counter() - start) * 1e3)
    return out


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--n", type=int, default=400, help="requests of each kind per pacing")
    ap.add_argument(
        "--gap", type=float, default=2.0, help="ms between a reply and the next request"
    )
    args = ap.parse_args()
    n = 30 if args.quick else args.n
    rows: list[Row] = []
    # no simulated robot: the figures are the latency model's, not the plant's CPU load
    with EmuProcess("--latency", "kvp", "--seed", "1", "--no-robot") as emu:
        measure(emu.host, emu.port, 10, 0.0)  # warm up
        for label, gap in (("back-to-back", 0.0), (f"paced {args.gap:g} ms", args.gap / 1e3)):
            rtt = measure(emu.host, emu.port, n, gap)
            for kind, target in (("read", 2.3), ("write", 3.3)):
                med = statistics.median(rtt[kind])
                rows.append(
                    Row(
                        f"kvp {kind} median, {label}",
                        med,
                        "ms",
                        target=("ours", "<=", target + 0.3),
                        note=f"profile median {target} ms; min {min(rtt[kind]):.2f} ms "
                        f"(floor {FLOOR_MS} ms)",
                    )
                )
    print_rows("Latency profile vs client pacing (kvp)", rows)
    write_json(args.json, "latency_pacing", rows, {"machine": machine_info(), "n": n})


if __name__ == "__main__":
    main()
