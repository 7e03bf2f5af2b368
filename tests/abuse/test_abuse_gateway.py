"""Abuse suite, gateway side: hostile robots and a login flood against the real ``kvp gateway``.

Every process is its own: healthy robots (real emulators whose program never stops moving),
the gateway, the attackers (a fake robot answering ~60 KB STRUCs, one answering ~3 KB ones
that are under the size cap but costly to parse, a process logging in with a wrong password
as fast as it is answered) and this test's OPC UA client, which subscribes to the healthy
robots' axes and reads a node every 20 ms (``pyopenshowvar_apps.gateway.testbed`` and
``.abuse``).

Each test measures a baseline phase and then an attack phase on the same gateway, and
compares: the healthy robots' update gaps and the reads may not get much worse than the
baseline measured seconds before on the same (possibly loaded, 2-core) machine, no healthy
value turns Bad, the gateway's peak resident memory during the attack stays within 50 MB of
what it had before, and the attackers' own tallies show the attack happened as designed.
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("asyncua")
from pyopenshowvar_apps.gateway.abuse import HostileProcess
from pyopenshowvar_apps.gateway.security import hash_password
from pyopenshowvar_apps.gateway.testbed import (
    CellProcess,
    GatewayProcess,
    Watch,
    cell_file,
    measure,
    open_client,
)

pytestmark = [
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RSS from /proc"),
    pytest.mark.timeout(180),
]

BASELINE_S = 3.0
ATTACK_S = 4.0
FLOOD_S = 12.0  # long enough for the checked attempts and the lockout after them
FAILURES = 3  # max_failed_logins: fewer costly checks before the lockout on a slow machine
RSS_GROWTH_MB = 50.0
SECRET = "correct horse battery"
HEALTHY = ("r1", "r2")


@pytest.fixture
def healthy(tmp_path: Path) -> Iterator[CellProcess]:
    cell = CellProcess(len(HEALTHY), tmp_path)
    try:
        yield cell
    finally:
        cell.stop()


async def _warm(watch: Watch) -> None:
    """Until every healthy robot has sent a few updates (the gateway polls them all)."""
    for _ in range(300):
        if min(watch.updates().values()) >= 5:
            return
        await asyncio.sleep(0.05)
    raise AssertionError(f"the healthy robots are not updating: {watch.updates()}")


def _compare(base: dict[str, Any], attack: dict[str, Any]) -> None:
    print(f"\nbaseline {base}\nattack   {attack}")  # the figures, for `pytest -s`
    assert base["gaps"] >= 20 and base["reads"] >= 50, base  # the baseline means something
    assert attack["gaps"] >= 20 and attack["reads"] >= 50, attack
    # the healthy robots keep their rate and their values stay Good
    assert attack["gaps"] >= 0.6 * base["gaps"] * ATTACK_S / BASELINE_S, (base, attack)
    assert attack["bad"] == 0 and attack["read_errors"] == 0, attack
    # compared with the baseline of this very run, not with a fixed number of ms: a loaded
    # machine slows both phases (on a 2-core machine shared with a dozen busy processes the
    # attackers' own CPU shows too); an event loop stalled by parsing or by a password check
    # costs seconds (1.9-4.9 s gaps and 1.7-3.9 s reads before the budget, on such a machine)
    assert attack["gap_p99"] <= 2 * base["gap_p99"] + 100, (base, attack)
    assert attack["gap_p50"] <= 2 * base["gap_p50"] + 50, (base, attack)
    assert attack["read_p99"] <= 3 * base["read_p99"] + 50, (base, attack)
    assert attack["growth_mb"] <= RSS_GROWTH_MB, attack


async def test_hostile_robots_do_not_slow_the_healthy_ones(
    tmp_path: Path, healthy: CellProcess
) -> None:
    huge, costly = HostileProcess(60_000), HostileProcess(3_000)
    gw = GatewayProcess(
        cell_file(tmp_path, healthy.ports, [huge.port, costly.port]), tmp_path / "gw.log"
    )
    tallies: list[dict[str, Any]] = []
    try:
        client = await open_client(gw, tmp_path)
        watch = Watch(client, "abuse", HEALTHY)
        await watch.start()
        await _warm(watch)
        base = await measure(gw, watch, BASELINE_S)
        huge.big(True)
        costly.big(True)
        await asyncio.sleep(2.5)  # both reconnected (the backoff is at most 2.4 s)
        attack = await measure(gw, watch, ATTACK_S)
        await watch.stop()
        await client.disconnect()
        assert gw.alive()
    finally:
        gw.stop()
        tallies = [huge.stop(), costly.stop()]
    _compare(base, attack)
    # the attackers really attacked: the 60 KB robot answered (and was refused at its first
    # reply, again after each backoff), the 3 KB one answered whole polls of 15 values
    assert tallies[0]["big_replies"] >= 4, tallies
    assert tallies[1]["big_replies"] >= 19, tallies
    log = gw.log.read_text()
    assert "over max_value_chars = 4096" in log and "over its budget" in log, log[-2000:]
    assert "Traceback" not in log, log[-2000:]


async def test_a_login_flood_neither_stalls_the_gateway_nor_gets_in(
    tmp_path: Path, healthy: CellProcess
) -> None:
    digest = hash_password(SECRET)  # 200 000 iterations, as --hash-password makes them
    security = (
        f'[security]\nusers = [{{ name = "scada", password_hash = "{digest}" }}]\n'
        f"max_failed_logins = {FAILURES}\n"
    )
    gw = GatewayProcess(cell_file(tmp_path, healthy.ports, security=security), tmp_path / "gw.log")
    try:
        client = await open_client(gw, tmp_path, "scada", SECRET)  # in before the flood
        watch = Watch(client, "abuse", HEALTHY)
        await watch.start()
        await _warm(watch)
        base = await measure(gw, watch, BASELINE_S)
        flood = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "pyopenshowvar_apps.gateway.abuse", "logins", gw.url,
            "--user", "scada", "--user", "nobody", "--seconds", str(FLOOD_S),
            "--folder", str(tmp_path), stdout=subprocess.PIPE,
        )  # fmt: skip
        assert flood.stdout is not None
        started = await asyncio.wait_for(flood.stdout.readline(), 60)
        assert started == b"flooding\n", started  # measured from its first attempt on
        attack = await measure(gw, watch, ATTACK_S)
        out, _ = await asyncio.wait_for(flood.communicate(), FLOOD_S + 60)
        await watch.stop()
        await client.disconnect()
        assert gw.alive()
    finally:
        gw.stop()
    tally = json.loads(out.decode().strip().splitlines()[-1])
    tally.pop("times")
    print(f"\nlogin flood {tally}")
    _compare(base, attack)
    # the abuser's own counts: never in, never an unexplained error; exactly the allowed
    # number of passwords checked (max_failed_logins), every later attempt cut off
    assert tally["accepted"] == 0 and tally["errors"] == 0, tally
    assert tally["denied"] == FAILURES, tally
    assert tally["locked"] >= 1 and tally["attempts"] == tally["denied"] + tally["locked"], tally
    log = gw.log.read_text()
    assert "too many failed logins" in log and "Traceback" not in log, log[-2000:]
