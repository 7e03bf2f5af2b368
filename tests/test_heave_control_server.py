"""The heave control server's tasks against the real parts, in-process and short: the emulator
running heave.src (over KVP) and the platform simulator's PLC (over Modbus TCP).

The full experiment (waves, compensation off then on, attenuation figures) is
tests/test_heave_e2e.py; here each task's own duty is checked in well under a second of
control: the start-up hand-shake, the platform task's heartbeat or wave set-points and its
log, the actuation task's write of the target the robot program follows and what it tells the
lag estimator, the accelerometer board streamed through its serial device, the operator's toggle
and quit, and a clean stop.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections.abc import AsyncIterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pytest
from pyopenshowvar_apps.heave.accel import AccelReader
from pyopenshowvar_apps.heave.control import READY_VARIABLE, ControlConfig, ControlServer
from pyopenshowvar_apps.heave.estimation import LagEstimator
from pyopenshowvar_apps.heave.experiment import PROGRAM
from pyopenshowvar_apps.heave.geometry import FloatArray
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


@contextlib.asynccontextmanager
async def _rig(board: bool) -> AsyncIterator[tuple[Client, PlatformClient, PlatformSimulator]]:
    emu = Emulator(replace(TEST_CONFIG, program=str(PROGRAM), plant="ideal"))
    await emu.start()
    try:
        async with PlatformSimulator(PlatformConfig(port=0, accel=board, seed=3)) as sim:
            async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
                plc = await PlatformClient("127.0.0.1", sim.port).connect()
                try:
                    await plc.configure(watchdog=1.0)
                    await plc.enable(True)
                    yield kvp, plc, sim
                finally:
                    plc.close()
    finally:
        await emu.close()


@pytest.fixture
async def rig() -> AsyncIterator[tuple[Client, PlatformClient]]:
    async with _rig(board=False) as (kvp, plc, _):
        yield kvp, plc


@pytest.fixture
async def rig_with_board() -> AsyncIterator[tuple[Client, PlatformClient, PlatformSimulator]]:
    async with _rig(board=True) as parts:
        yield parts


class RecordingLag(LagEstimator):
    """The real lag estimator, also noting what the actuation task tells it."""

    def __init__(self, initial: float) -> None:
        super().__init__(initial)
        self.commands: list[tuple[float, FloatArray]] = []
        self.measures: list[tuple[float, FloatArray]] = []

    def command(self, t: float, xyz: FloatArray) -> None:
        self.commands.append((t, np.array(xyz, float)))
        super().command(t, xyz)

    def measured(self, t: float, xyz: FloatArray) -> None:
        self.measures.append((t, np.array(xyz, float)))
        super().measured(t, xyz)


async def _wait(cond: Any, what: str, timeout: float = 10.0) -> None:
    async with asyncio.timeout(timeout):
        # the server's logs are plain lists, with no event to wait on: poll them, bounded
        while not cond():  # noqa: ASYNC110
            await asyncio.sleep(0.01)


async def test_tasks_hold_the_start_pose_and_log_the_platform(
    rig_with_board: tuple[Client, PlatformClient, PlatformSimulator],
) -> None:
    kvp, plc, sim = rig_with_board
    # the program first drives to HEAVE_HOME (a PTP of a second or so), then says it is ready
    async with asyncio.timeout(10.0):
        while str(await kvp.read(READY_VARIABLE)).strip().upper() != "TRUE":  # noqa: ASYNC110 (a robot variable: polled)
            await asyncio.sleep(0.05)
    # the attitude fused from the PLC and the board, whose lines stream through its serial device
    assert sim.accel_path is not None
    reader = await AccelReader(sim.accel_path).open()
    try:
        # the robot stands on the platform, its base 100 mm above the platform's origin
        mount = np.eye(4)
        mount[2, 3] = 100.0
        server = ControlServer(
            kvp, plc, reader, config=ControlConfig(attitude="fused"), mount=mount
        )
        lag = server.lag = RecordingLag(server.lag.value)
        await server.start(wave_t0=123.0)  # it waits for the board's samples to reach the estimate
        assert server.wave_t0 == 123.0 and server.law is not None
        assert reader.on_sample is not None and server.estimator.ready
        assert sorted(t.get_name() for t in server._tasks) == ["actuation", "operator", "platform"]
        pose = await kvp.read_value("$POS_ACT")  # the law starts where the robot stands
        assert server.law.base0[:3] == pytest.approx([pose.x, pose.y, pose.z], abs=0.5)
        # ... and holds its flange where it is in the world: on the mount, the platform level
        assert server.law.x_s0 == pytest.approx([pose.x, pose.y, pose.z + 100.0], abs=0.5)
        await _wait(lambda: len(server.rows) >= 5 and len(server.platform_rows) >= 5, "rows")
        await server.stop()
    finally:
        reader.close()
    row = server.platform_rows[-1]
    assert set(row) == {"t", "heave", "roll", "pitch", "status", "beta1", "beta2", "beta3"}
    assert abs(row["heave"]) < 1.0  # no waves: the platform stands still
    # the board sees the level plate too: the fused offset is within its noise (0.01 g a sample)
    assert np.all(np.abs(server.estimator.offset) < 2.0), server.estimator.offset
    ts = [r["t"] for r in server.rows]
    assert ts == sorted(ts) and all(r["comp"] == 0.0 for r in server.rows)
    # each step's time step is the time since the previous step's angles came back
    rows = list(server.rows)
    for before, row in itertools.pairwise(rows):
        assert row["dt"] == pytest.approx(row["t"] - before["t"], abs=1e-9)
    # the robot was sent the start pose: compensation off, stick centred
    target = await kvp.read_value("HEAVE_TGT")
    got = np.array([target.x, target.y, target.z, target.a, target.b, target.c])
    assert got == pytest.approx(server.law.base0, abs=1e-3)
    # the lag estimator got, each pass, the position sent when it was sent and the robot's
    # flange position (base frame) when its angles came back: both the standing start pose
    assert len(lag.commands) == len(lag.measures) == len(server.rows)
    for (t_cmd, cmd), (t_meas, meas), r in zip(
        lag.commands, lag.measures, server.rows, strict=True
    ):
        assert t_cmd < t_meas == r["t"]
        assert cmd == pytest.approx([target.x, target.y, target.z], abs=1e-3)
        assert meas == pytest.approx([pose.x, pose.y, pose.z], abs=0.5)
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
    assert server.platform_rows  # started once the platform had answered
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
