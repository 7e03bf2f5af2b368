"""The KUKA path: the control server drives the emulator over real KVP through KVP_JOG.

The emulator runs in its own thread (its IPO clock must not wait for a solver that holds the
test's event loop) with its default dynamic plant, so ``$POS_ACT`` is a measurement of the
simulated arm, not an echo of our commands. Deadlines are wall-clock and generous (the
machine is shared); the bounds themselves come from the safety design (deadline, cadence,
credit), not from timing luck.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterator

import numpy as np
import pytest
from pyopenshowvar_apps.universal.backend import BackendError
from pyopenshowvar_apps.universal.inputs import ScriptedInput, hold
from pyopenshowvar_apps.universal.kvparm import TCP_LIMIT, KvpArm
from pyopenshowvar_apps.universal.server import ControlServer
from pyopenshowvar_apps.web.jogplan import CADENCE, CREDIT
from pyopenshowvar_apps.web.runner import KRL_DIR

from kukavarproxy_emu import EmulatorConfig, EmulatorThread
from pyopenshowvar import Client
from pyopenshowvar.arms import load_arm

KR6 = load_arm("kr6_r900_sixx")


@pytest.fixture
def jog_emu() -> Iterator[EmulatorThread]:
    config = EmulatorConfig(port=0, latency="none", discovery=False,
                            program=str(KRL_DIR / "kvp_jog.src"),
                            config_files=(KRL_DIR / "kvp_jog_config.dat",))  # fmt: skip
    emu = EmulatorThread(config).start()
    try:
        yield emu
    finally:
        emu.stop()


async def _tcp(kvp: Client) -> np.ndarray:
    pose = await kvp.read_value("$POS_ACT")
    return np.array([pose["X"], pose["Y"], pose["Z"]], dtype=float)  # type: ignore[index]


async def _ready(kvp: Client) -> None:
    async with asyncio.timeout(20):
        while (await kvp.read("$PRO_STATE1")).strip() != "#P_ACTIVE":  # noqa: ASYNC110 - polling KVP is what a client does
            await asyncio.sleep(0.05)


async def _until_near(kvp: Client, goal: np.ndarray, tol: float, timeout: float) -> np.ndarray:
    async with asyncio.timeout(timeout):
        while np.linalg.norm((tcp := await _tcp(kvp)) - goal) > tol:  # noqa: ASYNC110
            await asyncio.sleep(0.05)
    return tcp


async def _still(kvp: Client, timeout: float = 10.0) -> np.ndarray:
    """The axes once they stand still (0.01° over 0.1 s)."""
    async with asyncio.timeout(timeout):
        a = await kvp.read_joint_angles()
        while True:
            await asyncio.sleep(0.1)
            b = await kvp.read_joint_angles()
            if np.max(np.abs(a - b)) < 0.01:
                return np.asarray(b)
            a = b


async def test_scripted_input_moves_the_tcp_where_asked(jog_emu: EmulatorThread) -> None:
    async with Client("127.0.0.1", jog_emu.port, timeout=2.0) as kvp:
        await _ready(kvp)
        start = await _tcp(kvp)
        device = ScriptedInput(hold((0.5, 0.0, 0.3)))
        server = ControlServer(KvpArm(KR6, "127.0.0.1", jog_emu.port), device,
                               solver="closed-form", mode="position", k_p=100.0)  # fmt: skip
        await server.start()
        task = asyncio.create_task(server.run())
        try:
            # x_ds = k_p·s + x_w (eq. 2.7): 50 mm along X and 30 mm up, by $POS_ACT
            await _until_near(kvp, start + np.array([50.0, 0.0, 30.0]), 1.0, 30.0)
            device.script = hold((0.0, 0.0, 0.0))  # released: back to the start
            await _until_near(kvp, start, 1.0, 30.0)
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
            await server.close()
        assert await kvp.read("JOG_MODE") == "0"  # the way out stopped the jog


async def test_the_robot_stops_when_the_input_falls_silent(jog_emu: EmulatorThread) -> None:
    async with Client("127.0.0.1", jog_emu.port, timeout=2.0) as kvp:
        await _ready(kvp)
        device = ScriptedInput(hold((0.6, 0.0, 0.0)), duration=1.5, end="silent")
        server = ControlServer(KvpArm(KR6, "127.0.0.1", jog_emu.port), device,
                               solver="dls", mode="velocity", deadline=0.25)  # fmt: skip
        await server.start()
        task = asyncio.create_task(server.run())
        try:
            async with asyncio.timeout(20):
                while not any(t.alive for t in server.ticks):  # noqa: ASYNC110 - watching the loop
                    await asyncio.sleep(0.02)
            first = next(t for t in server.ticks if t.alive)
            async with asyncio.timeout(20):  # moving...
                while server.ticks[-1].t - first.t < 1.2:  # noqa: ASYNC110
                    await asyncio.sleep(0.02)
            moving = await _tcp(kvp)
            assert np.linalg.norm(moving - server.solver.fk(first.q)) > 20.0
            async with asyncio.timeout(20):  # ...until the device falls silent
                while server.ticks[-1].alive:  # noqa: ASYNC110
                    await asyncio.sleep(0.005)
            assert await kvp.read("JOG_MODE") == "0"  # the server stopped the jog
            silent_at = first.t + 1.5
            stopped_tick = server.ticks[-1]
            # within the deadline and three periods of the loop as it ran then: a loaded
            # machine spaces the ticks wider than the nominal period
            times = [t.t for t in server.ticks if t.t >= silent_at - server.period]
            period = max([server.period, *np.diff(times)])
            assert stopped_tick.t - silent_at <= server.deadline + 3 * period, period
            at_stop = await _tcp(kvp)
            q_still = await _still(kvp)
            rest = server.solver.fk(q_still)
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
            await server.close()
        # what the robot may still travel once the server stopped: the increments in flight
        # (the credit, 5 × 20 ms, plus the ones planned behind) at the flange speed limit
        assert np.linalg.norm(rest - at_stop) <= TCP_LIMIT * (CREDIT + 3) * CADENCE
        assert np.linalg.norm(rest - at_stop) <= np.linalg.norm(at_stop - moving) + 60.0


async def test_the_connected_robot_must_be_the_arm(jog_emu: EmulatorThread) -> None:
    backend = KvpArm(load_arm("kr10_r1100_2"), "127.0.0.1", jog_emu.port)
    with pytest.raises(BackendError, match=r"KR6R900SIXX.*not a #KR10R1100-2"):
        await backend.start()
    await backend.close()
    with pytest.raises(BackendError, match="only KUKA six-axis arms"):
        KvpArm(load_arm("kuka_youbot_arm"), "127.0.0.1", jog_emu.port)


async def test_kvp_jog_must_be_running() -> None:
    emu = EmulatorThread(EmulatorConfig(port=0, latency="none", discovery=False)).start()
    try:
        backend = KvpArm(KR6, "127.0.0.1", emu.port)
        with pytest.raises(BackendError, match="KVP_JOG"):
            await backend.start()
        await backend.close()
    finally:
        emu.stop()


async def test_commands_are_clamped_to_the_jog_limits() -> None:
    backend = KvpArm(KR6, "127.0.0.1", 1, speed_scale=0.5)
    q = KR6.home_q + np.array([0, 0, 0, 0, 30.0, 0])
    u = backend.clamp(q, np.full(6, 1000.0))
    assert np.all(np.abs(u) <= 0.5 * np.fmin(KR6.max_speed, KR6.max_accel * CADENCE) + 1e-9)
    v = KR6.jacobian(q)[:3] @ np.radians(u)
    assert np.linalg.norm(v) <= TCP_LIMIT + 1e-6
    # an axis at its limit is not pushed further
    at_limit = KR6.home_q.copy()
    at_limit[0] = backend.upper[0]
    assert backend.clamp(at_limit, np.array([10.0, 0, 0, 0, 0, 0]))[0] == 0.0
