"""A generated snapshot SPS at rest: the same values every pass, at a fraction of the work.

The SPS copies the robot's readings every 12 ms, and the dynamic plant's readings carry fresh
sensor noise every cycle, so no pass repeats. Its assignments run as compiled plans
(:mod:`kukavarproxy_emu.krl.plan`) and its passes let a resting robot's clock coast. Work is
counted, not timed (a loaded machine makes wall-clock CPU meaningless): Python calls of one
pass, against the tree walk measured in the same test.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest

from kukavarproxy_emu.krl import plan as plan_module
from kukavarproxy_emu.responder import build_store
from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.testing import TEST_CONFIG
from pyopenshowvar import Snapshot
from pyopenshowvar.krl import Struct

CELL = Snapshot("CELL", ["$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[]"])  # README's snapshot
SENSORS = ("$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT")


def robot(tmp_path: Path, sps: Path | None = None) -> Robot:
    """A resting robot (dynamic plant, fixed seed) running README's snapshot SPS, ticked by
    hand (no clock: the test decides when a cycle happens)."""
    tmp_path.mkdir(exist_ok=True)
    dat, sub = CELL.write_krl(tmp_path)
    store = build_store(replace(TEST_CONFIG, config_files=(dat,)))
    r = Robot(store, program="follow", sps=str(sps or sub), plant="dynamic", seed=5)
    r._begin()
    for _ in range(30):  # the program's first pass, the plant settled
        r.tick()
    return r


@pytest.fixture
def tree_walk(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Plans off: every statement walks the tree (the executor before plans)."""
    monkeypatch.setattr(plan_module.AssignPlan, "compile", classmethod(lambda cls, ev, st: None))
    yield


def test_every_pass_copies_the_readings_of_its_cycle(tmp_path: Path) -> None:
    r = robot(tmp_path)
    store = r.store
    cycle = store.get("CELL.CYCLE")
    for _ in range(40):
        # what the robot published in the last cycle: the SPS of the next one copies it
        seen = {name: store.get(name) for name in SENSORS}
        r.tick()
        cell = store.get("CELL")
        assert isinstance(cell, Struct)
        assert cell["CYCLE"] == cycle + 1  # type: ignore[operator]
        cycle = cell["CYCLE"]
        assert cell["AXIS_ACT"] == seen["$AXIS_ACT"] and cell["POS_ACT"] == seen["$POS_ACT"]
        torques = [cell[f"TORQUE_AXIS_ACT_{i}"] for i in range(1, 13)]
        assert torques == seen["$TORQUE_AXIS_ACT"]
    assert cell["AXIS_ACT"] != store.get("$AXIS_ACT")  # noise: no two cycles read the same
    assert r._quiet  # the robot rests: its clock may coast through the snapshot's passes


SPS_RULES = """DEF RULES()
  DECL INT N
  LOOP
    N = 0
    R_INT = $TORQUE_AXIS_ACT[2]
    R_POS = $POS_ACT
    R_REAL = R_INT - 0.25
    R_FRAME = R_POS
    R_BOOL = TRUE
    R_AX.A1 = R_AX.A1 + 1
    R_AXIS = $AXIS_ACT
    R_TXT[] = "copied"
  ENDLOOP
END
"""
DAT_RULES = """DEFDAT $CONFIG
DECL INT R_INT
DECL POS R_POS
DECL REAL R_REAL
DECL FRAME R_FRAME
DECL BOOL R_BOOL
DECL E6AXIS R_AX={A1 0.0}
DECL AXIS R_AXIS
DECL CHAR R_TXT[12]
ENDDAT
"""


def _run_rules(tmp_path: Path) -> dict[str, object]:
    tmp_path.mkdir()
    (tmp_path / "rules.sub").write_text(SPS_RULES)
    (tmp_path / "rules.dat").write_text(DAT_RULES)
    store = build_store(replace(TEST_CONFIG, config_files=(tmp_path / "rules.dat",)))
    r = Robot(store, program="follow", sps=str(tmp_path / "rules.sub"), plant="dynamic", seed=9)
    r._begin()
    for _ in range(25):
        r.tick()
    assert r.sps is not None and r.sps.running, r.sps and r.sps.message
    names = ("R_INT", "R_POS", "R_REAL", "R_FRAME", "R_BOOL", "R_AX", "R_AXIS", "R_TXT[]")
    return {n: store.get(n) for n in names}


def test_plans_keep_krl_conversions(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """REAL → INT rounds, E6POS → POS/FRAME narrow, E6AXIS → AXIS, counters count: the same
    values with plans as by the tree walk (same seed, same ticks)."""
    planned = _run_rules(tmp_path / "p")
    monkeypatch.setattr(plan_module.AssignPlan, "compile", classmethod(lambda cls, ev, st: None))
    walked = _run_rules(tmp_path / "w")
    assert planned == walked
    assert isinstance(planned["R_INT"], int) and planned["R_AX"]["A1"] == 25.0  # type: ignore[index]
    assert isinstance(planned["R_POS"], Struct) and "E1" not in planned["R_POS"]


def _calls_per_pass(r: Robot, passes: int = 20) -> float:
    """Python calls of one SPS pass, the readings filled beforehand (the plant's work)."""
    count = [0]

    def profile(frame: object, event: str, arg: object) -> None:
        if event == "call":
            count[0] += 1

    assert r.sps is not None
    for _ in range(passes):
        for name in SENSORS:
            r.store.get(name)
        sys.setprofile(profile)
        try:
            r.sps.step()
        finally:
            sys.setprofile(None)
        r.kernel.tick()
    return count[0] / passes


def test_a_snapshot_pass_is_a_third_of_the_tree_walks_work(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    planned = _calls_per_pass(robot(tmp_path / "p"))
    monkeypatch.setattr(plan_module.AssignPlan, "compile", classmethod(lambda cls, ev, st: None))
    walked = _calls_per_pass(robot(tmp_path / "w"))
    assert planned <= 0.4 * walked, (planned, walked)


async def test_a_resting_robot_with_a_snapshot_sps_wakes_once_per_coast(tmp_path: Path) -> None:
    """On its real clock: far fewer wake-ups of the process than IPO ticks (the coast), every
    tick still run (the pass counter counts each one)."""
    import asyncio

    from kukavarproxy_emu import Emulator

    dat, sub = CELL.write_krl(tmp_path)
    config = replace(TEST_CONFIG, config_files=(dat,), sps=str(sub))
    async with Emulator(config) as emu:
        r = emu.robot
        assert r is not None and r.clock._wheel is not None
        await asyncio.sleep(0.5)  # settled
        wheel, clock = r.clock._wheel, r.clock
        fires, ticks, cycle = wheel.fires, clock.ticks, emu.store.get("CELL.CYCLE")
        await asyncio.sleep(1.0)
        r.sync()
        fires, ticks = wheel.fires - fires, clock.ticks - ticks
        assert ticks >= 20 and fires <= 0.35 * ticks, (fires, ticks)
        assert emu.store.get("CELL.CYCLE") == cycle + ticks  # type: ignore[operator]


async def test_with_a_latency_profile_the_snapshot_robot_does_not_coast(tmp_path: Path) -> None:
    """Replies first: a coast's catch-up of ticks that copy readings would make a reply late."""
    import asyncio

    from kukavarproxy_emu import Emulator

    dat, sub = CELL.write_krl(tmp_path)
    config = replace(TEST_CONFIG, config_files=(dat,), sps=str(sub), latency="kvp")
    async with Emulator(config) as emu:
        r = emu.robot
        assert r is not None
        await asyncio.sleep(0.5)
        coasted, ticks = r.clock.coasted, r.clock.ticks
        await asyncio.sleep(0.5)
        assert r.clock.ticks - ticks >= 10 and r.clock.coasted == coasted
