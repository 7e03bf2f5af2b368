"""The wave platform: kinematics (eq. 4.6–4.11), waves (eq. 4.13), PLC motors, the accelerometer."""

from __future__ import annotations

import asyncio
import math
import os

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from pyopenshowvar_apps.heave.accel import MAX_LINE, AccelFirmware, AccelReader, parse_line
from pyopenshowvar_apps.heave.geometry import THESIS_PLATFORM as G
from pyopenshowvar_apps.heave.geometry import PlatformPose, UnreachablePose, platform_matrix
from pyopenshowvar_apps.heave.plc import MotorLimits, PlatformPLC
from pyopenshowvar_apps.heave.simulator import PlatformConfig, PlatformSimulator
from pyopenshowvar_apps.heave.waves import WaveComponent, WaveGenerator


def test_leg_equation_4_6_end_points() -> None:
    # β = 125° is the crank straight up: a1 + a2; β = 0 is the crank 125° from the vertical
    assert G.leg_height(125.0) == pytest.approx(480.0)
    alpha = math.radians(125.0)
    expected = 150 * math.cos(alpha) + math.sqrt(330**2 - (150 * math.sin(alpha)) ** 2)
    assert G.leg_height(0.0) == pytest.approx(expected)
    assert G.stroke == pytest.approx((expected, 480.0))
    with pytest.raises(UnreachablePose, match="outside the stroke"):
        G.leg_angle(481.0)


@given(st.floats(0.0, 125.0))
def test_leg_round_trip(beta: float) -> None:
    assert float(G.leg_angle(G.leg_height(beta))) == pytest.approx(beta, abs=1e-6)


@settings(max_examples=200)
@given(st.floats(-60, 60), st.floats(-5, 5), st.floats(-5, 5))
def test_platform_inverse_forward_round_trip(z: float, phi: float, theta: float) -> None:
    pose = PlatformPose(z, phi, theta)
    try:
        legs = G.inverse(pose)
    except UnreachablePose:
        # Near the ends of the heave range a tilt puts a corner outside the stroke.
        assume(False)
    back = G.forward(legs)
    assert back.as_array() == pytest.approx(pose.as_array(), abs=1e-7)


@settings(max_examples=100)
@given(st.floats(-60, 60), st.floats(-5, 5), st.floats(-5, 5))
def test_corner_heights_are_the_plate_corners(z: float, phi: float, theta: float) -> None:
    # the corner heights are the z of the body-fixed corners under T_z T_θ T_φ (eq. 4.14)
    pose = PlatformPose(z, phi, theta)
    corners = np.column_stack([G.corners_xy(), np.zeros(3), np.ones(3)])
    world = (platform_matrix(pose) @ corners.T)[2]
    assert G.corner_heights(pose) - G.neutral_height == pytest.approx(world, abs=1e-9)


def test_printed_special_cases_hold() -> None:
    theta, phi = 3.0, 2.0
    h = G.corner_heights(PlatformPose(0.0, 0.0, theta)) - G.neutral_height
    st_ = math.sin(math.radians(theta))
    assert h[0] == pytest.approx(st_ * G.m2)  # eq. 4.10
    assert h[1] == pytest.approx(-st_ * G.m1) == pytest.approx(h[2])  # eq. 4.9
    h = G.corner_heights(PlatformPose(0.0, phi, 0.0))
    assert h[1] - h[2] == pytest.approx(math.sin(math.radians(phi)) * G.l)  # eq. 4.7
    # eq. 4.8 corrected: φ = arcsin(Δ/l), not arcsin(Δ)/l
    assert math.degrees(math.asin((h[1] - h[2]) / G.l)) == pytest.approx(phi)


def test_wave_statistics_follow_the_thesis_distributions() -> None:
    draws = [WaveGenerator.random(seed) for seed in range(3000)]
    for name, hi in (("heave", 150.0), ("roll", 100.0), ("pitch", 100.0)):
        amp = np.array([getattr(w, name).amplitude for w in draws])
        freq = np.array([getattr(w, name).frequency for w in draws])
        phase = np.array([getattr(w, name).phase for w in draws])
        for values, lo, top in ((amp, 0.0, hi), (freq, 0.0, 0.1), (phase, -math.pi, math.pi)):
            assert values.min() >= lo and values.max() <= top
            u = (values - lo) / (top - lo)
            # uniform: mean 1/2 and variance 1/12 within 4 standard errors, every decile filled
            assert abs(u.mean() - 0.5) < 4 * math.sqrt(1 / 12 / len(u))
            assert abs(u.var() - 1 / 12) < 4 * math.sqrt(1 / 180 / len(u))
            counts = np.histogram(u, bins=10, range=(0, 1))[0]
            chi2 = float(np.sum((counts - len(u) / 10) ** 2 / (len(u) / 10)))
            assert chi2 < 33.7  # 9 degrees of freedom, p = 1e-4
    # rows draw independently: heave and roll frequencies are uncorrelated
    fh = np.array([w.heave.frequency for w in draws])
    fr = np.array([w.roll.frequency for w in draws])
    assert abs(np.corrcoef(fh, fr)[0, 1]) < 0.08
    assert WaveGenerator.random(7) == WaveGenerator.random(7) != WaveGenerator.random(8)
    coherent = WaveGenerator.random(7, coherent=True)
    assert coherent.heave.frequency == coherent.roll.frequency == coherent.pitch.frequency


def test_wave_signal_is_peak_to_peak_and_fits_the_stroke() -> None:
    wave = WaveComponent(150.0, 0.1, 0.3)
    t = np.linspace(0.0, 10.0, 10001)[:-1]  # one whole period
    values = np.array([wave.value(x) for x in t])
    assert values.max() - values.min() == pytest.approx(150.0, rel=1e-6)
    assert math.sqrt(np.mean(values**2)) == pytest.approx(75.0 / math.sqrt(2), rel=1e-4)
    sea = WaveGenerator.thesis_max(3)
    lo, hi = G.stroke
    heights = np.array([G.corner_heights(sea.pose(x)) for x in np.linspace(0, 10, 501)])
    assert heights.min() > lo and heights.max() < hi  # the hardest thesis sea never saturates
    ramped = WaveGenerator.thesis_max(3, ramp=2.0)
    assert ramped.pose(0.0) == PlatformPose() and ramped.pose(5.0) == sea.pose(5.0)


def test_plc_motors_respect_speed_and_acceleration_limits() -> None:
    plc = PlatformPLC(motors=MotorLimits(speed=60.0, accel=200.0), watchdog=0)
    plc.set_enable(True)
    plc.set_pose_setpoint(PlatformPose(100.0, 0.0, 0.0))
    speeds = []
    for _ in range(800):
        plc.step(0.005)
        speeds.append(plc.beta_dot.copy())
    v = np.array(speeds)
    assert np.abs(v).max() <= 60.0 + 1e-9
    assert np.abs(np.diff(v, axis=0)).max() / 0.005 <= 200.0 + 1e-6
    assert plc.pose.z == pytest.approx(100.0, abs=0.01) and not plc.saturated
    plc.set_pose_setpoint(PlatformPose(200.0, 0.0, 0.0))  # beyond the stroke: clamped
    for _ in range(600):
        plc.step(0.005)
    assert plc.saturated and plc.beta == pytest.approx([125.0] * 3, abs=1e-6)


def test_plc_watchdog_stops_the_drives() -> None:
    plc = PlatformPLC(watchdog=0.1)
    plc.set_enable(True)
    for _ in range(10):
        plc.step(0.005)
    assert plc.enabled
    for _ in range(20):
        plc.step(0.005)
    assert not plc.enabled and plc.fault == 1
    plc.set_enable(True)
    assert not plc.enabled  # latched until RESET
    plc.reset_fault()
    plc.set_enable(True)
    assert plc.enabled


def test_plc_watchdog_stops_the_plcs_own_waves_too() -> None:
    """The watchdog holds in every mode: waves running with nobody writing stop ~1 s after the
    last master write (it once skipped the check while WAVE was on)."""
    plc = PlatformPLC(watchdog=1.0)
    plc.set_enable(True)
    plc.set_wave(True)
    dt = 0.01
    while plc.time < 0.99:  # the last master write was the enable at t = 0
        plc.step(dt)
    assert plc.enabled and plc.fault == 0 and plc.wave_on
    assert np.any(np.abs(plc.beta_dot) > 0.1)  # the waves drive it
    plc.step(dt)
    plc.step(dt)
    assert not plc.enabled and plc.fault == 1  # at 1.0 s + one scan
    fault_speed = float(np.abs(plc.beta_dot).max())
    for _ in range(math.ceil(fault_speed / plc.motors.accel / dt) + 1):
        plc.step(dt)  # braking at the motors' acceleration limit
    assert np.all(plc.beta_dot == 0.0)
    beta = plc.beta.copy()
    for _ in range(200):  # and it stays put with the waves still "on"
        plc.step(dt)
    assert np.array_equal(plc.beta, beta)


def test_plc_watchdog_register_cannot_switch_it_off() -> None:
    words = PlatformPLC(watchdog=1.0).command_words()
    plc = PlatformPLC(watchdog=1.0)
    i = 7  # WATCHDOG

    def block(ms: int) -> list[int]:
        return [*words[:i], ms, *words[i + 1 :]]

    assert plc.check_commands(block(1000)) is None  # the start-up value
    assert plc.check_commands(block(1)) is None  # shorter: fine
    assert "WATCHDOG = 0 ms: 1…1000" in str(plc.check_commands(block(0)))
    assert "WATCHDOG = 1001 ms" in str(plc.check_commands(block(1001)))
    assert plc.check_commands(block(60001)) is not None  # the register range itself
    off = PlatformPLC(watchdog=0.0)  # off by the start-up option: the master may set any
    assert off.check_commands(block(0)) is None and off.check_commands(block(60000)) is None
    assert off.check_commands(block(60001)) is not None
    short = PlatformPLC(watchdog=0.25)
    assert short.check_commands(block(250)) is None and short.check_commands(block(251))


def test_accelerometer_angles_match_the_pose() -> None:
    board = AccelFirmware(noise=0.0)
    roll, pitch = board.sample(PlatformPose(0.0, 3.0, -2.0))
    assert (roll, pitch) == pytest.approx((3.0, -2.0), abs=1e-9)
    noisy = AccelFirmware(noise=0.005, seed=1)
    samples = np.array([noisy.sample(PlatformPose(0.0, 3.0, -2.0)) for _ in range(2000)])
    assert samples[500:].mean(axis=0) == pytest.approx([3.0, -2.0], abs=0.02)
    assert 0.02 < samples[500:, 0].std() < 0.3  # filtered noise, not none


def test_accel_lines_parse_and_garbage_is_bounded() -> None:
    assert parse_line(b"1234,1.500,-2.250\n") == (1234, 1.5, -2.25)
    for bad in (b"1,2\n", b"x,1,2\n", b"1,nan,2\n", b"1,95,0\n"):
        with pytest.raises(ValueError):
            parse_line(bad)
    reader = AccelReader("/nonexistent")
    reader.feed(b"\x00" * 1_000_000, 0.0)  # a line that never ends
    assert len(reader._buffer) <= MAX_LINE and reader.rejected == 1
    reader.feed(b"junk\n5,1.0,2.0\n", 1.0)
    assert reader.latest is not None and reader.latest.roll == 1.0 and reader.rejected == 2


async def test_accelerometer_stream_over_the_serial_device() -> None:
    async with PlatformSimulator(PlatformConfig(port=0, accel_noise=0.0)) as sim:
        sim.plc.sp_pose = PlatformPose(0.0, 2.0, -1.0)
        sim.plc.set_enable(True)
        sim.plc.watchdog = 0
        assert sim.accel_path is not None
        reader = await AccelReader(sim.accel_path).open()
        try:
            await asyncio.sleep(1.5)
            n0 = reader.received
            await asyncio.sleep(0.5)
            rate = (reader.received - n0) / 0.5
            assert reader.latest is not None
            assert (reader.latest.roll, reader.latest.pitch) == pytest.approx((2.0, -1.0), abs=0.01)
        finally:
            reader.close()
        assert 60 < rate < 140  # 100 Hz, with a loaded machine's slack
        assert reader.rejected == 0


async def test_the_reader_drops_what_came_before_it_listened_and_a_torn_first_line() -> None:
    """A port opened mid-stream: the bytes buffered before (old samples) and the rest of the
    line being sent are dropped, not taken as a sample or counted as rejected lines."""
    import tty

    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        os.write(master, b"1,1.000,1.000\n2,2.000")  # sent before anyone listened
        opening = asyncio.ensure_future(AccelReader(os.ttyname(slave)).open(timeout=5.0))
        await asyncio.sleep(0)  # the reader opened the port and waits for its first line
        os.write(master, b"0\n4,4.000,-4.000\n")  # the torn line's end, then a whole one
        reader = await opening
        try:
            assert reader.latest is not None and reader.latest.millis == 4
            assert (reader.latest.roll, reader.latest.pitch) == (4.0, -4.0)
            assert reader.received == 1 and reader.rejected == 0
        finally:
            reader.close()
    finally:
        os.close(master)
        os.close(slave)
