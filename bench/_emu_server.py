"""The emulator as the benchmarks run it: ``kukavarproxy-emu`` plus a control channel on stdin.

Takes the options of ``kukavarproxy-emu`` (same parser, same :class:`EmulatorConfig`; with
``--robots N`` a cell), prints ``listening on HOST:PORT`` (one line per robot) and then answers one JSON line per command read from stdin:

* ``stats`` — requests served, clients connected, RSS, CPU seconds and the IPO jitter
  (p50/p99/max/mean in ms over every robot's recorded ticks; null without a robot) and, with a
  latency profile, how late replies were computed after their deadlines;
* ``reset`` — clear the jitter and reply-lateness records (call it once the load is running).

EOF on stdin stops it. Not a public tool: the benchmark scripts start it via
:class:`bench._common.EmuProcess`.
"""

from __future__ import annotations

import asyncio
import gc
import json
import os
import resource
import sys
from pathlib import Path
from typing import Any

from kukavarproxy_emu import Cell, Emulator, cell_configs
from kukavarproxy_emu.__main__ import build_parser, config_from_args


def _rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024 / 1e6
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


def _jitter(emulators: list[Emulator]) -> dict[str, Any] | None:
    """Tick lateness over every robot of the process (a cell: all their ticks together)."""
    robots = [emu.robot for emu in emulators if emu.robot is not None]
    if not robots:
        return None
    data = sorted(x for robot in robots for x in robot.clock.jitter)
    n = len(data)
    if not n:
        return {"count": 0, "p50_ms": 0.0, "p99_ms": 0.0, "max_ms": 0.0, "mean_ms": 0.0,
                "overruns": 0, "held": 0}  # fmt: skip
    return {
        "count": n,
        "p50_ms": data[n // 2] * 1e3,
        "p99_ms": data[min(n - 1, int(n * 0.99))] * 1e3,
        "max_ms": data[-1] * 1e3,
        "mean_ms": sum(data) / n * 1e3,
        "overruns": sum(robot.clock.overruns for robot in robots),
        "held": sum(robot.clock.held for robot in robots),
    }


def _reply_lateness(emulators: list[Emulator]) -> dict[str, float] | None:
    """How late replies were computed after their latency deadlines (ms), all emulators."""
    data = sorted(x for emu in emulators if emu.service is not None for x in emu.service.late)
    if not data:
        return None
    n = len(data)
    return {
        "count": n,
        "p50_ms": data[n // 2] * 1e3,
        "p90_ms": data[int(n * 0.9)] * 1e3,
        "p99_ms": data[min(n - 1, int(n * 0.99))] * 1e3,
        "mean_ms": sum(data) / n * 1e3,
    }


def _stats(emulators: list[Emulator]) -> dict[str, Any]:
    usage = os.times()
    return {
        "requests": sum(emu.stats.requests for emu in emulators),
        "clients": sum(emu.stats.clients for emu in emulators),
        "rss_mb": _rss_mb(),
        "cpu_s": usage.user + usage.system,
        "jitter": _jitter(emulators),
        "reply_late": _reply_lateness(emulators),
    }


async def _serve(argv: list[str]) -> None:
    args = build_parser().parse_args(argv)
    config = config_from_args(args)
    loop = asyncio.get_running_loop()
    async with Cell(cell_configs(config, args.robots)) as cell:
        gc.freeze()  # as kukavarproxy-emu does: the start-up heap is never scanned again
        for emu in cell.emulators:
            print(f"listening on {emu.host}:{emu.port}", flush=True)
        while True:
            # a thread blocks on stdin, so the loop (and the IPO clock) never waits for it
            line = await loop.run_in_executor(None, sys.stdin.readline)
            command = line.strip()
            if not line or command == "quit":
                return
            if command == "reset":
                for emu in cell.emulators:
                    if emu.robot is not None:
                        emu.robot.clock.reset_stats()
                    if emu.service is not None:
                        emu.service.late.clear()
            print(json.dumps(_stats(cell.emulators)), flush=True)


def main() -> None:
    asyncio.run(_serve(sys.argv[1:]))


if __name__ == "__main__":
    main()
