"""Coasting IPO clocks (``motion.clock``): a robot at rest wakes once per ``coast`` ticks, and
whoever reads or writes it sees exactly the robot an uncoasted clock would show.

Everything is counted in ticks, not wall time: a loaded machine makes the clock late (and a
late clock runs its ticks back to back), which changes when things happen but none of what
these tests check.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import replace

from kukavarproxy_emu import Emulator
from kukavarproxy_emu.responder import build_store
from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.store import VariableStore
from kukavarproxy_emu.testing import TEST_CONFIG, wait_until
from pyopenshowvar import Client

PERIOD = 0.012


async def test_a_robot_at_rest_coasts_and_a_busy_one_does_not() -> None:
    rest = Robot(VariableStore(), plant="ideal")
    rest.start()
    clock = rest.clock
    await wait_until(lambda: clock.coasted > 0, what="the first coast")  # settled
    wakeups, ticks = clock.wakeups, clock.ticks
    await wait_until(lambda: clock.ticks >= ticks + 25)
    # one wake-up per tick without coasting; with it, one per up to 8 ticks (a late clock
    # runs its ticks back to back, coasted or not, so a busy machine only lowers the count)
    assert clock.wakeups - wakeups <= 10, (clock.wakeups - wakeups, clock.ticks - ticks)
    clock.poll()
    assert len(clock.jitter) == clock.ticks - clock.coasted  # coasted: not late
    assert rest.jitter().count == len(clock.jitter)
    await rest.stop()

    # a running $TIMER writes every tick: no coasting, and the timer counts every tick
    timed = Robot(VariableStore(), plant="ideal")
    timed.store.set_system("$TIMER_STOP[1]", False)
    timed.start()
    await wait_until(lambda: timed.clock.ticks >= 30)  # 0.36 s of robot time
    ticks = timed.clock.ticks
    assert timed.clock.coasted == 0 and timed.clock.coasting == 0
    assert timed.store.get("$TIMER[1]") == round(ticks * PERIOD * 1000)
    await timed.stop()


async def test_reads_after_a_coast_match_a_robot_ticked_normally() -> None:
    """Over TCP: the reply shows every tick due when it was asked for, with the values of a
    twin robot (same configuration and seed: dynamic plant, noisy torques) ticked by hand."""
    cfg = replace(TEST_CONFIG, seed=7)
    async with Emulator(cfg) as emu:
        robot = emu.robot
        assert robot is not None and robot.plant is not None
        clock = robot.clock
        async with Client("127.0.0.1", emu.port, timeout=5.0, keepalive=None) as kvp:
            await wait_until(lambda: clock.coasting > 0, what="a coast")
            # the ticks due when the read is sent: those run and those slept through so far
            asked = asyncio.get_running_loop().time()
            due = robot.kernel.ticks + max(0, math.floor((asked - clock.deadline) / PERIOD) + 1)
            torque = await kvp.read("$TORQUE_AXIS_ACT[]")
            axes = await kvp.read("$AXIS_ACT")
            last = robot.kernel.ticks  # the replies were computed after at most this many
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
    twin.begin()
    # the readings after each tick (noise is drawn from (seed, cycle): reading does not
    # disturb the twin); a busy loop may run more ticks before the reply is computed
    seen: dict[str, list[str]] = {"$TORQUE_AXIS_ACT[]": [], "$AXIS_ACT": []}
    for _ in range(last):
        twin.tick()
        for name, texts in seen.items():
            texts.append(twin.store.read(name).strip())
    torques, axes_texts = seen["$TORQUE_AXIS_ACT[]"], seen["$AXIS_ACT"]
    assert torque.strip() in torques[due - 1 :], (due, last)  # none due was left out
    at = torques.index(torque.strip(), due - 1)
    assert axes.strip() in axes_texts[at:]  # the same robot, a tick or more later


async def test_a_write_during_a_coast_is_acted_on_by_the_next_regular_tick() -> None:
    robot = Robot(VariableStore(), plant="ideal")
    seen: list[tuple[float, object]] = []
    tick = robot.clock.callback

    def traced() -> None:
        tick()
        seen.append((robot.clock.deadline - PERIOD, robot.kernel.moving))

    robot.clock.callback = traced
    robot.start()
    loop = asyncio.get_running_loop()
    await wait_until(lambda: robot.clock.coasting > 0, what="a coast")  # asleep
    before = loop.time()
    robot.store.write("MYAXIS", "{A1 20.0}")  # in process, mid-coast
    after = loop.time()
    # the ticks due before the write ran first, still at rest ...
    assert all(not moving for deadline, moving in seen if deadline <= before)
    assert robot.clock.ticks == len(seen) and robot.clock.coasting == 0
    n = len(seen)
    await wait_until(lambda: len(seen) > n)
    # ... and the first tick after it, on the regular grid, started the motion
    assert seen[n][0] > before and seen[n][1] is True
    assert seen[n][0] - after <= PERIOD + 1e-9
    await robot.stop()


async def test_a_write_over_tcp_during_a_coast_moves_the_robot_at_the_next_tick() -> None:
    async with Emulator(replace(TEST_CONFIG, plant="ideal")) as emu:
        robot = emu.robot
        assert robot is not None
        seen: list[tuple[bool, bool]] = []  # (moving, a coasted tick?) after each tick
        coasted = robot.clock.coasted
        in_tick = False
        tick, hook = robot.clock.callback, robot.store.on_write
        assert hook is not None

        def traced() -> None:
            nonlocal in_tick, coasted
            in_tick = True
            try:
                tick()
            finally:
                in_tick = False
            seen.append((robot.kernel.moving, robot.clock.coasted > coasted))
            coasted = robot.clock.coasted

        # the server polls the clock before each batch it answers: (ticks run by then, was
        # the clock coasting?)
        poll = robot.clock.poll
        polled: list[tuple[int, bool]] = []

        def traced_poll() -> None:
            coasting = robot.clock.coasting > 0
            poll()
            polled.append((len(seen), coasting))

        # (ticks so far, did a poll since the last tick end a coast?) when a write from
        # outside a tick reaches the store
        writes: list[tuple[int, bool]] = []

        def on_write() -> None:
            hook()
            if not in_tick:
                n = len(seen)
                writes.append((n, any(c for k, c in polled if k == n)))

        robot.clock.callback, robot.store.on_write = traced, on_write
        robot.clock.poll = traced_poll  # type: ignore[method-assign]
        async with Client("127.0.0.1", emu.port, timeout=5.0, keepalive=None) as kvp:
            # a busy machine may end the coast before the write arrives: then the robot
            # moves, comes to rest and coasts again, and the next target is written
            for a1 in (20.0, 25.0, 30.0):
                await wait_until(lambda: robot.clock.coasting > 0, what="a coast")
                rest = len(seen)
                del writes[:], polled[:]
                await kvp.write("MYAXIS", f"{{A1 {a1}}}")
                assert len(writes) == 1
                n, coasting = writes[0]
                await wait_until(lambda: len(seen) > n)  # noqa: B023 - n is this write's
                assert not any(moving for moving, _ in seen[rest:n])  # at rest until the write
                # ... and the first tick after it, a regular one, started the motion
                assert seen[n] == (True, False)
                if coasting:
                    break
            assert coasting, "no write arrived during a coast"
