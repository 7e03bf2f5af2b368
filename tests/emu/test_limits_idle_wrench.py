"""Tests that catch three one-line bugs the rest of the suite let through (issue 16, item 11):

* the lower software limit switches ($SOFTN_END) never enforced — only +A limits were tested;
* an idle client dropped after half the idle timeout — the old test measured its lower bound
  after its own 0.6 s loop, so any drop before that passed;
* the external wrench turned into torques without $TOOL — the old expected value came from the
  same calls; here it comes from an independent computation (virtual work through FK).
"""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

from kukavarproxy_emu import Emulator
from kukavarproxy_emu.motion.kernel import MotionRefused
from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.store import VariableStore
from kukavarproxy_emu.testing import EmulatorFactory, RawClient
from pyopenshowvar import Client, Frame
from pyopenshowvar.kinematics import KR6R900SIXX, fk_matrix

SOFTN = [-170.0, -190.0, -120.0, -185.0, -120.0, -350.0]
SOFTP = [170.0, 45.0, 156.0, 185.0, 120.0, 350.0]
SAFE = np.array([0.0, -90.0, 90.0, 0.0, 30.0, 0.0])


@pytest.mark.parametrize("axis", range(6))
def test_every_lower_and_upper_software_limit_is_enforced(axis: int) -> None:
    kernel = Robot(VariableStore()).kernel
    lo, hi = SOFTN[axis], SOFTP[axis]
    for value, sign in ((lo - 0.5, "-"), (hi + 0.5, "+")):
        q = SAFE.copy()
        q[axis] = value
        with pytest.raises(MotionRefused, match=rf"Software limit switch \{sign}A{axis + 1}\b"):
            kernel.check_limits(q, "PTP")
    for value in (lo, hi):  # the limits themselves are allowed
        q = SAFE.copy()
        q[axis] = value
        kernel.check_limits(q, "PTP")


async def test_lower_limit_stops_the_program_over_kvp(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(speed=20.0, plant="ideal")  # exact texts: the ideal plant
    async with Client("127.0.0.1", emu.port) as kvp:
        await kvp.write("MYAXIS", "{A3 -121.0}")  # $SOFTN_END[3] = -120
        for _ in range(200):
            if await kvp.read("$PRO_STATE1") == "#P_STOP":
                break
            await asyncio.sleep(0.01)
        assert "Software limit switch -A3" in await kvp.read("$EMU_MESSAGE[]")
        assert await kvp.read("$AXIS_ACT.A3") == "90.0000"  # never moved


async def test_idle_client_is_not_dropped_before_the_idle_timeout(
    emulator_factory: EmulatorFactory,
) -> None:
    timeout = 0.4
    emu: Emulator = await emulator_factory(idle_timeout=timeout)
    idle = await RawClient.connect(emu.host, emu.port)
    connected = time.monotonic()
    try:
        assert await idle.is_closed_by_peer(timeout=3.0)
        lived = time.monotonic() - connected
    finally:
        await idle.close()
    # KVP drops a client silent for the whole timeout: not before it (half the timeout was a
    # bug no test saw), and soon after (the watchdog ticks every timeout / 4)
    assert timeout - 0.01 <= lived < timeout + 0.5, lived
    assert emu.stats.idle_drops == 1


def _tcp_jacobian_numeric(q_deg: np.ndarray, tool: tuple[float, ...]) -> np.ndarray:
    """∂(TCP position, m)/∂(q, rad) by central differences of the full FK with the tool."""
    h = 1e-4  # degrees
    jac = np.zeros((3, 6))
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = h
        plus = np.asarray(fk_matrix(KR6R900SIXX, q_deg + dq, tool))[:3, 3]
        minus = np.asarray(fk_matrix(KR6R900SIXX, q_deg - dq, tool))[:3, 3]
        jac[:, i] = (plus - minus) / 1000.0 / np.radians(2 * h)
    return jac


async def test_wrench_torques_use_the_tool(emulator_factory: EmulatorFactory) -> None:
    tool = (30.0, -20.0, 244.0, -90.0, 0.0, 180.0)
    force = np.array([25.0, -10.0, 40.0])  # N at the TCP, no moment
    # the ideal plant: statics torques exactly (the dynamic plant adds servo and sensor noise)
    emu = await emulator_factory(speed=20.0, plant="ideal")
    async with Client("127.0.0.1", emu.port) as kvp:
        await kvp.write("$TOOL", Frame.from_numpy(np.asarray(tool)))
        await kvp.write("MYAXIS", "{A5 30.0}")  # the default program follows MYAXIS: SAFE
        for _ in range(300):
            if np.allclose(await kvp.read_joint_angles(), SAFE, atol=1e-6):
                break
            await asyncio.sleep(0.01)
        else:
            pytest.fail("the robot did not reach SAFE")
        await asyncio.sleep(0.05)  # at rest: no inertia term
        tau0 = await kvp.read_joint_torques()
        fx, fy, fz = force
        await kvp.write("EMU_WRENCH", f"{{FX {fx}, FY {fy}, FZ {fz}, MX 0, MY 0, MZ 0}}")
        tau = tau0
        for _ in range(100):
            tau = await kvp.read_joint_torques()
            if not np.allclose(tau, tau0):
                break
            await asyncio.sleep(0.01)
    # virtual work: a force f at the TCP needs joint torques τ = (∂p/∂q)ᵀ f (in the robot's
    # torque sign convention); p is the TCP through FK *with* the tool
    expected = KR6R900SIXX.torque_sign * _tcp_jacobian_numeric(SAFE, tool).T @ force
    without_tool = KR6R900SIXX.torque_sign * _tcp_jacobian_numeric(SAFE, (0,) * 6).T @ force
    assert np.max(np.abs(expected - without_tool)) > 2.0  # the tool matters at this pose
    np.testing.assert_allclose(tau - tau0, expected, atol=0.02)
