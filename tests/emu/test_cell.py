"""A cell of robots in one process, cheap cycles at rest, replies before ticks (issue 11, 2-3).

CPU figures are benchmarks (bench/cell_cpu.py); these tests check the mechanisms: independent
robots on consecutive ports, KRL cycles skipped only while they would repeat exactly, the
gate that holds a tick until a request was booked, and texts formatted ahead for pollers.
"""

from __future__ import annotations

import asyncio
import random
import subprocess
import sys
import time
from dataclasses import replace

import pytest

from kukavarproxy_emu import Cell, EmulatorConfig, cell_configs
from kukavarproxy_emu.__main__ import main as emu_main
from kukavarproxy_emu.krl.executor import parse_text
from kukavarproxy_emu.latency import LatencyProfile, ServiceQueue, tick_gate
from kukavarproxy_emu.motion import IpoClock
from kukavarproxy_emu.motion.clock import release
from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.store import VariableStore
from kukavarproxy_emu.testing import TEST_CONFIG
from pyopenshowvar import Client


def test_cell_configs_ports_seeds_phases_and_limits() -> None:
    base = EmulatorConfig(port=7100, seed=40, discovery=True)
    configs = cell_configs(base, 3)
    assert [c.port for c in configs] == [7100, 7101, 7102]
    assert [c.seed for c in configs] == [40, 41, 42]
    assert [c.discovery for c in configs] == [True, False, False]  # one UDP 6999 per host
    assert len({c.ipo_phase for c in configs}) == 3 and configs[0].ipo_phase == 0.0
    assert all(0 <= c.ipo_phase < c.ipo for c in configs)
    assert cell_configs(base, 1) == [base]
    ephemeral = cell_configs(replace(base, port=0, seed=None), 2)
    assert [c.port for c in ephemeral] == [0, 0] and ephemeral[0].seed != ephemeral[1].seed - 2
    for bad in (0, 201):
        with pytest.raises(ValueError, match="robots"):
            cell_configs(base, bad)
    with pytest.raises(ValueError, match="65535"):
        cell_configs(replace(base, port=65535), 2)


async def test_robots_of_a_cell_are_independent() -> None:
    async with Cell(cell_configs(replace(TEST_CONFIG, plant="ideal", speed=10.0), 3)) as cell:
        ports = [emu.port for emu in cell.emulators]
        assert len(set(ports)) == 3
        async with Client("127.0.0.1", ports[1], timeout=2.0, keepalive=None) as kvp:
            await kvp.write("MYAXIS", "{A1 30.0}")
            for _ in range(200):
                if abs(float((await kvp.read_joint_angles())[0]) - 30.0) < 1e-6:
                    break
                await asyncio.sleep(0.01)
        a1 = [float(emu.robot.q[0]) for emu in cell.emulators if emu.robot is not None]
        assert a1 == [0.0, pytest.approx(30.0), 0.0]
        assert cell.emulators[0].store.get("MYAXIS") != cell.emulators[1].store.get("MYAXIS")


def test_command_line_prints_one_line_per_robot() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "kukavarproxy_emu", "--port", "0", "--robots", "2",
         "--no-discovery", "--plant", "ideal"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        lines = [proc.stdout.readline().strip() for _ in range(2)]
        assert all(line.startswith("listening on 127.0.0.1:") for line in lines), lines
        assert len(set(lines)) == 2
    finally:
        proc.terminate()
        proc.wait(10)
    assert proc.returncode == 0
    with pytest.raises(SystemExit) as usage:
        emu_main(["--robots", "0"])
    assert usage.value.code == 2


def test_krl_cycles_are_skipped_only_while_they_would_repeat() -> None:
    store = VariableStore()
    robot = Robot(store, program="follow", sps="sps", plant="dynamic", seed=3)
    robot._begin()
    assert robot.sps is not None
    program = robot.program.interp  # type: ignore[attr-defined]
    for _ in range(10):
        robot.tick()
    sps_skipped, program_skipped = robot.sps.interp.skipped, program.skipped
    assert sps_skipped >= 7 and program_skipped >= 7  # at rest: nothing to redo
    store.write("OUTPUT_VARS[3]", "TRUE")
    robot.tick()
    assert store.get("$OUT[3]") is True  # the write ended the skipping at once
    store.write("MYAXIS", "{A1 20.0}")
    for _ in range(3):
        robot.tick()
    assert robot.kernel.moving or float(robot.kernel.q[0]) > 0.0
    # a pass that changes something every time (a counter) is never skipped
    counter = parse_text("DEF CNT()\n  LOOP\n    MYINT = MYINT + 1\n  ENDLOOP\nEND\n", "cnt.sub")
    from kukavarproxy_emu.krl.executor import KrlSubmit

    sub = KrlSubmit(counter, store)
    sub.start()
    for _ in range(5):
        sub.step()
    assert store.get("MYINT") == 5 and sub.interp.skipped == 0


async def test_gate_holds_a_due_tick_until_a_request_is_booked() -> None:
    ticks: list[float] = []
    clock = IpoClock(lambda: ticks.append(time.monotonic()), ipo=0.02, max_hold=5.0)
    clock.gate = lambda cost: False  # a reply is always imminent
    clock.start()
    await asyncio.sleep(0.06)
    assert ticks == [] and clock.ticks == 0  # due, but held
    release()  # a request was booked: the best moment for the tick
    assert len(ticks) == 1 and clock.held == 1
    await clock.stop()


async def test_tick_gate_reads_the_booked_deadlines() -> None:
    loop = asyncio.get_running_loop()
    queue = ServiceQueue(LatencyProfile.fixed(0.4), random.Random(1))
    gate = tick_gate(loop)
    assert gate(0.001)  # no latency worker on this loop yet
    task = loop.create_task(queue.run("read", lambda: 1))
    await asyncio.sleep(0.005)  # booked: its reply is ~0.4 s away
    assert gate(0.001) and not gate(0.4)  # a 0.4 s tick would make it late
    assert await task == 1
    assert not gate(0.001)  # just answered: the client's next request is on its way
    queue.last_reply -= 1.0
    assert gate(0.001)  # idle for long: nobody to wait for


def test_texts_polled_every_cycle_are_formatted_in_the_tick() -> None:
    store = VariableStore()
    robot = Robot(store, program="none", sps=None, plant="dynamic", seed=5)
    robot.tick()
    fills: list[int] = []
    publish_axes = robot.plant._publish_axes  # type: ignore[union-attr]

    def counting_publish() -> None:
        fills.append(robot.kernel.ticks)
        publish_axes()

    robot.plant._publish_axes = counting_publish  # type: ignore[union-attr,method-assign]
    robot.tick()  # the plant defers to the counting fill from now on
    in_read, in_tick = [], []
    for _ in range(4):  # a client polls $AXIS_ACT every cycle
        fills.clear()
        store.read("$AXIS_ACT")
        in_read.append(len(fills))
        fills.clear()
        robot.tick()
        in_tick.append(len(fills))
    # once it is polled in two cycles in a row, the tick formats it and the read looks it up
    assert in_read[:2] == [1, 1] and in_read[2:] == [0, 0]
    assert in_tick[0] == 0 and in_tick[1:] == [1, 1, 1]
    # and only its own group: the pose (forward kinematics) waits until someone reads it
    assert "$POS_ACT" in store._stale and "$AXIS_ACT" not in store._stale
