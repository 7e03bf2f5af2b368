"""The motion kernel without sockets: profiles, limits, approximation, torques, programs.

A :class:`Robot` on a plain store is ticked by hand, so simulated time is exact and the tests
are deterministic and fast.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from kukavarproxy_emu.config import ROBOT_PROGRAMS
from kukavarproxy_emu.motion import Trapezoid, ptp_profile
from kukavarproxy_emu.program_factory import PROGRAMS
from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.store import VariableStore
from pyopenshowvar.kinematics import KR6R900SIXX, gravity_torques, wrench_to_torques
from pyopenshowvar.krl import E6Axis

IPO = 0.012
HOME = np.array([0.0, -90.0, 90.0, 0.0, 0.0, 0.0])
VMAX, AMAX = KR6R900SIXX.max_speed, KR6R900SIXX.max_accel


def axis_text(q: np.ndarray) -> str:
    return "{" + ", ".join(f"A{i + 1} {v!r}" for i, v in enumerate(q.tolist())) + "}"


def make_robot(program: str = "follow", start: np.ndarray | None = None) -> Robot:
    store = VariableStore()
    if start is not None:
        store.set_system("$AXIS_ACT", E6Axis.from_numpy(np.concatenate([start, np.zeros(6)])))
    robot = Robot(store, program=program)
    robot._begin()
    robot.kernel.trace = []
    return robot


def run_until_still(robot: Robot, limit: int = 3000) -> None:
    """Tick until the robot has moved and come to rest again (program keeps running)."""
    moved = False
    for _ in range(limit):
        robot.tick()
        moving = robot.kernel.moving or bool(np.any(robot.kernel.qd))
        moved |= moving
        if moved and not moving:
            return
    raise AssertionError("robot did not come to rest")


def predicted_duration(delta: np.ndarray, vel: float = 1.0, acc: float = 1.0) -> float:
    """Synchronised trapezoid, computed independently of the kernel's profile module."""
    d = np.abs(delta)
    moving = d > 1e-12
    vs = float(np.min(VMAX[moving] * vel / d[moving]))
    as_ = float(np.min(AMAX[moving] * acc / d[moving]))
    if vs * vs / as_ <= 1.0:
        return 1.0 / vs + vs / as_
    return 2.0 * math.sqrt(1.0 / as_)


def moving_span(robot: Robot) -> tuple[float, float]:
    trace = robot.kernel.trace
    assert trace
    times = [t for t, _q, qd in trace if np.any(np.abs(qd) > 1e-12)]
    return times[0] - IPO, times[-1]


def test_program_names_match_config() -> None:
    assert set(PROGRAMS) == set(ROBOT_PROGRAMS)


def test_trapezoid_shapes() -> None:
    full = Trapezoid.plan(2.0, 4.0)  # reaches v: t_acc 0.5, cruise 0.25
    assert full.duration == pytest.approx(1.0 / 2.0 + 0.5)
    assert full.s(full.duration) == 1.0 and full.s(0.0) == 0.0
    assert full.s(full.duration / 2) == pytest.approx(0.5)
    tri = Trapezoid.plan(100.0, 4.0)  # never reaches v
    assert tri.duration == pytest.approx(2 * math.sqrt(1 / 4.0))
    assert tri.ds(tri.t_acc) == pytest.approx(4.0 * tri.t_acc)
    assert full.time_at_remaining(0.0) == full.duration
    assert 1 - full.s(full.time_at_remaining(0.3)) == pytest.approx(0.3)
    assert Trapezoid.plan(math.inf, math.inf).duration == 0.0


def test_ptp_profile_is_synchronised_and_within_limits() -> None:
    delta = np.array([100.0, -20.0, 50.0, 180.0, -5.0, 300.0])
    prof = ptp_profile(delta, VMAX, AMAX)
    assert prof.duration == pytest.approx(predicted_duration(delta))
    ts = np.linspace(0.0, prof.duration, 2001)
    speed = np.array([np.abs(delta) * prof.ds(t) for t in ts])
    assert np.all(speed <= VMAX * (1 + 1e-9))
    assert np.all(np.abs(delta) * prof.a <= AMAX * (1 + 1e-9))


@pytest.mark.parametrize("ov", [100, 50, 30])
def test_ptp_duration_sync_and_speed_limit(ov: int) -> None:
    robot = make_robot()
    robot.store.write("$OV_PRO", str(ov))
    robot.store.write("$VEL_AXIS[1]", "80")
    target = np.array([120.0, -60.0, 100.0, 30.0, 40.0, -90.0])
    robot.store.write("MYAXIS", axis_text(target))
    run_until_still(robot)
    np.testing.assert_array_equal(robot.q, target)  # exact stop on the target
    start, end = moving_span(robot)
    vel = np.ones(6)
    vel[0] = 0.8
    d = np.abs(target - HOME)
    expected = ptp_profile(target - HOME, VMAX * vel, AMAX).duration / (ov / 100)
    assert end - start == pytest.approx(expected, abs=2 * IPO)
    # no per-cycle step ever exceeds max × $VEL_AXIS × $OV_PRO
    limit = VMAX * vel * ov / 100
    qs = np.array([q for _t, q, _qd in robot.kernel.trace])
    steps = np.abs(np.diff(qs, axis=0)) / IPO
    assert np.all(steps <= limit * (1 + 1e-9))
    # synchronised: every moving axis reaches its target on the same cycle
    arrival = [int(np.argmax(np.abs(qs[:, i] - target[i]) < 1e-12)) for i in range(6) if d[i] > 0]
    assert len(set(arrival)) == 1


def test_override_50_doubles_a_speed_limited_move() -> None:
    durations = []
    for ov in (100, 50):
        robot = make_robot()
        robot.store.write("$OV_PRO", str(ov))
        robot.store.write("MYAXIS", "{A1 160.0}")
        run_until_still(robot)
        start, end = moving_span(robot)
        durations.append(end - start)
    assert durations[1] / durations[0] == pytest.approx(2.0, abs=2 * IPO / durations[0])


def test_override_change_acts_on_the_running_motion() -> None:
    robot = make_robot()
    robot.store.write("MYAXIS", "{A1 160.0}")
    for _ in range(20):
        robot.tick()
    robot.store.write("$OV_PRO", "10")
    for _ in range(60):
        robot.tick()
    assert abs(robot.kernel.qd[0]) <= VMAX[0] * 0.1 + 1e-9  # slewed down to 10 %
    run_until_still(robot)
    assert robot.q[0] == 160.0


def test_software_limit_refuses_and_stops_the_program() -> None:
    robot = make_robot()
    robot.store.write("MYAXIS", "{A1 60.0}")
    for _ in range(10):
        robot.tick()
    robot.store.write("MYAXIS", "{A1 171.0}")  # planned behind the running move: refused
    run_until_still(robot)
    assert robot.store.read("$PRO_STATE1") == "#P_STOP"
    assert robot.store.read("$STOPMESS") == "TRUE"
    assert "+A1" in robot.store.read("$EMU_MESSAGE[]")
    assert robot.q[0] == 60.0  # the running move ended exactly, the refused one never started
    assert max(q[0] for _t, q, _qd in robot.kernel.trace) <= 60.0
    # acknowledge over the variable: the program runs again and follows a valid target
    robot.store.write("MYAXIS", "{A1 20.0}")
    robot.store.write("EMU_RESTART", "TRUE")
    run_until_still(robot)
    assert robot.store.read("$PRO_STATE1") == "#P_ACTIVE"
    assert robot.store.read("$STOPMESS") == "FALSE" and robot.store.read("$EMU_MESSAGE[]") == '""'
    assert robot.q[0] == 20.0


def test_rest_state_is_not_rewritten() -> None:
    robot = make_robot()
    before = {n: robot.store.read(n) for n in ("$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[]")}
    for _ in range(20):
        robot.tick()
    assert {n: robot.store.read(n) for n in before} == before


def test_torques_at_home_and_external_wrench() -> None:
    robot = make_robot()
    robot.kernel.publish(force=True)
    tau = [float(v) for v in robot.store.read("$TORQUE_AXIS_ACT[]").split()]
    np.testing.assert_allclose(tau[:6], [0, -24.8, -25.5, -0.8, -0.6, 0], atol=1.0)
    wrench = [10.0, -20.0, -50.0, 1.0, 2.0, -3.0]
    robot.apply_wrench(wrench)
    robot.tick()
    tau2 = np.array([float(v) for v in robot.store.read("$TORQUE_AXIS_ACT[]").split()][:6])
    expected = gravity_torques(KR6R900SIXX, HOME) + wrench_to_torques(KR6R900SIXX, HOME, wrench)
    np.testing.assert_allclose(tau2, expected, atol=1e-3)
    # a payload from $LOAD adds to gravity (6 kg 50 mm out: §3.3 table)
    robot.apply_wrench([0.0] * 6)
    robot.store.write("$LOAD", "{M 6.0, CM {X 0.0, Y 0.0, Z 50.0}}")
    robot.tick()
    tau3 = [float(v) for v in robot.store.read("$TORQUE_AXIS_ACT[]").split()][:6]
    np.testing.assert_allclose(tau3, [0, -57.2, -57.9, -0.8, -8.3, 0], atol=1.0)


def test_inertial_term_follows_the_acceleration() -> None:
    robot = make_robot()
    robot.store.write("MYAXIS", "{A1 90.0}")
    robot.tick()
    robot.tick()
    tau1 = float(robot.store.read("$TORQUE_AXIS_ACT[1]"))
    assert tau1 == pytest.approx(robot.kernel.inertia[0] * math.radians(AMAX[0]), rel=0.05)
    assert float(robot.store.read("$VEL_AXIS_ACT[1]")) > 0


def test_c_ptp_blends_but_the_last_point_is_exact() -> None:
    robot = make_robot("joint_path")
    store = robot.store
    points = [HOME + np.array([10.0 * i, 0, 0, 0, 0, 0]) for i in (1, 2, 3)]
    for i, p in enumerate(points, start=1):
        store.write(f"MYE6ARRAY[{i}]", axis_text(p))
    store.write("PATH_COUNT", "3")
    store.write("PATH_START", "TRUE")
    for _ in range(1000):
        robot.tick()
        if store.get("PATH_DONE") is True:
            break
    assert store.get("PATH_DONE") is True and store.get("PATH_BUSY") is False
    assert store.get("PATH_START") is False and store.get("PATH_INDEX") == 3
    np.testing.assert_array_equal(robot.q, points[-1])
    speeds = [qd[0] for _t, _q, qd in robot.kernel.trace]
    first = next(i for i, v in enumerate(speeds) if v > 0)
    last = max(i for i, v in enumerate(speeds) if v > 0)
    assert all(v > 0 for v in speeds[first : last + 1])  # never stops at a junction
    assert not any(q[0] in (10.0, 20.0) for _t, q, _qd in robot.kernel.trace)  # blended past
    assert max(speeds) <= VMAX[0] * (1 + 1e-9)


def test_zero_advance_stops_exactly_between_segments() -> None:
    robot = make_robot("joint_path")
    store = robot.store
    store.write("$ADVANCE", "0")
    for i in (1, 2):
        store.write(f"MYE6ARRAY[{i}]", axis_text(HOME + np.array([20.0 * i, 0, 0, 0, 0, 0])))
    store.write("PATH_COUNT", "2")
    store.write("PATH_START", "TRUE")
    for _ in range(1000):
        robot.tick()
        if store.get("PATH_DONE") is True:
            break
    # no approximation without look-ahead: the robot stops exactly on point 1 (speed 0 at
    # that instant; the next motion is planned and starts in the following cycle)
    assert any(q[0] == 20.0 for _t, q, _qd in robot.kernel.trace)
    assert robot.q[0] == 40.0


def test_follower_captures_the_target_at_planning_time() -> None:
    robot = make_robot()
    robot.store.write("MYAXIS", "{A1 30.0}")
    robot.tick()
    # the advance run has planned the move plus zero-length repeats up to $ADVANCE (3)
    assert robot.kernel.queued == 3
    robot.store.write("MYAXIS", "{A1 -30.0}")  # arrives after the queued segments
    robot.tick()
    assert robot.kernel.planned_q[0] == 30.0
    run_until_still(robot)
    assert robot.q[0] == -30.0
    # the zero-length repeats of 30 came first: the robot stopped exactly on 30 on the way
    assert any(q[0] == 30.0 for _t, q, _qd in robot.kernel.trace)


def test_actuator_rel_moves_relative_to_the_planned_end_point() -> None:
    robot = make_robot("actuator")
    store = robot.store
    robot.tick()  # actuator.src: PTP HOME (already there), then $ADVANCE=1
    assert store.read("$ADVANCE") == "1" and store.read("$PRO_NAME1[]") == '"ACTUATOR"'
    x0 = float(store.read("$POS_ACT.X"))
    store.write("MYPOS", "{X 2.0}")
    for _ in range(25):
        robot.tick()
    store.write("MYPOS", "{X 0.0}")
    run_until_still(robot)
    x1 = float(store.read("$POS_ACT.X"))
    steps = round((x1 - x0) / 2.0)
    assert steps >= 2 and x1 - x0 == pytest.approx(2.0 * steps, abs=1e-3)


def test_lin_from_home_runs() -> None:
    """docs/emulator-robot.md: a LIN that starts on the A5 = 0 singularity of HOME is not refused."""
    from pyopenshowvar.kinematics import forward

    robot = make_robot("cart_path")  # HOME: A5 = 0
    store = robot.store
    goal = forward(KR6R900SIXX, HOME) + np.array([0.0, 150.0, -190.0, 10.0, 0.0, 0.0])
    store.write(
        "MYPOSARRAY[1]",
        "{" + ", ".join(f"{k} {v!r}" for k, v in zip("XYZABC", goal.tolist(), strict=True)) + "}",
    )
    store.write("PATH_COUNT", "1")
    store.write("PATH_START", "TRUE")
    for _ in range(2000):
        robot.tick()
        if store.get("PATH_DONE") is True:
            break
    assert store.get("PATH_DONE") is True and store.read("$PRO_STATE1") == "#P_ACTIVE"
    pos = store.get("$POS_ACT")
    np.testing.assert_allclose([pos[k] for k in "XYZ"], goal[:3], atol=1e-3)  # type: ignore[index]


def test_lin_is_straight_and_ends_on_the_pose() -> None:
    # start away from the A5 = 0 wrist singularity of HOME (test_lin_from_home_runs starts there)
    q0 = np.array([0.0, -80.0, 80.0, 0.0, 30.0, 0.0])
    robot = make_robot("cart_path", start=q0)
    store = robot.store
    from pyopenshowvar.kinematics import forward

    p0 = forward(KR6R900SIXX, q0)
    goal = p0 + np.array([0.0, 150.0, -190.0, 10.0, 0.0, 0.0])
    store.write(
        "MYPOSARRAY[1]",
        "{" + ", ".join(f"{k} {v!r}" for k, v in zip("XYZABC", goal.tolist(), strict=True)) + "}",
    )
    store.write("PATH_COUNT", "1")
    store.write("PATH_START", "TRUE")
    for _ in range(2000):
        robot.tick()
        if store.get("PATH_DONE") is True:
            break
    pos = store.get("$POS_ACT")
    got = np.array([pos[k] for k in "XYZABC"])  # type: ignore[index]
    np.testing.assert_allclose(got[:3], goal[:3], atol=1e-3)
    turn = (got[3:] - goal[3:] + 180.0) % 360.0 - 180.0  # A 190 is reported as A -170
    np.testing.assert_allclose(turn, 0.0, atol=1e-3)
    xyz = np.array([forward(KR6R900SIXX, q)[:3] for _t, q, _qd in robot.kernel.trace])
    a, b = p0[:3], goal[:3]
    u = (b - a) / np.linalg.norm(b - a)
    off = (xyz - a) - np.outer((xyz - a) @ u, u)
    assert np.max(np.linalg.norm(off, axis=1)) < 1e-6
    speed = np.linalg.norm(np.diff(xyz, axis=0), axis=1) / IPO / 1000.0
    assert np.max(speed) <= 2.0 + 1e-9  # $VEL.CP


def test_unreachable_lin_is_refused() -> None:
    robot = make_robot("cart_path")
    store = robot.store
    store.write("MYPOSARRAY[1]", "{X 1500.0, Y 0.0, Z 890.0, A 0.0, B 90.0, C 0.0}")
    store.write("PATH_COUNT", "1")
    store.write("PATH_START", "TRUE")
    for _ in range(5):
        robot.tick()
    assert store.read("$PRO_STATE1") == "#P_STOP"
    assert "LIN MYPOSARRAY[1]" in store.read("$EMU_MESSAGE[]")
    np.testing.assert_array_equal(robot.q, HOME)


def test_sps_copies_outputs_every_cycle() -> None:
    robot = make_robot("none")
    assert robot.store.read("$PRO_STATE1") == "#P_FREE"
    robot.store.write("OUTPUT_VARS[2]", "TRUE")
    robot.tick()
    assert robot.store.read("$OUT[2]") == "TRUE" and robot.store.read("$OUT[1]") == "FALSE"
    robot.store.write("OUTPUT_VARS[2]", "FALSE")
    robot.tick()
    assert robot.store.read("$OUT[2]") == "FALSE"


def test_measurement_noise_is_seeded_and_tiny() -> None:
    robot = Robot(VariableStore(), noise=1e-5, seed=3)
    robot._begin()
    robot.tick()
    meas = robot.store.get("$AXIS_ACT_MEAS")
    assert robot.store.read("$AXIS_ACT").startswith("{E6AXIS: A1 0.0, A2 -90.0000")
    diff = np.array([meas[f"A{i}"] for i in range(1, 7)]) - HOME  # type: ignore[index]
    assert 0 < np.max(np.abs(diff)) < 1e-4


def test_consecutive_exact_lins_lose_no_motion() -> None:
    # Thirty short exact LINs (each starts in the cycle its predecessor ends) must add up to
    # the whole path: each one is based on its predecessor's end pose.
    q0 = np.array([0.0, -80.0, 80.0, 0.0, 30.0, 0.0])
    robot = make_robot("none", start=q0)
    from pyopenshowvar.kinematics import forward

    p0 = forward(KR6R900SIXX, q0)
    kernel = robot.kernel
    points = [p0 + np.array([0.0, 2.0 * i, 0.0, 0.0, 0.0, 0.0]) for i in range(1, 31)]
    for p in points:
        kernel.lin(p)  # no approximation: each segment stops exactly
    for _ in range(3000):
        robot.tick()
        if not kernel.moving and not kernel.queued:
            break
    final = forward(KR6R900SIXX, kernel.q)
    np.testing.assert_allclose(final[:3], points[-1][:3], atol=1e-3)


async def test_clock_poll_runs_a_due_tick_once() -> None:
    # The server polls the clock before answering a batch: a due tick runs right there, and
    # the clock's own timer must not run the same tick a second time.
    import asyncio
    import time as _time

    from kukavarproxy_emu.motion import IpoClock

    # A loaded machine may pause this process between two lines: each "not yet" check only
    # counts when the clock shows that the pause was shorter than a cycle.
    ipo = 0.1
    calls: list[float] = []
    clock = IpoClock(lambda: calls.append(_time.monotonic()), ipo=ipo)
    started = _time.monotonic()
    clock.start()
    await asyncio.sleep(0)  # the clock task sets its first deadline
    clock.poll()
    if _time.monotonic() - started < ipo:
        assert calls == []  # not due yet
    _time.sleep(ipo * 1.2)  # noqa: ASYNC251 - the loop must be busy past the deadline, on purpose
    clock.poll()
    assert len(calls) == 1 and clock.ticks == 1
    polled = _time.monotonic()
    await asyncio.sleep(0.02)  # the timer wakes for the old deadline: nothing more to do
    if _time.monotonic() - polled < ipo * 0.5:
        assert clock.ticks == 1
    await clock.stop()
