"""Client round-trip benchmark against an emulator in a separate process (latency ``none``).

Prints the serial read round-trip time (one request in flight, like JOpenShowVar) and the
pipelined read throughput of ``read_many``. Run::

    .venv/bin/python bench/client_roundtrip.py [--reads 5000] [--repeat 5]

Numbers are medians over ``--repeat`` runs. This is a benchmark, not a test: it never fails on a
slow machine.
"""

from __future__ import annotations

import argparse
import asyncio
import platform
import statistics
import subprocess
import sys
import time

from pyopenshowvar import Client


def start_emulator() -> tuple[subprocess.Popen[str], int]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "kukavarproxy_emu", "--port", "0", "--latency", "none", "--log-level", "warning"],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    line = proc.stdout.readline().strip()  # "listening on HOST:PORT"
    return proc, int(line.rsplit(":", 1)[1])


async def serial(port: int, n: int) -> list[float]:
    async with Client("127.0.0.1", port, keepalive=None) as kvp:
        for _ in range(200):  # warm-up
            await kvp.read("$AXIS_ACT")
        times = []
        for _ in range(n):
            t0 = time.perf_counter()
            await kvp.read("$AXIS_ACT")
            times.append(time.perf_counter() - t0)
        return times


async def pipelined(port: int, n: int, batch: int) -> float:
    names = [f"MYE6ARRAY[{i % 512 + 1}]" for i in range(batch)]
    async with Client("127.0.0.1", port, keepalive=None) as kvp:
        await kvp.read_many(names)
        t0 = time.perf_counter()
        done = 0
        while done < n:
            res = await kvp.read_many(names)
            done += len(res)
        return done / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--reads", type=int, default=5000)
    ap.add_argument("--batch", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    proc, port = start_emulator()
    try:
        medians, p99s, rates = [], [], []
        for _ in range(args.repeat):
            t = sorted(asyncio.run(serial(port, args.reads)))
            medians.append(t[len(t) // 2])
            p99s.append(t[int(len(t) * 0.99)])
            rates.append(asyncio.run(pipelined(port, args.reads * 4, args.batch)))
    finally:
        proc.terminate()
        proc.wait(5)
    print(f"machine: {platform.machine()} {platform.processor() or ''} python {platform.python_version()}")
    print(f"serial read $AXIS_ACT round trip: median {statistics.median(medians) * 1e6:.0f} us, p99 {statistics.median(p99s) * 1e6:.0f} us")
    print(f"pipelined read_many ({args.batch} names/call): {statistics.median(rates):,.0f} reads/s")


if __name__ == "__main__":
    main()
