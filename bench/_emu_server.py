"""The emulator as the benchmarks run it: ``kukavarproxy-emu`` plus a control channel on stdin.

Takes the options of ``kukavarproxy-emu`` (same parser, same :class:`EmulatorConfig`), prints
``listening on HOST:PORT`` and then answers one JSON line per command read from stdin:

* ``stats`` — requests served, clients connected, RSS, CPU seconds and the IPO jitter
  (p50/p99/max/mean in ms, from ``emu.robot.jitter()``; null without a robot);
* ``reset`` — clear the jitter record (call it once the load is running).

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

from kukavarproxy_emu import Emulator
from kukavarproxy_emu.__main__ import build_parser, config_from_args


def _rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024 / 1e6
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3


def _stats(emu: Emulator) -> dict[str, Any]:
    usage = os.times()
    out: dict[str, Any] = {
        "requests": emu.stats.requests,
        "clients": emu.stats.clients,
        "rss_mb": _rss_mb(),
        "cpu_s": usage.user + usage.system,
        "jitter": None,
    }
    if emu.robot is not None:
        j = emu.robot.jitter()
        out["jitter"] = {
            "count": j.count,
            "p50_ms": j.p50 * 1e3,
            "p99_ms": j.p99 * 1e3,
            "max_ms": j.max * 1e3,
            "mean_ms": j.mean * 1e3,
            "overruns": emu.robot.clock.overruns,
        }
    return out


async def _serve(argv: list[str]) -> None:
    config = config_from_args(build_parser().parse_args(argv))
    loop = asyncio.get_running_loop()
    async with Emulator(config) as emu:
        gc.freeze()  # as kukavarproxy-emu does: the start-up heap is never scanned again
        print(f"listening on {emu.host}:{emu.port}", flush=True)
        while True:
            # a thread blocks on stdin, so the loop (and the IPO clock) never waits for it
            line = await loop.run_in_executor(None, sys.stdin.readline)
            command = line.strip()
            if not line or command == "quit":
                return
            if command == "reset" and emu.robot is not None:
                emu.robot.clock.reset_stats()
            print(json.dumps(_stats(emu)), flush=True)


def main() -> None:
    asyncio.run(_serve(sys.argv[1:]))


if __name__ == "__main__":
    main()
