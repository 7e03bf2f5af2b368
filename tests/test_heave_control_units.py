"""The heave control law's parts as units: the PID with anti-windup, the target smoother, the
clamps of the set-point and of the robot target, and the frame text the robot reads.

Each test states the behaviour the control server relies on (docs/heave.md) and checks it with
numbers worked out by hand, not with the code's own formulas.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from pyopenshowvar_apps.heave.control import (
    ControlConfig,
    ControlLaw,
    ControlServer,
    Smoother,
    VectorPID,
    frame_text,
)
from pyopenshowvar_apps.heave.geometry import PlatformPose

THETA0 = np.array([20.0, -80.0, 100.0, 15.0, 55.0, 20.0])
LEVEL = PlatformPose()


# --- VectorPID -----------------------------------------------------------------------------------
def test_pid_terms_per_component() -> None:
    pid = VectorPID(3, kp=2.0, ki=0.5, kd=0.25, limit=100.0)
    # first step: no derivative yet; integral = e·dt
    out = pid.update([1.0, -2.0, 0.0], 0.1)
    assert out == pytest.approx([2.0 + 0.5 * 0.1, -4.0 - 0.5 * 0.2, 0.0])
    assert pid.integral == pytest.approx([0.1, -0.2, 0.0])
    # second step: derivative (e - e_prev) / dt, integral accumulates
    out = pid.update([3.0, -2.0, 1.0], 0.5)
    integral = np.array([0.1 + 1.5, -0.2 - 1.0, 0.5])
    deriv = np.array([2.0 / 0.5, 0.0, 1.0 / 0.5])
    assert pid.integral == pytest.approx(integral)
    assert out == pytest.approx(2.0 * np.array([3.0, -2.0, 1.0]) + 0.5 * integral + 0.25 * deriv)


def test_pid_output_is_clamped_symmetrically() -> None:
    pid = VectorPID(2, kp=10.0, ki=0.0, kd=0.0, limit=20.0)
    assert pid.update([5.0, -5.0], 0.01) == pytest.approx([20.0, -20.0])
    assert pid.update([1.9, -1.9], 0.01) == pytest.approx([19.0, -19.0])  # inside: untouched
    assert pid.update([2.0, -2.0], 0.01) == pytest.approx([20.0, -20.0])  # on the limit


def test_pid_anti_windup_freezes_only_the_saturated_component() -> None:
    pid = VectorPID(2, kp=0.1, ki=1.0, kd=0.0, limit=5.0)
    for _ in range(100):  # x saturated for 10 s (kp·e alone is 10); y small
        out = pid.update([100.0, 0.1], 0.1)
    assert out[0] == pytest.approx(5.0)
    assert pid.integral[0] == 0.0  # conditional integration: never grew while saturated
    assert pid.integral[1] == pytest.approx(1.0)  # y integrated all along (0.1 · 100 · 0.1)
    assert out[1] == pytest.approx(0.01 + 1.0)
    # the error vanishes: x leaves saturation at once (no wound-up integral to unwind)
    out = pid.update([0.0, 0.0], 0.1)
    assert out == pytest.approx([0.0, 1.0])


def test_pid_integrates_again_when_the_output_comes_back_inside() -> None:
    pid = VectorPID(1, kp=0.0, ki=1.0, kd=0.0, limit=1.0)
    pid.update([10.0], 0.05)  # trial 0.5: inside, taken
    pid.update([10.0], 0.05)  # trial 1.0: on the limit, not clipped: taken
    assert pid.integral == pytest.approx([1.0])
    pid.update([10.0], 0.05)  # trial 1.5: clipped, integral frozen
    assert pid.integral == pytest.approx([1.0])
    out = pid.update([-4.0], 0.05)  # trial 0.8: back inside, taken
    assert pid.integral == pytest.approx([0.8]) and out == pytest.approx([0.8])


def test_pid_reset_forgets_integral_and_last_error() -> None:
    pid = VectorPID(1, kp=0.0, ki=1.0, kd=1.0, limit=1e9)
    pid.update([2.0], 0.5)
    pid.reset()
    assert pid.integral == pytest.approx([0.0])
    # no derivative kick from the error before the reset: the first step has no derivative
    assert pid.update([4.0], 0.5) == pytest.approx([2.0])


def test_pid_survives_a_zero_time_step() -> None:
    pid = VectorPID(1, kp=0.0, ki=0.0, kd=1.0, limit=1e9)
    pid.update([0.0], 0.01)
    out = pid.update([1e-6], 0.0)  # dt 0 is taken as 1 µs: finite derivative
    assert out == pytest.approx([1.0])
    assert np.isfinite(out).all()


# --- Smoother ------------------------------------------------------------------------------------
def test_smoother_accelerates_at_the_limit_then_cruises_at_the_speed_limit() -> None:
    s = Smoother([0.0], max_speed=100.0, max_accel=1000.0)
    x1 = s.update([1000.0], 0.01)
    assert s.speed == pytest.approx([10.0])  # a·dt
    assert x1 == pytest.approx([0.1])
    for _ in range(50):
        s.update([1000.0], 0.01)
    assert s.speed == pytest.approx([100.0])  # capped at max_speed
    before = s.state.copy()
    s.update([1000.0], 0.01)
    assert s.state - before == pytest.approx([1.0])  # cruising: v·dt


def test_smoother_brakes_in_time_and_stops_on_the_target() -> None:
    s = Smoother([0.0, 0.0], max_speed=[200.0, 50.0], max_accel=[2000.0, 500.0])
    trace = [s.update([100.0, -30.0], 0.01) for _ in range(400)]
    xs = np.array(trace)
    # time-optimal braking: at most a step's worth past the target (a·dt² scale), no ringing
    assert 99.0 < xs[:, 0].max() <= 101.0
    assert -30.5 <= xs[:, 1].min() < -29.0
    assert xs[-1] == pytest.approx([100.0, -30.0], abs=1e-3)
    assert s.speed == pytest.approx([0.0, 0.0], abs=1e-2)
    steps = np.diff(xs, axis=0) / 0.01
    assert np.abs(steps[:, 0]).max() <= 200.0 + 1e-6  # per-component speed limits
    assert np.abs(steps[:, 1]).max() <= 50.0 + 1e-6
    dv = np.abs(np.diff(steps, axis=0)) / 0.01
    assert dv[:, 0].max() <= 2000.0 * (1 + 1e-6) and dv[:, 1].max() <= 500.0 * (1 + 1e-6)


def test_smoother_never_jumps_past_a_near_target_in_one_step() -> None:
    s = Smoother([0.0], max_speed=1e6, max_accel=1e9)
    # wanted speed |e|/dt at most: one step lands on the target, not beyond it
    assert s.update([0.5], 0.01) == pytest.approx([0.5])
    assert s.update([0.5], 0.01) == pytest.approx([0.5], abs=1e-9)


def test_smoother_bounds_the_time_step() -> None:
    # a long stall (1 s) counts as 50 ms; a zero step as 0.1 ms
    s = Smoother([0.0], max_speed=1e6, max_accel=100.0)
    s.update([1e6], 1.0)
    assert s.speed == pytest.approx([5.0])  # 100 · 0.05, not 100 · 1.0
    assert s.state == pytest.approx([0.25])
    s = Smoother([0.0], max_speed=1e6, max_accel=100.0)
    s.update([1e6], 0.0)
    assert s.speed == pytest.approx([0.01])  # 100 · 1e-4
    assert s.state == pytest.approx([1e-6])


def test_smoother_keeps_its_own_copy() -> None:
    start = np.array([1.0, 2.0])
    s = Smoother(start, max_speed=1.0, max_accel=1.0)
    out = s.update([1.0, 2.0], 0.01)
    out[0] = 99.0
    start[1] = 99.0
    assert s.state == pytest.approx([1.0, 2.0])


# --- ControlLaw: clamps and the uncompensated path --------------------------------------------------
def _fast(**kw: float) -> ControlConfig:
    limits = {"max_speed": 1e9, "max_accel": 1e12, "max_rot_speed": 1e9, "max_rot_accel": 1e12}
    return ControlConfig(**{**limits, **kw})  # type: ignore[arg-type]


def test_stick_is_clipped_to_full_scale_and_the_set_point_to_the_reach() -> None:
    law = ControlLaw(_fast(k=100.0, reach=250.0), THETA0)
    x0 = law.x_s.copy()
    law.step(0.1, THETA0, LEVEL, LEVEL, [5.0, -5.0, 0.5])  # a stick beyond ±1 is full scale
    assert law.x_s - x0 == pytest.approx([10.0, -10.0, 5.0])
    for _ in range(40):
        law.step(0.1, THETA0, LEVEL, LEVEL, [1.0, -1.0, 0.0])
    assert law.x_s - x0 == pytest.approx([250.0, -250.0, 5.0])  # held at the reach


def test_uncompensated_target_follows_the_stick_in_the_robot_base() -> None:
    law = ControlLaw(_fast(k=100.0), THETA0)
    target = law.step(0.2, THETA0, PlatformPose(30.0, 3.0, 2.0), LEVEL, [0.0, 0.0, 1.0])
    assert target[:3] - law.base0[:3] == pytest.approx([0.0, 0.0, 20.0])
    assert target[3:] == pytest.approx(law.base0[3:])
    assert law.delta == pytest.approx([0.0, 0.0, 0.0])


def test_switching_compensation_off_resets_the_pid() -> None:
    law = ControlLaw(_fast(kp=0.0, ki=1.0), THETA0)
    law.compensate = True
    law.step(0.05, THETA0 + np.array([0.0, 2.0, 0.0, 0.0, 0.0, 0.0]), LEVEL, LEVEL, [0.0, 0.0, 0.0])
    assert np.abs(law.pid.integral).max() > 0
    law.compensate = False
    law.step(0.05, THETA0, LEVEL, LEVEL, [0.0, 0.0, 0.0])
    assert law.pid.integral == pytest.approx([0.0, 0.0, 0.0])
    assert law.delta == pytest.approx([0.0, 0.0, 0.0])


def test_target_is_clamped_to_the_reach_and_the_orientation_reach() -> None:
    cfg = _fast(kp=0.0, ki=0.0, reach=40.0, reach_deg=5.0)
    # a platform raised (lowered) 100 mm and pitched 12°: the exact target is far outside the box
    for sign in (1.0, -1.0):
        law = ControlLaw(cfg, THETA0)
        law.compensate = True
        pose = PlatformPose(100.0 * sign, 0.0, 12.0 * sign)
        target = law.step(0.01, THETA0, pose, pose, [0.0, 0.0, 0.0])
        offset = target - law.base0
        assert np.all(np.abs(offset[:3]) <= 40.0 + 1e-9)
        assert np.all(np.abs(offset[3:]) <= 5.0 + 1e-9)
        assert np.abs(offset[:3]).max() == pytest.approx(40.0)
        assert np.abs(offset[3:]).max() == pytest.approx(5.0)
        assert law.smoother.state == pytest.approx(target)  # the smoother goes on from the clamp
    # inside the box nothing is clipped
    small = PlatformPose(10.0, 0.0, 1.0)
    law2 = ControlLaw(cfg, THETA0)
    law2.compensate = True
    inner = law2.step(0.01, THETA0, small, small, [0.0, 0.0, 0.0]) - law2.base0
    assert 0 < np.abs(inner[:3]).max() < 40.0 and 0 < np.abs(inner[3:]).max() < 5.0


def test_pid_correction_pushes_the_flange_towards_the_set_point() -> None:
    moved = THETA0 + np.array([0.0, 1.5, -1.0, 0.0, 0.0, 0.0])  # the robot is off its start
    targets = {}
    for kp in (0.0, 0.5):
        law = ControlLaw(_fast(kp=kp, ki=0.0, pid_limit=1e6, reach=1e6, reach_deg=180.0), THETA0)
        law.compensate = True
        targets[kp] = law.step(0.01, moved, LEVEL, LEVEL, [0.0, 0.0, 0.0])
        error = law.x_s - law.x_c
        assert np.abs(error).max() > 1.0
        assert law.delta == pytest.approx(kp * error)  # δx = kp (x_s - x_c)
    # on a level platform the correction shifts the robot target by δx itself
    assert targets[0.5][:3] - targets[0.0][:3] == pytest.approx(0.5 * error, abs=1e-6)
    assert targets[0.5][3:] == pytest.approx(targets[0.0][3:], abs=1e-9)


def test_the_mount_places_the_robot_on_the_platform() -> None:
    mount = np.eye(4)
    mount[:3, 3] = [10.0, -20.0, 100.0]  # the robot base 100 mm above the plate, off-centre
    plain, mounted = ControlLaw(_fast(), THETA0), ControlLaw(_fast(), THETA0, mount)
    assert mounted.x_s - plain.x_s == pytest.approx([10.0, -20.0, 100.0])
    assert mounted.base0 == pytest.approx(plain.base0)  # the robot's own target is unchanged
    world = mounted.world_flange(LEVEL, THETA0)[:3, 3] - plain.world_flange(LEVEL, THETA0)[:3, 3]
    assert world == pytest.approx([10.0, -20.0, 100.0])


def test_orientation_near_180_degrees_takes_the_short_way() -> None:
    law = ControlLaw(_fast(reach_deg=20.0), THETA0)
    a0 = float(law.base0[3])
    # pretend the smoother sits 179° away: the commanded A must stay within 1° of the short path
    law.smoother.state[3] = a0 + 359.0
    target = law.step(0.01, THETA0, LEVEL, LEVEL, [0.0, 0.0, 0.0])
    # raw A is a0; the short way from a0+359 is +1° (to a0+360), not -359°; the box clamps to
    # a0+20 at most, so a 360° detour would have ended at a0+339 - clipped to a0+20 either way;
    # check the smoother was asked for a0+360, i.e. it did not move backwards
    assert target[3] == pytest.approx(a0 + 20.0)


def test_wrap180_maps_differences_to_minus_180_to_180() -> None:
    from pyopenshowvar_apps.heave.control import _wrap180

    assert _wrap180(np.array([0.0, 179.0, 181.0, -181.0, 360.0, 540.0, -180.0])) == pytest.approx(
        [0.0, 179.0, -179.0, 179.0, 0.0, -180.0, -180.0]
    )


def test_frame_text_is_a_krl_frame_literal() -> None:
    text = frame_text([1.23456, -2.0, 3.0, 10.123456, -20.5, 0.0])
    assert text == "{X 1.235, Y -2.000, Z 3.000, A 10.1235, B -20.5000, C 0.0000}"


# --- ControlServer: its set-up ---------------------------------------------------------------------
def test_server_undoes_the_accelerometer_filter_delay() -> None:
    # a first-order low-pass at fc delays a slow signal by 1 / (2π fc)
    server = ControlServer(None, None, accel=object(), config=ControlConfig(accel_cutoff=5.0))
    assert server.estimator.accel_lag == pytest.approx(1.0 / (2.0 * math.pi * 5.0))
    assert server.lag.value == pytest.approx(ControlConfig().initial_lead)
    fixed = ControlServer(None, None, accel=object(), config=ControlConfig(lead=0.12))
    assert fixed.lag.value == pytest.approx(0.12)


def test_server_without_accelerometer_needs_the_plc_attitude() -> None:
    with pytest.raises(ValueError, match="attitude 'fused' needs the accelerometer stream"):
        ControlServer(None, None)
    with pytest.raises(ValueError, match="'accel' needs"):
        ControlServer(None, None, config=ControlConfig(attitude="accel"))
    server = ControlServer(None, None, config=ControlConfig(attitude="plc"))
    assert not server.compensate  # no law before start(): never compensating
    server.set_compensation(True)
    assert not server.compensate


def _server_with_law(**cfg: float) -> ControlServer:
    server = ControlServer(None, None, config=ControlConfig(attitude="plc", **cfg))  # type: ignore[arg-type]
    server.law = ControlLaw(server.config, THETA0)
    for k in range(20):  # a level, still platform sampled at 50 Hz up to t = 0.38 s
        server.estimator.add_plc(0.02 * k, 0.0, 0.0, 0.0)
    return server


def test_control_step_aims_half_a_period_past_the_measured_delay() -> None:
    server = _server_with_law()
    server.lag.value = 0.05
    server._control_step(0.4, 0.02, THETA0)
    assert server.rows[-1]["lead"] == pytest.approx(0.05 + 0.01)
    server._control_step(0.42, 1.0, THETA0)  # a stalled loop: at most 25 ms added
    assert server.rows[-1]["lead"] == pytest.approx(0.05 + 0.025)
    server.lag.value = 1.0  # never predicts further than max_lead
    server._control_step(0.44, 0.02, THETA0)
    assert server.rows[-1]["lead"] == pytest.approx(ControlConfig().max_lead)


def test_control_step_with_a_fixed_lead_and_its_row() -> None:
    server = _server_with_law(lead=0.1)
    server.lag.value = 0.2  # ignored: the lead is fixed
    target = server._control_step(0.4, 0.02, THETA0)
    row = server.rows[-1]
    assert row["lead"] == pytest.approx(0.1) and row["t"] == 0.4 and row["dt"] == 0.02
    assert row["comp"] == 0.0
    assert [row[f"tgt_{k}"] for k in "xyzabc"] == pytest.approx(list(target))
    assert [row[f"theta_{i}"] for i in range(1, 7)] == pytest.approx(list(THETA0))
    assert [row[f"xs_{a}"] for a in "xyz"] == pytest.approx(list(server.law.x_s))  # type: ignore[union-attr]
    assert (row["est_z"], row["est_phi"], row["est_theta"]) == pytest.approx((0.0, 0.0, 0.0))
    server.set_compensation(True)
    assert server.compensate
    server._control_step(0.42, 0.02, THETA0)
    assert server.rows[-1]["comp"] == 1.0
    assert set(server.rows[-1]) >= {"delta_x", "xc_z", "lead"}


async def test_a_failing_task_stops_the_server_with_its_error() -> None:
    server = ControlServer(None, None, config=ControlConfig(attitude="plc"))

    async def broken() -> None:
        raise OSError("platform gone")

    await server._guard(broken())
    assert isinstance(server.error, OSError) and server.quit.is_set()
    with pytest.raises(OSError, match="platform gone"):
        await server.stop()


async def test_cancelling_a_guarded_task_is_not_an_error() -> None:
    import asyncio

    server = ControlServer(None, None, config=ControlConfig(attitude="plc"))
    task = asyncio.ensure_future(server._guard(asyncio.Event().wait()))
    await asyncio.sleep(0)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert server.error is None and not server.quit.is_set()
    await server.stop()  # nothing running, nothing to raise


async def test_waiting_for_a_data_source_times_out_with_its_name() -> None:
    with pytest.raises(
        TimeoutError, match=r"^no data from the accelerometer stream within 0\.05 s$"
    ):
        await ControlServer._wait_for(lambda: False, 0.05, "the accelerometer stream")
    await ControlServer._wait_for(lambda: True, 0.0, "anything")  # ready: returns at once
