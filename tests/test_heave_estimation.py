"""The control server's estimates: device clocks, fits, the attitude fusion, the command delay."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pyopenshowvar_apps.heave.estimation import (
    ClockMapper,
    LagEstimator,
    PlatformEstimator,
    RecentFit,
)


def test_clock_mapper_keeps_the_time_a_sample_was_taken() -> None:
    clock = ClockMapper()
    rng = np.random.default_rng(1)
    # device clock 1000 s behind ours; each sample arrives 1..40 ms late, some in bursts
    mapped = [
        clock.to_local(t, 1000.0 + t + 0.001 + 0.04 * rng.random()) for t in np.arange(0, 5, 0.01)
    ]
    assert mapped[-1] == pytest.approx(1000.0 + 4.99, abs=0.002)
    assert clock.to_local(0.0, 5.0) == pytest.approx(5.0)  # a device restart re-bases


def test_recent_fit_follows_a_quadratic_and_extrapolates() -> None:
    fit = RecentFit(0.4)
    for t in np.arange(0.0, 2.0, 0.01):
        fit.add(t, 3 * t * t - 2 * t + 1)
    assert fit.at(2.1) == pytest.approx(3 * 2.1**2 - 2 * 2.1 + 1, abs=1e-9)
    assert fit.rate(1.99) == pytest.approx(6 * 1.99 - 2, abs=1e-9)
    fit.add(1.5, 99.0)  # out of order: ignored
    assert fit.at(1.99) == pytest.approx(3 * 1.99**2 - 2 * 1.99 + 1, abs=1e-9)


def test_fused_attitude_takes_the_motion_from_the_plc_and_the_offset_from_the_board() -> None:
    est = PlatformEstimator(attitude="fused", fuse_tau=1.0)
    rng = np.random.default_rng(2)
    for k in range(1000):  # 10 s; the board reads 0.4° more roll than the encoders see
        t = k * 0.01
        roll = 2.0 * math.sin(2 * math.pi * 0.1 * t)
        est.add_plc(t, 10.0, roll, -1.0)
        est.add_accel(t, roll + 0.4 + rng.normal(0, 0.1), -1.0 + rng.normal(0, 0.1))
    pose = est.pose_at(9.99)
    assert pose.phi == pytest.approx(2.0 * math.sin(2 * math.pi * 0.999) + 0.4, abs=0.05)
    assert pose.theta == pytest.approx(-1.0, abs=0.05) and pose.z == pytest.approx(10.0)
    # never beyond the platform's range, however wild the extrapolation
    assert est.pose_at(1e6).phi <= 15.0 and est.pose_at(1e6, max_ahead=0.25).z == pytest.approx(
        10.0
    )


def test_lag_estimator_finds_the_command_delay() -> None:
    lag = LagEstimator(initial=0.0, smoothing=1.0)
    for k in range(400):
        t = k * 0.008
        x = 50.0 * math.sin(2 * math.pi * 0.5 * t)
        lag.command(t, np.array([x, 0.0, 0.0]))
        delayed = 50.0 * math.sin(2 * math.pi * 0.5 * (t - 0.072))
        lag.measured(t, np.array([delayed, 0.0, 0.0]))
    assert lag.updates > 0 and lag.value == pytest.approx(0.072, abs=0.005)
