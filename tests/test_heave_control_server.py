"""The heave control server's tasks against the real parts, in-process and short: the emulator
running heave.src (over KVP) and the platform simulator's PLC (over Modbus TCP).

The full experiment (waves, compensation off then on, attenuation figures) is
tests/test_heave_e2e.py; here each task's own duty is checked in well under a second of
control: the start-up hand-shake, the platform task's heartbeat or wave set-points and its
log, the actuation task's write of the target the robot program follows, the operator's toggle
and quit, and a clean stop.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pytest
from pyopenshowvar_apps.heave.control import READY_VARIABLE, ControlConfig, ControlServer
from pyopenshowvar_apps.heave.experiment import PROGRAM
from pyopenshowvar_apps.heave.master import PlatformClient
from pyopenshowvar_apps.heave.operator import OperatorCommand, OperatorInput
from pyopenshowvar_apps.heave.simulator import PlatformConfig, PlatformSimulator

from kukavarproxy_emu import Emulator
from kukavarproxy_emu.testing import TEST_CONFIG
from pyopenshowvar import Client


@dataclass
class TogglingOperator(OperatorInput):
    """An input device that presses the toggle once, then quits after ``polls`` polls."""

    polls: int = 10
    seen: int = 0
    closed: bool = False
    times: list[float] = field(default_factory=list)

    def poll(self, t: float) -> OperatorCommand:
        self.seen += 1
        self.times.append(t)
        return OperatorCommand(
            np.array([0.0, 0.0, 0.5]), toggle=self.seen == 1, quit=self.seen >= self.polls
        )

    def close(self) -> None:
        self.closed = True


@pytest.fixture
async def rig() -> AsyncIterator[tuple[Client, PlatformClient]]:
    emu = Emulator(replace(TEST_CONFIG, program=str(PROGRAM), plant="ideal"))
    await emu.start()
    try:
        async with PlatformSimulator(PlatformConfig(port=0, accel=False, seed=3)) as sim:
            async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
                plc = await PlatformClient("127.0.0.1", sim.port).connect()
                try:
                    await plc.configure(watchdog=1.0)
                    await plc.enable(True)
                    yield kvp, plc
                finally:
                    plc.close()
    finally:
        await emu.close()


async def _wait(cond: Any, what: str, timeout: float = 10.0) -> None:
    async with asyncio.timeout(timeout):
        # the server's logs are plain lists, with no event to wait on: poll them, bounded
        while not cond():  # noqa: ASYNC110
            await asyncio.sleep(0.01)


async def test_tasks_hold_the_start_pose_and_log_the_platform(
    rig: tuple[Client, PlatformClient],
) -> None:
    kvp, plc = rig
    # the program first drives to HEAVE_HOME (a PTP of a second or so), then says it is ready
    async with asyncio.timeout(10.0):
        while str(await kvp.read(READY_VARIABLE)).strip().upper() != "TRUE":  # noqa: ASYNC110 (a robot variable: polled)
            await asyncio.sleep(0.05)
    server = ControlServer(kvp, plc, None, config=ControlConfig(attitude="plc"))
    await server.start(wave_t0=123.0)
    assert server.wave_t0 == 123.0 and server.law is not None
    pose = await kvp.read_value("$POS_ACT")  # the law starts where the robot stands
    assert server.law.base0[:3] == pytest.approx([pose.x, pose.y, pose.z], abs=0.5)
    await _wait(lambda: len(server.rows) >= 5 and len(server.platform_rows) >= 5, "rows")
    await server.stop()
    row = server.platform_rows[-1]
    assert set(row) == {"t", "heave", "roll", "pitch", "status", "beta1", "beta2", "beta3"}
    assert abs(row["heave"]) < 1.0  # no waves: the platform stands still
    assert server.estimator.ready
    ts = [r["t"] for r in server.rows]
    assert ts == sorted(ts) and all(r["comp"] == 0.0 for r in server.rows)
    # the robot was sent the start pose: compensation off, stick centred
    target = await kvp.read_value("HEAVE_TGT")
    got = np.array([target.x, target.y, target.z, target.a, target.b, target.c])
    assert got == pytest.approx(server.law.base0, abs=1e-3)
    n = len(server.rows)
    for _ in range(50):
        await asyncio.sleep(0)
    assert len(server.rows) == n and server._tasks == []  # stopped: no task runs any more


async def test_operator_toggles_compensation_and_quits(
    rig: tuple[Client, PlatformClient],
) -> None:
    from pyopenshowvar_apps.heave.waves import WaveGenerator

    kvp, plc = rig
    operator = TogglingOperator(polls=15)
    waves = WaveGenerator.random(5)
    server = ControlServer(
        kvp, plc, None, operator=operator, config=ControlConfig(attitude="plc"), waves=waves
    )
    await server.start()
    async with asyncio.timeout(10.0):
        await server.quit.wait()  # the operator's quit
    assert server.compensate  # toggled on by the first poll
    await _wait(lambda: any(r["comp"] == 1.0 for r in server.rows), "a compensated step")
    await server.stop()
    assert operator.closed and server.error is None
    assert np.all(server.stick == [0.0, 0.0, 0.5])
    # the operator is polled at its period, not in a busy loop
    gaps = np.diff(operator.times)
    assert np.median(gaps) >= 0.5 * ControlConfig().operator_period
    # the waves drove the platform: its heave left the neutral position
    assert max(abs(r["heave"]) for r in server.platform_rows) > 1.0
