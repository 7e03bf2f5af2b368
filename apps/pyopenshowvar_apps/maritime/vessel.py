"""A supply vessel's 6-DOF wave-frequency motion from a sea spectrum (reusable by any study).

The sea: a long-crested irregular sea from a standard spectrum, JONSWAP (γ = 3.3 by default)
or the modified Pierson–Moskowitz spectrum, both as implemented by **waveresponse** (4Subsea,
DNV-RP-C205's forms), given the significant wave height H_s, the peak period T_p and the
wave direction β relative to the ship (β = 180° head seas, 90° waves travelling to
starboard, Fossen's convention). The realisation is the usual random-phase sum of N
harmonics with a_k = √(2 S(ω_k) Δω_k), frequencies jittered inside their bins so the record
does not repeat.

The vessel: response amplitude operators (RAOs) per unit wave amplitude, at zero speed
(dynamic positioning during crane work), in the body frame {b} (x forward, y starboard,
z down; SNAME), the phase referred to the wave elevation at the origin CO:

* heave and pitch: the closed-form expressions of Jensen, Mansour & Olsen (2004, Ocean
  Eng. 31, 61–85) for a homogeneously loaded box, as coded in Fossen's MSS toolbox
  (``waveresponse345``, the toolbox the paper used): F, G, natural frequency √(g/2T) and
  damping ζ from the sectional damping A;
* roll: a 1-DOF oscillator (natural period T_4, damping ratio ζ_4) driven by the effective
  wave slope k sin β, reduced by Froude–Krylov averaging over the length (sinc) and the
  draught (e^{−kT/2});
* surge, sway, yaw: Froude–Krylov force and moment on the box L × C_B·B × T of the same
  displacement (pressure ρ g ζ e^{−kz} integrated over its sides), with the long-wave
  diffraction correction of G. I. Taylor / Morison (the excitation is (m + A) times the
  Froude–Krylov force per unit mass), so the added masses cancel and the response is the
  Froude–Krylov force (moment) over the rigid-body mass (yaw inertia); no restoring: the
  ship follows the water particles, averaged over its length and beam.

The main dimensions default to the supply vessel of the MSS example (L 82.8 m, B 19.2 m,
T 6 m, C_B 0.65). Long waves give back the wave itself: heave → ζ, pitch → the slope (the
tests check these limits).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import numpy.typing as npt

__all__ = ["RHO", "G", "Motion", "SeaState", "Vessel", "euler_rotation", "sea_state_code"]

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

G = 9.81  # m/s²
RHO = 1025.0  # kg/m³, sea water

#: WMO sea-state codes by significant wave height (upper bounds, m), as tabulated by Fossen (2011)
_SEA_STATES = ((0.0, 0), (0.1, 1), (0.5, 2), (1.25, 3), (2.5, 4), (4.0, 5), (6.0, 6),
               (9.0, 7), (14.0, 8))  # fmt: skip


def sea_state_code(hs: float) -> int:
    """The WMO sea state of a significant wave height (3.0 m → 5, "rough")."""
    for upper, code in _SEA_STATES:
        if hs <= upper:
            return code
    return 9


@dataclass(frozen=True)
class SeaState:
    """A long-crested irregular sea. ``tp`` defaults to 5·√H_s (the fully developed
    Pierson–Moskowitz relation ω_p = 0.4·√(g/H_s)); ``heading`` is β in degrees."""

    hs: float
    tp: float | None = None
    gamma: float = 3.3
    spectrum: Literal["jonswap", "pm"] = "jonswap"
    heading: float = 150.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.hs) and self.hs >= 0.0):
            raise ValueError(f"significant wave height must be >= 0 m, got {self.hs}")
        if self.tp is not None and not self.tp > 0.0:
            raise ValueError(f"peak period must be > 0 s, got {self.tp}")
        if self.spectrum not in ("jonswap", "pm"):
            raise ValueError(f"spectrum must be 'jonswap' or 'pm', got {self.spectrum!r}")

    @property
    def peak_period(self) -> float:
        return self.tp if self.tp is not None else 2.0 * math.pi / 0.4 * math.sqrt(self.hs / G)

    def density(self, omega: npt.ArrayLike) -> FloatArray:
        """S(ω) in m²·s/rad at the frequencies ``omega`` (rad/s, > 0)."""
        import waveresponse as wr

        w = np.asarray(omega, dtype=np.float64)
        if self.hs == 0.0:
            return np.zeros_like(w)
        if self.spectrum == "jonswap":
            _, s = wr.JONSWAP(w)(self.hs, self.peak_period, gamma=self.gamma)
        else:
            _, s = wr.ModifiedPiersonMoskowitz(w)(self.hs, self.peak_period)
        return np.asarray(s, dtype=np.float64)

    def components(
        self, n: int = 200, seed: int = 0, band: tuple[float, float] = (0.25, 3.5)
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """ω_k (rad/s), amplitudes a_k (m) and phases ε_k of a random-phase realisation.

        ``band`` is in units of the peak frequency; the bins are equal, each frequency drawn
        uniformly inside its bin.
        """
        rng = np.random.default_rng(seed)
        wp = 2.0 * math.pi / self.peak_period
        edges = np.linspace(band[0] * wp, band[1] * wp, n + 1)
        omega = edges[:-1] + rng.uniform(0.0, 1.0, n) * np.diff(edges)
        amp = np.sqrt(2.0 * self.density(omega) * np.diff(edges))
        phase = rng.uniform(0.0, 2.0 * math.pi, n)
        return omega, amp, phase


def euler_rotation(phi: npt.ArrayLike, theta: npt.ArrayLike, psi: npt.ArrayLike) -> FloatArray:
    """R_b^n = R_x(φ) R_y(θ) R_z(ψ), eq. 37 of the crane-head paper: ``(..., 3, 3)``."""
    p, t, s = (np.asarray(v, dtype=np.float64) for v in (phi, theta, psi))
    cp, sp, ct, st, cs, ss = np.cos(p), np.sin(p), np.cos(t), np.sin(t), np.cos(s), np.sin(s)
    one, zero = np.ones_like(cp), np.zeros_like(cp)
    rx = np.stack([one, zero, zero, zero, cp, -sp, zero, sp, cp], -1).reshape(*cp.shape, 3, 3)
    ry = np.stack([ct, zero, st, zero, one, zero, -st, zero, ct], -1).reshape(*cp.shape, 3, 3)
    rz = np.stack([cs, -ss, zero, ss, cs, zero, zero, zero, one], -1).reshape(*cp.shape, 3, 3)
    return np.asarray(rx @ ry @ rz)


def _sinc(u: FloatArray) -> FloatArray:
    return np.asarray(np.sinc(u / np.pi))  # sin(u)/u


def _first_moment(k: FloatArray, length: float) -> ComplexArray:
    """∫ x e^{−ikx} dx over [−l/2, l/2] (= 0 for k = 0)."""
    h = length / 2.0
    ks = np.where(np.abs(k) < 1e-9, 1e-9, k)
    return np.asarray(1j * (2.0 * h * np.cos(ks * h) / ks - 2.0 * np.sin(ks * h) / ks**2))


@dataclass(frozen=True)
class Vessel:
    """Main dimensions (m), roll data and the RAO model described in the module docstring."""

    length: float = 82.8
    beam: float = 19.2
    draught: float = 6.0
    block: float = 0.65
    roll_period: float = 10.0  # T_4 (s)
    roll_damping: float = 0.1  # ζ_4

    @property
    def mass(self) -> float:
        return RHO * self.block * self.length * self.beam * self.draught

    def raos(self, omega: npt.ArrayLike, heading: float) -> ComplexArray:
        """Complex RAOs ``(len(omega), 6)``: x, y, z (m/m, z down), φ, θ, ψ (rad/m)."""
        w = np.asarray(omega, dtype=np.float64)
        beta = math.radians(heading)
        cb, sb = math.cos(beta), math.sin(beta)
        L, B, T = self.length, self.beam, self.draught
        k = w * w / G
        kx, ky = k * cb, k * sb
        # heave and pitch: Jensen et al. (2004) as in MSS waveresponse345 (zero speed: α = 1)
        ke = np.abs(kx)
        sigma = np.maximum(ke * L / 2.0, 1e-9)
        kappa = np.exp(-ke * T)
        a_damp = 2.0 * np.sin(k * B / 2.0) * np.exp(-k * T)
        f = np.sqrt((1.0 - k * T) ** 2 + (a_damp**2 / (k * B)) ** 2)
        big_f = kappa * f * np.sin(sigma) / sigma
        big_g = kappa * f * (6.0 / L) / sigma * (np.sin(sigma) / sigma - np.cos(sigma))
        wn = math.sqrt(G / (2.0 * T))
        zeta = a_damp**2 / B * np.sqrt(1.0 / (8.0 * k**3 * T))
        h35 = wn**2 / (wn**2 - w**2 + 2j * zeta * wn * w)
        heave_up = big_f * h35
        pitch = -1j * math.copysign(1.0, cb) * big_g * h35 if cb != 0.0 else 0.0 * h35
        # roll: effective wave slope through a 1-DOF oscillator
        w4 = 2.0 * math.pi / self.roll_period
        slope = 1j * ky * _sinc(kx * L / 2.0) * np.exp(-k * T / 2.0)
        roll = slope * w4**2 / (w4**2 - w**2 + 2j * self.roll_damping * w4 * w)
        # surge, sway, yaw: Froude-Krylov on the equivalent box over the rigid-body inertia
        be = self.block * B
        depth = (1.0 - np.exp(-k * T)) / k
        fx = 2j * RHO * G * depth * be * _sinc(ky * be / 2.0) * np.sin(kx * L / 2.0)
        fy = 2j * RHO * G * depth * L * _sinc(kx * L / 2.0) * np.sin(ky * be / 2.0)
        nz = (
            2j
            * RHO
            * G
            * depth
            * (
                np.sin(ky * be / 2.0) * _first_moment(kx, L)
                - np.sin(kx * L / 2.0) * _first_moment(ky, be)
            )
        )
        m = self.mass
        izz = m * (L**2 + be**2) / 12.0
        surge = fx / (-(w**2) * m)
        sway = fy / (-(w**2) * m)
        yaw = nz / (-(w**2) * izz)
        return np.stack([surge, sway, -heave_up, roll, pitch, yaw], axis=-1)


@dataclass
class Motion:
    """A sampled vessel motion: η = [x y z φ θ ψ] (NED, m and rad), η̇, η̈, at times ``t``."""

    t: FloatArray
    eta: FloatArray
    eta_dot: FloatArray
    eta_ddot: FloatArray
    info: dict[str, float] = field(default_factory=dict)

    @classmethod
    def simulate(
        cls, vessel: Vessel, sea: SeaState, t: npt.ArrayLike, *, seed: int = 0, n: int = 200
    ) -> Motion:
        """The vessel's motion in ``sea`` at the times ``t`` (s): one realisation per seed."""
        ts = np.asarray(t, dtype=np.float64)
        omega, amp, phase = sea.components(n=n, seed=seed)
        h = vessel.raos(omega, sea.heading) * amp[:, None]  # (n, 6) complex amplitudes
        arg = ts[:, None] * omega[None, :] + phase[None, :]
        e = np.exp(1j * arg)  # (T, n)
        eta = np.real(e @ h)
        eta_dot = np.real(e @ (h * (1j * omega)[:, None]))
        eta_ddot = np.real(e @ (h * (-(omega**2))[:, None]))
        info = {"hs": sea.hs, "tp": sea.peak_period, "heading_deg": sea.heading,
                "sea_state": float(sea_state_code(sea.hs))}  # fmt: skip
        return cls(ts, eta, eta_dot, eta_ddot, info)

    def rotation(self) -> FloatArray:
        """R_b^n along the record: ``(T, 3, 3)``."""
        return euler_rotation(self.eta[:, 3], self.eta[:, 4], self.eta[:, 5])

    def body_rates(self) -> FloatArray:
        """ω_b^n = [p q r] in {b} (rad/s), from R^T Ṙ with the exact Euler-rate derivative."""
        return _body_rates(self.eta[:, 3:], self.eta_dot[:, 3:])

    def nu(self) -> FloatArray:
        """ν = [u v w p q r]: linear velocity in {b} (m/s) and ω_b^n (rad/s)."""
        r = self.rotation()
        v = np.einsum("tji,tj->ti", r, self.eta_dot[:, :3])
        return np.concatenate([v, self.body_rates()], axis=1)

    def point(self, r_b: npt.ArrayLike) -> FloatArray:
        """NED positions of a point fixed in {b} at ``r_b`` (m): ``(T, 3)``."""
        return np.asarray(self.eta[:, :3] + self.rotation() @ np.asarray(r_b, dtype=np.float64))


def _body_rates(angles: FloatArray, rates: FloatArray) -> FloatArray:
    """ω in {b} for R = R_x(φ)R_y(θ)R_z(ψ): vee(Rᵀ Ṙ), Ṙ by the product rule."""
    phi, th, psi = angles.T
    dphi, dth, dpsi = rates.T
    zeros = np.zeros_like(phi)
    # R_x(φ)R_y(θ)R_z(ψ): ω_b = R_z(ψ)ᵀ R_y(θ)ᵀ [φ̇,0,0] + R_z(ψ)ᵀ [0,θ̇,0] + [0,0,ψ̇]
    rz_t = euler_rotation(zeros, zeros, psi).transpose(0, 2, 1)
    ry_t = euler_rotation(zeros, th, zeros).transpose(0, 2, 1)
    ex = np.stack([dphi, zeros, zeros], axis=-1)
    ey = np.stack([zeros, dth, zeros], axis=-1)
    ez = np.stack([zeros, zeros, dpsi], axis=-1)
    omega = np.einsum("tij,tj->ti", rz_t @ ry_t, ex) + np.einsum("tij,tj->ti", rz_t, ey) + ez
    return np.asarray(omega)
