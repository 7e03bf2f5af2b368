"""Coasting IPO clocks (``motion.clock``): a robot at rest wakes once per ``coast`` ticks, and
whoever reads or writes it sees exactly the robot an uncoasted clock would show."""

from __future__ import annotations

import asyncio
from dataclasses import replace

from kukavarproxy_emu import Emulator
from kukavarproxy_emu.handler import build_store
from kukavarproxy_emu.motion import Robot
from kukavarproxy_emu.store import VariableStore
from kukavarproxy_emu.testing import TEST_CONFIG
from pyopenshowvar import Client

PERIOD = 0.012


async def _fires(robot: Robot, seconds: float) -> int:
    wheel = robot.clock._wheel
    assert wheel is not None
    before = wheel.fires
    await asyncio.sleep(seconds)
    return wheel.fires - before


async def test_a_robot_at_rest_coasts_and_a_busy_one_does_not() -> None:
    rest = Robot(VariableStore(), plant="ideal")
    rest.start()
    await asyncio.sleep(0.15)  # settled: the program's first pass and the first coast
    fires = await _fires(rest, 0.3)
    rest.clock.poll()
    assert rest.clock.coasted > 0
    assert fires <= 10  # ~25 wake-ups without coasting (one per 12 ms)
    assert len(rest.clock.jitter) == rest.clock.ticks - rest.clock.coasted  # coasted: not late
    assert rest.jitter().count == len(rest.clock.jitter)
    await rest.stop()

    # a running $TIMER writes every tick: no coasting, and the timer counts every tick
    timed = Robot(VariableStore(), plant="ideal")
    timed.store.set_system("$TIMER_STOP[1]", False)
    timed.start()
    await asyncio.sleep(0.15)
    await asyncio.sleep(0.2)
    ticks = timed.clock.ticks
    assert timed.clock.coasted == 0 and not timed.clock._coasting
    assert timed.store.get("$TIMER[1]") == round(ticks * PERIOD * 1000)
    await timed.stop()


async def test_reads_after_a_coast_match_a_robot_ticked_normally() -> None:
    """Over TCP: the reply shows every tick due when it was asked for, with the values of a
    twin robot (same configuration and seed: dynamic plant, noisy torques) ticked as many
    times by hand."""
    cfg = replace(TEST_CONFIG, seed=7)
    async with Emulator(cfg) as emu:
        robot = emu.robot
        assert robot is not None and robot.plant is not None
        async with Client("127.0.0.1", emu.port, timeout=2.0, keepalive=None) as kvp:
            await asyncio.sleep(0.3)
            assert robot.clock._coasting > 0  # asleep through the next ticks
            asked = asyncio.get_running_loop().time()
            torque = await kvp.read("$TORQUE_AXIS_ACT[]")
            ticks = robot.kernel.ticks
            # every tick due when the read arrived has run (none ahead of its time)
            assert robot.clock._deadline > asked and robot.clock.ticks == ticks
            axes = await kvp.read("$AXIS_ACT")
            assert robot.kernel.ticks == ticks or robot.clock._deadline > asked + PERIOD
    twin = Robot(
        build_store(cfg),
        program=cfg.robot_program,
        sps=cfg.sps,
        noise=cfg.noise,
        seed=cfg.seed,
        plant=cfg.plant,
        calibration_error=cfg.calibration_error,
        torque_noise=cfg.torque_noise,
    )
    twin._begin()
    for _ in range(ticks):
        twin.tick()
    assert torque.strip() == twin.store.read("$TORQUE_AXIS_ACT[]").strip()
    if robot.kernel.ticks == ticks:
        assert axes.strip() == twin.store.read("$AXIS_ACT").strip()


async def test_a_write_during_a_coast_is_acted_on_by_the_next_regular_tick() -> None:
    robot = Robot(VariableStore(), plant="ideal")
    seen: list[tuple[float, object]] = []
    tick = robot.clock.callback

    def traced() -> None:
        tick()
        seen.append((robot.clock._deadline - PERIOD, robot.kernel.moving))

    robot.clock.callback = traced
    robot.start()
    loop = asyncio.get_running_loop()
    await asyncio.sleep(0.2)
    assert robot.clock._coasting > 0  # asleep through the next ticks
    robot.store.write("MYAXIS", "{A1 20.0}")  # in process, mid-coast
    written = loop.time()
    # the ticks due before the write ran first, still at rest ...
    assert all(not moving for deadline, moving in seen if deadline <= written)
    assert robot.clock.ticks == len(seen) and robot.clock._coasting == 0
    n = len(seen)
    await asyncio.sleep(3 * PERIOD)
    # ... and the first tick after it, on the regular grid, started the motion
    assert seen[n][0] > written and seen[n][1] is True
    assert seen[n][0] - written <= PERIOD + 1e-9
    await robot.stop()


async def test_a_write_over_tcp_during_a_coast_moves_the_robot_at_the_next_tick() -> None:
    async with Emulator(replace(TEST_CONFIG, plant="ideal")) as emu:
        robot = emu.robot
        assert robot is not None
        seen: list[bool] = []
        tick = robot.clock.callback

        def traced() -> None:
            tick()
            seen.append(robot.kernel.moving)

        robot.clock.callback = traced
        async with Client("127.0.0.1", emu.port, timeout=2.0, keepalive=None) as kvp:
            await asyncio.sleep(0.2)
            assert robot.clock._coasting > 0
            await kvp.write("MYAXIS", "{A1 20.0}")
            n = len(seen)
            assert robot.clock._coasting == 0 and not robot.kernel.moving
            for _ in range(100):
                if len(seen) > n:
                    break
                await asyncio.sleep(0.002)
            assert seen[n] is True  # the first tick after the write started the motion
