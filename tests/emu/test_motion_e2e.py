"""The simulated robot over real TCP: pyopenshowvar.Client against the emulator at 20× speed."""

from __future__ import annotations

import asyncio
from typing import Any

import numpy as np
import pytest

from kukavarproxy_emu.__main__ import build_parser, config_from_args
from kukavarproxy_emu.motion import ptp_profile
from pyopenshowvar import Client
from pyopenshowvar.kinematics import KR6R900SIXX, forward, status_turn, wrench_to_torques
from pyopenshowvar.krl import E6Pos, Struct, format_krc4

SPEED = 20.0
IPO = 0.012
HOME = np.array([0.0, -90.0, 90.0, 0.0, 0.0, 0.0])


async def wait_for(cond: Any, timeout: float = 5.0) -> None:
    async with asyncio.timeout(timeout):
        while not await cond():  # noqa: ASYNC110 - polling over KVP is what a client does
            await asyncio.sleep(0.002)


async def test_myaxis_arrives_in_the_predicted_time(emulator_factory: Any) -> None:
    emu = await emulator_factory(plant="ideal", speed=SPEED)
    emu.robot.kernel.trace = []
    target = np.array([40.0, -70.0, 100.0, 20.0, 30.0, 40.0])
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        await kvp.write("MYAXIS", "{A1 40, A2 -70, A3 100, A4 20, A5 30, A6 40}")

        async def arrived() -> bool:
            return await kvp.read("$AXIS_ACT.A6") == "40.0000"

        await wait_for(arrived)
        await asyncio.sleep(2 * IPO / SPEED)
        pos = await kvp.read("$POS_ACT")
    trace = emu.robot.kernel.trace
    moving = [t for t, _q, qd in trace if np.any(qd != 0)]
    measured = moving[-1] - moving[0] + IPO
    predicted = ptp_profile(target - HOME, KR6R900SIXX.max_speed, KR6R900SIXX.max_accel).duration
    assert measured == pytest.approx(predicted, abs=2 * IPO)
    np.testing.assert_array_equal(emu.robot.q, target)
    # $POS_ACT is the KRC4 text of the forward-kinematics pose
    s, t = status_turn(KR6R900SIXX, target)
    fk = E6Pos.from_numpy(np.concatenate([forward(KR6R900SIXX, target), np.zeros(6)]), s=s, t=t)
    assert pos == format_krc4(fk)


async def test_ov_pro_50_halves_the_speed(emulator_factory: Any) -> None:
    durations = []
    for ov in ("100", "50"):
        emu = await emulator_factory(speed=SPEED)
        emu.robot.kernel.trace = []
        async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
            await kvp.write("$OV_PRO", ov)
            await kvp.write("MYAXIS", "{A1 150}")

            async def arrived(kvp: Client = kvp) -> bool:
                return await kvp.read("$AXIS_ACT.A1") == "150.000"

            await wait_for(arrived)
        moving = [t for t, _q, qd in emu.robot.kernel.trace if qd[0] != 0]
        durations.append(moving[-1] - moving[0] + IPO)
        peak = max(abs(qd[0]) for _t, _q, qd in emu.robot.kernel.trace)
        assert peak <= KR6R900SIXX.max_speed[0] * int(ov) / 100 * (1 + 1e-9)
    assert durations[1] == pytest.approx(2 * durations[0], abs=2 * IPO)


async def test_out_of_limit_target_is_refused_and_reported(emulator_factory: Any) -> None:
    emu = await emulator_factory(plant="ideal", speed=SPEED)
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        await kvp.write("MYAXIS", "{A2 50.0}")  # $SOFTP_END[2] = 45

        async def stopped() -> bool:
            return await kvp.read("$PRO_STATE1") == "#P_STOP"

        await wait_for(stopped)
        assert await kvp.read("$STOPMESS") == "TRUE"
        assert "Software limit switch +A2" in await kvp.read("$EMU_MESSAGE[]")
        assert await kvp.read("$AXIS_ACT.A2") == "-90.0000"  # never moved
        await kvp.write("MYAXIS", "{A2 -85.0}")
        await kvp.write("EMU_RESTART", "TRUE")

        async def running_again() -> bool:
            return await kvp.read("$AXIS_ACT.A2") == "-85.0000"

        await wait_for(running_again)
        assert await kvp.read("$PRO_STATE1") == "#P_ACTIVE"


async def test_wrench_written_over_kvp_shows_as_jt_f(emulator_factory: Any) -> None:
    emu = await emulator_factory(plant="ideal", speed=SPEED)
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        home = [float(v) for v in (await kvp.read("$TORQUE_AXIS_ACT[]")).split()][:6]
        np.testing.assert_allclose(home, [0, -24.8, -25.5, -0.8, -0.6, 0], atol=1.0)
        await kvp.write("EMU_WRENCH", "{FX 0.0, FY 30.0, FZ -40.0, MX 0.0, MY 0.0, MZ 2.0}")
        tau0 = np.array(home)

        async def changed() -> bool:
            return (await kvp.read("$TORQUE_AXIS_ACT[1]")) != "0.0"

        await wait_for(changed)
        tau = np.array([float(v) for v in (await kvp.read("$TORQUE_AXIS_ACT[]")).split()][:6])
    expected = wrench_to_torques(KR6R900SIXX, HOME, [0.0, 30.0, -40.0, 0.0, 0.0, 2.0])
    np.testing.assert_allclose(tau - tau0, expected, atol=0.05)  # tau0 rounded to the table


async def test_joint_path_handshake_end_to_end(emulator_factory: Any) -> None:
    emu = await emulator_factory(plant="ideal", speed=SPEED, program="joint_path")
    points = [[5.0 * i, -90.0 + 3 * i, 90.0 - 2 * i, 0.0, 10.0 + i, -i] for i in range(1, 6)]
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        assert await kvp.read("$PRO_NAME1[]") == '"JOINT_PATH"'
        await kvp.write_joint_path(points)
        await kvp.wait_path_done(poll=0.002, timeout=5.0)
        assert await kvp.read_value("PATH_BUSY") is False
        assert await kvp.read_value("PATH_START") is False
        assert await kvp.read_value("PATH_INDEX") == 5
        axis = await kvp.read_value("$AXIS_ACT")
    assert isinstance(axis, Struct)
    np.testing.assert_allclose([float(axis[f"A{i}"]) for i in range(1, 7)], points[-1], atol=1e-4)  # type: ignore[arg-type]


async def test_cart_path_with_lin_end_to_end(emulator_factory: Any) -> None:
    emu = await emulator_factory(plant="ideal", speed=SPEED, program="cart_path")
    emu.robot.kernel.ptp([0.0, -80.0, 80.0, 0.0, 30.0, 0.0])  # leave HOME's wrist singularity
    await asyncio.sleep(1.0 / SPEED)
    start = forward(KR6R900SIXX, emu.robot.q)
    pts = [list(start + np.array([0.0, 40.0 * i, -30.0 * i, 0.0, 0.0, 0.0])) for i in (1, 2, 3)]
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        await kvp.write_cartesian_path(pts)
        await kvp.wait_path_done(poll=0.002, timeout=5.0)
        pos = await kvp.read_value("$POS_ACT")
    assert isinstance(pos, Struct)
    got = np.array([float(pos[k]) for k in "XYZABC"])  # type: ignore[arg-type]
    diff = got - np.array(pts[-1])
    diff[3:] = (diff[3:] + 180.0) % 360.0 - 180.0  # A/C = 180 and -180 are the same angle
    np.testing.assert_allclose(diff, 0.0, atol=1e-3)


async def test_sps_copies_output_vars(emulator_factory: Any) -> None:
    emu = await emulator_factory(speed=SPEED)
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        await kvp.write("OUTPUT_VARS[7]", "TRUE")

        async def copied() -> bool:
            return await kvp.read("$OUT[7]") == "TRUE"

        await wait_for(copied, timeout=1.0)


async def test_no_robot_and_jitter_stats(emulator_factory: Any) -> None:
    still = await emulator_factory(robot=False)
    assert still.robot is None
    emu = await emulator_factory(speed=SPEED)
    # a robot at rest coasts (its late-on-purpose ticks are not counted): poll, with a deadline

    async def counted() -> bool:
        return bool(emu.robot.jitter().count > 10)

    await wait_for(counted, timeout=5.0)
    stats = emu.robot.jitter()
    assert stats.count > 10 and stats.max >= stats.p99 >= stats.p50 >= 0


def test_cli_options_reach_the_config() -> None:
    args = build_parser().parse_args(
        ["--program", "cart_path", "--speed", "5", "--ipo", "0.004", "--no-robot"]
    )
    cfg = config_from_args(args)
    assert (cfg.program, cfg.speed, cfg.ipo, cfg.robot) == ("cart_path", 5.0, 0.004, False)
    assert config_from_args(build_parser().parse_args([])).robot is True
    # a program is a shipped name or a .src file: anything else is a usage error
    with pytest.raises(ValueError, match="unknown program"):
        config_from_args(build_parser().parse_args(["--program", "nope"]))
