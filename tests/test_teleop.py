"""Teleoperation (case study 3): dead zone, eq. 2.7 / 4.2 math, devices, PID, and short runs
against the emulator with their metrics asserted."""

from __future__ import annotations

import csv
import itertools

import numpy as np
import pytest
from pyopenshowvar_apps.casestudies.devices import (
    CENTRE,
    Clock,
    ScriptedDevice,
    apply_key,
    circle,
    decode_keys,
    figure_eight,
    replay_csv,
    step,
    write_csv_trajectory,
)
from pyopenshowvar_apps.casestudies.pid import JointPID
from pyopenshowvar_apps.casestudies.teleop import (
    AXES,
    dead_zone,
    position_target,
    run_teleoperation,
    velocity_target,
)

from pyopenshowvar import Client
from pyopenshowvar.kinematics import KR6R900SIXX as KR6


def test_dead_zone_is_an_8cm_sphere_and_continuous() -> None:
    assert np.all(dead_zone([39.9, 0, 0]) == 0)
    assert np.all(dead_zone([20, 20, 20]) == 0)  # |x| = 34.6 mm
    np.testing.assert_allclose(dead_zone([0, 0, 100]), [0, 0, 60])
    np.testing.assert_allclose(dead_zone([40.001, 0, 0]), [0.001, 0, 0], atol=1e-9)


def test_position_mode_is_eq_2_7() -> None:
    x_w = np.array([500.0, 0.0, 600.0])
    np.testing.assert_allclose(position_target([0, 0, 10], 2.0, x_w), x_w)  # in the dead zone
    np.testing.assert_allclose(position_target([140, 0, 0], 2.0, x_w), np.add(x_w, [200, 0, 0]))


def test_velocity_mode_is_eq_4_2() -> None:
    np.testing.assert_allclose(velocity_target([1, 2, 3], [100, 0, -50], 0.004), [1.4, 2, 2.8])


def test_scripted_device_is_deterministic_and_in_the_hemisphere() -> None:
    for traj in (circle(), figure_eight(), step()):
        a, b = ScriptedDevice(traj), ScriptedDevice(traj)
        ts = np.linspace(0, 10, 101)
        pa = np.array([a.at(t) for t in ts])
        np.testing.assert_array_equal(pa, [b.at(t) for t in ts])
        assert np.all(pa[:, 2] >= 0) and np.all(np.linalg.norm(pa, axis=1) <= 1000)
    np.testing.assert_allclose(ScriptedDevice(circle(100)).at(0.0), np.add(CENTRE, [100, 0, 0]))


async def test_scripted_stream_and_csv_replay(tmp_path) -> None:
    path = write_csv_trajectory(tmp_path / "rec.csv", [(0.0, (0, 0, 0)), (1.0, (100, 0, -50))])
    traj = replay_csv(path)
    np.testing.assert_allclose(traj(0.5), [50, 0, -25])
    np.testing.assert_allclose(traj(9.0), [100, 0, -50])  # held at the end
    dev = ScriptedDevice(traj, duration=0.05, rate_hz=200)
    got = [s async for s in dev.samples(Clock(1.0))]
    assert 3 <= len(got) <= 12
    assert all(b.t > a.t for a, b in itertools.pairwise(got))


def test_keyboard_mapping() -> None:
    assert decode_keys("\x1b[Aw\x1b[D ") == ["up", "w", "left", "space"]
    p = np.array(CENTRE)
    np.testing.assert_allclose(apply_key(p, "up", 20), np.add(p, [20, 0, 0]))
    np.testing.assert_allclose(apply_key(p, "a", 20), np.add(p, [0, 20, 0]))
    np.testing.assert_allclose(apply_key(p, "r", 20), np.add(p, [0, 0, 20]))
    np.testing.assert_allclose(apply_key(p, "x", 20), p)
    np.testing.assert_allclose(apply_key(p + 300, "space"), CENTRE)
    low = apply_key([0, 0, 5], "f", 20)  # never below the sensor plane
    assert low[2] == 0


def test_pid_tracks_step_and_ramp_without_steady_state_error() -> None:
    pid = JointPID([0.0], kp=25, ki=150, kd=0.0)
    out = [pid.update([10.0], 0.005)[0] for _ in range(400)]  # 2 s step response
    assert abs(out[-1] - 10.0) < 1e-3
    assert max(out) < 10.0 * 1.15  # damped: < 15 % overshoot
    pid.reset([0.0])
    dt, speed = 0.005, 20.0  # a 20 deg/s ramp: PI leaves no lag in steady state
    for k in range(1, 801):
        y = pid.update([speed * k * dt], dt)[0]
    assert abs(speed * 800 * dt - y) < speed * dt + 0.01  # only the one-sample delay


def test_pid_respects_speed_limit_and_max_dt() -> None:
    pid = JointPID([0.0, 0.0], max_speed=[10.0, 100.0])
    for _ in range(10):
        pid.update([100.0, 100.0], 0.01)
    assert abs(pid.speed[0]) <= 10.0 + 1e-9 and pid.state[0] <= 1.0 + 1e-9
    stable = JointPID([0.0], max_dt=0.02)
    for _ in range(200):  # a 1 s gap per call must not destabilise the explicit update
        y = stable.update([1.0], 1.0)
    assert abs(y[0] - 1.0) < 1e-3


def _columns(path) -> dict[str, np.ndarray]:
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


# Timing decides how closely the robot follows (loop rate, access times): on a loaded machine
# that is a benchmark figure (the demo prints it), not a test bound. What the app controls is
# asserted: the PID's command never exceeds the speed it allows, the commands stay inside the
# software limits, every access is measured, and the robot really follows the hand.
@pytest.mark.timeout(40)
@pytest.mark.parametrize("mode", ["position", "velocity"])
async def test_teleoperation_tracks_on_the_emulator(emulator_factory, mode, tmp_path) -> None:
    emu = await emulator_factory(program="ext_move_axis", speed=1.0)
    async with Client("127.0.0.1", emu.port) as kvp:
        first = kvp.stats.count
        res = await run_teleoperation(kvp, mode=mode, duration=3.0, out_dir=tmp_path, plots=False)
        accesses = kvp.stats.count - first
    m = res.metrics
    col = _columns(tmp_path / "teleop.csv")
    t = col["t"]
    cycles = len(t)
    # two accesses per cycle (read $AXIS_ACT, write MYAXIS) besides the approach to the start
    assert accesses >= 2 * cycles and m["cycle_hz"] > 0
    access = np.loadtxt(tmp_path / "access_ms.csv", skiprows=1, ndmin=1)
    assert len(access) == 2 * cycles and np.all(access > 0)  # every access of the loop timed
    theta_s = np.stack([col[f"theta_s_{a}"] for a in AXES], axis=1)
    speed = np.abs(np.diff(theta_s, axis=0)) / np.maximum(np.diff(t), 1e-9)[:, None]
    assert np.all(speed <= 0.5 * KR6.max_speed + 1e-6)  # the PID's speed clamp
    assert np.all(theta_s >= KR6.lower + 2 - 1e-9) and np.all(theta_s <= KR6.upper - 2 + 1e-9)
    # the robot follows: the measured TCP moves with the target (lag removed), by most of the
    # motion; the hand really moved the target
    assert m["motion_range_mm"] > 50.0, m
    target = np.stack([col[f"target_{a}"] for a in "xyz"], axis=1)
    actual = np.stack([col[f"actual_{a}"] for a in "xyz"], axis=1)
    lag, shifted, keep = _align(t, target, actual)
    # One correlation of the whole motion (each axis about its mean, summed over the axes): an
    # axis that moved little weighs little. How tight it is depends on timing: 0.997 to
    # 0.9997 in runs at load 5; at load 6 (the loop and the in-process emulator sharing a third of a core) one
    # lag no longer fits the whole run and it fell to 0.65, the RMS error to 0.69 of the
    # range. A robot that does not follow the hand gives about 0.
    s, a = shifted[keep] - shifted[keep].mean(axis=0), actual[keep] - actual[keep].mean(axis=0)
    corr = float(np.sum(s * a) / np.sqrt(np.sum(s * s) * np.sum(a * a)))
    assert corr > 0.5, (corr, lag, m)
    # ... and it covers the hand's path, not a shrunken copy of it
    moved = np.ptp(target, axis=0) > 20.0
    assert np.all(np.ptp(actual, axis=0)[moved] > 0.5 * np.ptp(target, axis=0)[moved]), m


def _align(
    t: np.ndarray, target: np.ndarray, actual: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray]:
    """The delay that best aligns ``actual`` with ``target`` (least squares), the target
    delayed by it and the samples it leaves to compare. The lag itself is timing (the app
    reports it, searching 0–0.5 s); here it may be up to half the run, as long as a loaded
    machine makes it: the loop rate and the emulator's ticks decide it, not the app."""
    best, best_err = 0.0, np.inf
    for lag in np.arange(0.0, 0.5 * (t[-1] - t[0]), 0.004):
        shifted = np.stack([np.interp(t - lag, t, c) for c in target.T], axis=1)
        err = float(np.mean(np.sum((shifted - actual)[t > t[0] + lag] ** 2, axis=1)))
        if err < best_err:
            best, best_err = float(lag), err
    shifted = np.stack([np.interp(t - best, t, c) for c in target.T], axis=1)
    return best, shifted, t > t[0] + best


@pytest.mark.timeout(40)
async def test_teleoperation_kvp_latency_and_follow(emulator_factory) -> None:
    """With the `kvp` latency profile every access is the proxy's service time plus the
    client's: never below the profile's 1.5 ms floor, whatever the load (which only adds)."""
    emu = await emulator_factory(program="follow", latency="kvp", seed=1)
    async with Client("127.0.0.1", emu.port) as kvp:
        res = await run_teleoperation(
            kvp, device=ScriptedDevice(figure_eight(), duration=2.5), duration=2.5, program="follow"
        )
    m = res.metrics
    assert m["access_max_ms"] >= m["access_p99_ms"] >= m["access_mean_ms"] >= 1.5, m
    assert res.thesis["access_mean_ms"] == "≈ 4.27"  # compared in the demo, like for like
    assert m["motion_range_mm"] > 50.0 and m["tracking_rms_mm"] < m["motion_range_mm"], m
