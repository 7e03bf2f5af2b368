"""The vessel-motion model (sea spectrum, RAOs, 6-DOF record) and the motion sensor."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pyopenshowvar_apps.maritime.imu import IMU, Channel
from pyopenshowvar_apps.maritime.vessel import (
    G,
    Motion,
    SeaState,
    Vessel,
    euler_rotation,
    sea_state_code,
)


def test_sea_state_codes_of_the_wmo_table() -> None:
    assert [sea_state_code(h) for h in (0.0, 0.3, 1.0, 2.0, 3.0, 5.0, 8.0, 20.0)] == [
        0, 2, 3, 4, 5, 6, 7, 9,
    ]  # fmt: skip


def test_bad_sea_states_are_refused() -> None:
    for bad in ({"hs": -1.0}, {"hs": float("nan")}, {"hs": 2.0, "tp": 0.0},
                {"hs": 2.0, "spectrum": "bretschneider"}):  # fmt: skip
        with pytest.raises(ValueError):
            SeaState(**bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("spectrum", ["jonswap", "pm"])
def test_the_realisation_has_the_significant_wave_height(spectrum: str) -> None:
    sea = SeaState(2.5, spectrum=spectrum)  # type: ignore[arg-type]
    omega, amp, _ = sea.components(n=400, seed=3)
    # H_s = 4 √m0 of the component variance; the band 0.25..3.5 ω_p holds ~all the energy
    assert 4.0 * math.sqrt(np.sum(amp**2) / 2.0) == pytest.approx(2.5, rel=0.02)
    assert omega[np.argmax(amp)] == pytest.approx(2 * math.pi / sea.peak_period, rel=0.1)
    assert sea.peak_period == pytest.approx(5.0 * math.sqrt(2.5), rel=0.01)


@pytest.mark.parametrize("heading", [180.0, 150.0, 120.0, 90.0])
def test_long_waves_carry_the_ship_with_the_water(heading: float) -> None:
    v = Vessel()
    w = np.array([0.05])
    k = w**2 / G
    b = math.radians(heading)
    rao = v.raos(w, heading)[0]
    # surge, sway follow the particles, heave the surface (z down), pitch and roll the slopes
    assert abs(rao[0]) == pytest.approx(abs(math.cos(b)), abs=2e-3)
    assert abs(rao[1]) == pytest.approx(abs(math.sin(b)), abs=2e-3)
    assert abs(rao[2] + 1.0) < 6e-3
    assert abs(rao[4]) == pytest.approx(abs(k[0] * math.cos(b)), rel=0.02, abs=1e-6)
    assert abs(rao[3]) == pytest.approx(abs(k[0] * math.sin(b)), rel=0.02, abs=1e-6)


def test_short_waves_barely_move_the_ship() -> None:
    rao = Vessel().raos(np.array([3.0]), 150.0)[0]
    assert np.all(np.abs(rao[:3]) < 0.02) and np.all(np.abs(rao[3:]) < 0.005)


def test_record_variance_matches_the_response_spectrum() -> None:
    v, sea = Vessel(), SeaState(3.0)
    t = np.arange(0.0, 3600.0, 0.5)
    m = Motion.simulate(v, sea, t, seed=5, n=300)
    w = np.linspace(0.2, 3.0, 4000)
    h = v.raos(w, sea.heading)
    predicted = np.trapezoid(np.abs(h) ** 2 * sea.density(w)[:, None], w, axis=0)
    measured = m.eta.var(axis=0)
    assert measured == pytest.approx(predicted, rel=0.2)


def test_body_rates_and_velocities_are_the_derivatives_of_the_record() -> None:
    t = np.arange(0.0, 60.0, 0.01)
    m = Motion.simulate(Vessel(), SeaState(4.0, heading=120.0), t, seed=2)
    r = m.rotation()
    dr = np.gradient(r, t, axis=0)
    w_hat = np.einsum("tji,tjk->tik", r, dr)  # Rᵀ Ṙ = S(ω_b)
    w = np.stack([w_hat[:, 2, 1], w_hat[:, 0, 2], w_hat[:, 1, 0]], axis=-1)
    nu = m.nu()
    assert np.abs(w[5:-5] - nu[5:-5, 3:]).max() < 1e-3 * np.abs(nu[:, 3:]).max()
    ned_v = np.einsum("tij,tj->ti", r, nu[:, :3])
    inner = slice(5, -5)  # np.gradient is one-sided at the ends
    assert ned_v[inner] == pytest.approx(np.gradient(m.eta[:, :3], t, axis=0)[inner], abs=2e-3)
    assert m.eta_dot[inner] == pytest.approx(np.gradient(m.eta, t, axis=0)[inner], abs=2e-3)


def test_euler_rotation_is_rx_ry_rz() -> None:
    phi, th, psi = 0.3, -0.2, 1.1
    rx = np.array(
        [[1, 0, 0], [0, math.cos(phi), -math.sin(phi)], [0, math.sin(phi), math.cos(phi)]]
    )
    ry = np.array([[math.cos(th), 0, math.sin(th)], [0, 1, 0], [-math.sin(th), 0, math.cos(th)]])
    rz = np.array(
        [[math.cos(psi), -math.sin(psi), 0], [math.sin(psi), math.cos(psi), 0], [0, 0, 1]]
    )
    assert euler_rotation(phi, th, psi) == pytest.approx(rx @ ry @ rz)


def test_ideal_imu_reads_the_truth_and_a_real_one_does_not() -> None:
    t = np.arange(0.0, 200.0, 0.02)
    m = Motion.simulate(Vessel(), SeaState(2.0), t, seed=1)
    ideal = IMU.ideal().measure(m, seed=4)
    assert np.array_equal(ideal.eta, m.eta) and np.array_equal(ideal.nu, ideal.nu_true)
    real = IMU().measure(m, seed=4)
    err = real.eta - m.eta
    assert 0.005 < np.std(err[:, 2]) < 0.1  # heave: centimetres
    assert np.abs(err[:, 3:]).max() < math.radians(0.2)  # attitude: hundredths of a degree


def test_channel_errors_have_their_statistics() -> None:
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 20000.0, 0.1)
    noise = Channel(noise=0.3).errors(t, rng)
    assert noise.std(axis=0) == pytest.approx([0.3] * 3, rel=0.02)
    bias = Channel(bias=1.0).errors(t, rng)
    assert np.ptp(bias, axis=0) == pytest.approx([0.0] * 3, abs=1e-12)  # constant per run
    drift = Channel(drift=0.5, tau=50.0).errors(t, rng)
    assert drift.std(axis=0) == pytest.approx([0.5] * 3, rel=0.15)  # stationary Gauss-Markov
    lag = np.mean(drift[500:, 0] * drift[:-500, 0]) / np.var(drift[:, 0])
    assert lag == pytest.approx(math.exp(-50.0 / 50.0), abs=0.1)  # correlation time τ
    walk = Channel(drift=0.1, tau=math.inf).errors(t, rng)
    assert abs(walk[-1, 0] - walk[0, 0]) < 6 * 0.1 * math.sqrt(20000.0)
