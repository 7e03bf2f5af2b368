"""Abuse suite, wave platform: garbage, floods and idle connections against ``kvp platform``.

The platform simulator runs in its own process, and so does the bystander, a master reading the
state block one request at a time; the attackers send broken frames and MBAP headers, undefined
function codes and coil writes, reads back to back, and hold idle connections.

Asserted, against a baseline of the same bystander measured in the same run just before the
attack (never a fixed number of ms): every bystander read succeeds and its latency stays close
to the baseline; the PLC keeps scanning; the platform's peak memory *during* the attack stays
bounded; it prints no traceback; and the attackers report no failures of their own.
"""

from __future__ import annotations

import asyncio
import statistics
import sys
import time
from collections.abc import Iterator

import pytest
from pyopenshowvar_apps.abusekit import AttackTally, PeakMemory
from pyopenshowvar_apps.heave.abuse import PlatformProcess, flood, garbage, idle, probe_process
from pyopenshowvar_apps.heave.master import PlatformClient

pytestmark = [
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RSS from /proc"),
    pytest.mark.timeout(90),
]

BASELINE, SECONDS = 1.0, 2.5
PEAK_GROWTH_MB = 30.0


@pytest.fixture(scope="module")
def plc() -> Iterator[PlatformProcess]:
    with PlatformProcess() as plc:
        yield plc


def _p(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(len(ordered) * q))]


def test_garbage_floods_and_idle_connections_with_a_bystander(plc: PlatformProcess) -> None:
    async def run() -> tuple[list[float], list[float], dict[str, AttackTally], PeakMemory, int]:
        async with PlatformClient(plc.host, plc.port) as master:
            cycle0 = (await master.read_state()).cycle
        bystander = probe_process(plc.host, plc.port, 0.3 + BASELINE + SECONDS)
        await bystander.start()
        await asyncio.sleep(0.3 + BASELINE)  # a warm-up, then the baseline
        tallies = {name: AttackTally() for name in ("garbage", "flood", "idle")}
        with PeakMemory(plc.pid) as memory:
            attack_start = time.monotonic()
            tasks = [
                *(asyncio.create_task(garbage(plc.host, plc.port, tallies["garbage"], seed=s))
                  for s in range(2)),
                asyncio.create_task(flood(plc.host, plc.port, tallies["flood"])),
                asyncio.create_task(idle(plc.host, plc.port, tallies["idle"], sockets=50)),
            ]  # fmt: skip
            samples = await bystander.result()
            for task in tasks:
                task.cancel()
            outcomes = await asyncio.gather(*tasks, return_exceptions=True)
        for outcome in outcomes:
            if isinstance(outcome, Exception):
                tallies["garbage"].error(repr(outcome))
        async with PlatformClient(plc.host, plc.port) as master:
            scans = ((await master.read_state()).cycle - cycle0) & 0xFFFF
        first = samples[0][0]
        base = [ms for t, ms in samples if first + 0.3 <= t < attack_start]
        during = [ms for t, ms in samples if t >= attack_start + 0.2]
        return base, during, tallies, memory, scans

    base, during, tallies, memory, scans = asyncio.run(run())
    b50, b99, d50, d99 = _p(base, 0.5), _p(base, 0.99), _p(during, 0.5), _p(during, 0.99)
    print(
        f"bystander read p50/p99 {b50:.2f}/{b99:.2f} -> {d50:.2f}/{d99:.2f} ms ({len(base)} ->"
        f" {len(during)} reads); {scans} scans; peak RSS {memory.start:.0f} ->"
        f" {memory.peak:.0f} MB; "
        + ", ".join(f"{n}: {t.connections} conns, {t.requests} sent" for n, t in tallies.items())
    )
    assert plc.alive() and plc.tracebacks() == 0, plc.stderr()[-3000:]
    assert base and len(during) > 0.2 * len(base) * (SECONDS - 0.2) / BASELINE
    # against the baseline of this very run (the attackers share the two cores, and the PLC
    # serves them too): a bounded factor, or a few tens of ms more; a stall is far beyond
    assert d50 <= max(10 * b50, b50 + 20.0) and d99 <= max(10 * b99, b99 + 100.0)
    mean_b, mean_d = statistics.mean(base), statistics.mean(during)
    assert mean_d <= max(10 * mean_b, mean_b + 20.0)
    assert scans >= 0.5 * (BASELINE + SECONDS) / 0.01  # the PLC scanned on (10 ms scans)
    assert memory.peak - memory.start <= PEAK_GROWTH_MB
    for name, tally in tallies.items():
        assert tally.errors == 0, (name, tally.notes)
    assert tallies["garbage"].connections > 20 and tallies["idle"].connections == 50
    flooded = tallies["flood"]
    assert flooded.replies > 20 and flooded.replies >= flooded.requests - 1  # the last: cancelled
