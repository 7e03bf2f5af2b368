"""Emulator benchmark: requests/s with 1 and 10 clients, IPO jitter under that load, memory.

The emulator (``bench/_emu_server.py``: ``kukavarproxy-emu`` options, latency ``none``, the
simulated robot running its default program with the 12 ms IPO clock) runs in its own process.
The load comes from separate processes too, one per client, each a plain blocking socket
keeping ``--depth`` read requests in flight (send a batch, read the batch's replies by byte
count, repeat), so neither the GIL nor an asyncio client is the bottleneck. While the load runs,
the IPO clock's tick lateness (p50/p99/max) and the emulator's RSS are taken from the server.
The peer is the real KUKAVARPROXY's measured throughput (the NTNU measurements, ivareri/KUKAVARPROXY_tests: ~350–400
requests/s in total, whatever the number of clients).

    .venv/bin/python bench/emu_throughput.py [--quick] [--repeat 3] [--seconds 3] [--depth 16]
"""

from __future__ import annotations

import multiprocessing as mp
import socket
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import EmuProcess, Row, base_parser, median, print_rows, write_json

from pyopenshowvar.protocol import encode_read

#: Real KVP on a KRC (the NTNU measurements, ivareri/KUKAVARPROXY_tests): the single proxy thread serves ~350–400 requests/s.
KVP_REQUESTS_PER_S = 400.0
NAMES = ("$OV_PRO", "$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[3]")


def _load(host: str, port: int, depth: int, seconds: float, start_at: float, out: Any) -> None:
    """One client process: ``depth`` requests per batch until ``seconds`` have passed."""
    sock = socket.create_connection((host, port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    batch = b"".join(encode_read(i, NAMES[i % len(NAMES)]) for i in range(depth))
    # learn the batch's reply size once (replies are deterministic in length only for
    # unchanging values, so measure it on every batch: read frames by their length fields)
    recv = sock.recv
    while time.time() < start_at:
        time.sleep(0.001)
    done = 0
    t0 = time.perf_counter()
    end = t0 + seconds
    buf = b""
    while time.perf_counter() < end:
        sock.sendall(batch)
        got = 0
        while got < depth:
            buf += recv(65536)
            # count whole frames in buf
            pos = 0
            while len(buf) - pos >= 4:
                size = 4 + int.from_bytes(buf[pos + 2 : pos + 4], "big")
                if len(buf) - pos < size:
                    break
                pos += size
                got += 1
            buf = buf[pos:]
        done += depth
    out.put(done / (time.perf_counter() - t0))
    sock.close()


def _drive(
    emu: EmuProcess, clients: int, depth: int, seconds: float
) -> tuple[float, dict[str, Any]]:
    """Total requests/s of ``clients`` load processes, plus the server's stats during the load."""
    ctx = mp.get_context("fork")
    out = ctx.Queue()
    start_at = time.time() + 0.3
    procs = [
        ctx.Process(target=_load, args=(emu.host, emu.port, depth, seconds, start_at, out))
        for _ in range(clients)
    ]
    for p in procs:
        p.start()
    time.sleep(max(0.0, start_at - time.time()) + min(0.5, seconds / 4))
    emu.query("reset")  # jitter recorded only while the load runs
    req0 = emu.query("stats")["requests"]
    t0 = time.perf_counter()
    time.sleep(seconds / 2)
    busy = emu.query("stats")  # RSS with every client connected and busy
    rates = [out.get(timeout=seconds + 30) for _ in procs]
    stats = emu.query("stats")
    for p in procs:
        p.join(10)
    server_rate = (stats["requests"] - req0) / (time.perf_counter() - t0)
    stats["rss_busy_mb"] = busy["rss_mb"]
    stats["server_rate"] = server_rate
    return sum(rates), stats


def run(quick: bool, repeat: int, seconds: float, depth: int) -> tuple[list[Row], dict[str, Any]]:
    rows: list[Row] = []
    extra: dict[str, Any] = {"depth": depth, "seconds": seconds}
    rates: dict[int, list[float]] = {1: [], 10: []}
    jitter: dict[int, list[dict[str, float]]] = {1: [], 10: []}
    rss: list[float] = []
    idle_rss: list[float] = []
    for _ in range(repeat):
        with EmuProcess("--latency", "none") as emu:
            time.sleep(0.2)
            idle_rss.append(emu.query("stats")["rss_mb"])
            for n in (1, 10):
                rate, stats = _drive(emu, n, depth, seconds)
                rates[n].append(rate)
                if stats["jitter"] is not None:
                    jitter[n].append(stats["jitter"])
                if n == 10:
                    rss.append(stats["rss_busy_mb"])
    for n in (1, 10):
        rows.append(
            Row(
                f"requests/s, {n} client{'s' if n > 1 else ''} (latency none, {depth} in flight each)",
                median(rates[n]),
                "req/s",
                peer=KVP_REQUESTS_PER_S,
                peer_name="real KVP (NTNU)",
                target=("ours", ">=", 20_000.0) if n == 10 else None,
                runs=rates[n],
            )
        )
    for n in (1, 10):
        if jitter[n]:
            for key, label, target in (
                ("p50_ms", "p50", None),
                ("p99_ms", "p99", ("ours", "<", 2.0)),
                ("max_ms", "max", None),
            ):
                vals = [j[key] for j in jitter[n]]
                rows.append(
                    Row(
                        f"IPO tick lateness {label}, under the {n}-client load",
                        median(vals),
                        "ms",
                        target=target,  # type: ignore[arg-type]
                        runs=vals,
                        note=(
                            f"{median([j['count'] for j in jitter[n]]):.0f} ticks of 12 ms per run"
                            if key == "p50_ms"
                            else ""
                        ),
                    )
                )
    rows.append(
        Row(
            "emulator RSS, 10 clients connected and busy",
            median(rss),
            "MB",
            target=("ours", "<", 150.0),
            runs=rss,
            note=f"idle (robot running, no client): {median(idle_rss):.1f} MB",
        )
    )
    extra["jitter"] = jitter
    return rows, extra


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--seconds", type=float, default=None, help="load duration per run")
    ap.add_argument("--depth", type=int, default=16, help="requests in flight per client")
    args = ap.parse_args()
    repeat = args.repeat or (1 if args.quick else 3)
    seconds = args.seconds or (0.4 if args.quick else 4.0)
    rows, extra = run(args.quick, repeat, seconds, args.depth)
    print_rows(f"Emulator (median of {repeat} runs)", rows)
    write_json(args.json, "emulator", rows, extra)


if __name__ == "__main__":
    main()
