"""The haptic app's own model of the arm: what the motor torques say about the operator's force.

The controller publishes motor torques; the force the TCP exerts on the world is what is left
after the app's *nominal* model of everything else is subtracted (thesis eq. 4.5, τ = Jᵀ F):

* **gravity** — the library's :func:`~pyopenshowvar.kinematics.gravity_torques` (link masses,
  centres of mass, ``$LOAD``);
* **link inertia** — the links as point masses at their centres of mass (the only mass data a
  kinematic model carries), driven by the *measured* motion: the mean axis acceleration over
  the IPO cycle is the change of the measured axis speed from the cycle's start to its end;
* **joint terms the kinematic model lacks** — per axis a rotor/rotational inertia I·q̈ and a
  *friction map*: friction as a piecewise-linear function of the axis speed through fixed
  knots (:data:`FRICTION_KNOTS`, odd in q̇, a viscous slope beyond the last knot), the
  look-up table friction compensation of drive practice. Both are *identified* by
  :func:`identify` from a short free-space motion, plus a tare offset measured at rest
  (:func:`tare`), as one zeroes a force sensor before touching anything.

None of this is the emulator's code: the simulated robot is a MuJoCo model with link inertia
tensors, motor inertia and its own friction law, a Stribeck curve (docs/emulator-robot.md),
which the map can approximate but does not contain; here the app meets it as it would meet a
real arm whose friction law nobody knows. :class:`ForceEstimator` solves Jᵥᵀ F = τ_ext for the 3-D force by
weighted least squares (weights: the torque noise measured while taring), which stays well
posed at HOME's wrist singularity where the 6-D Jᵀ is not.

Units: axes in degrees and deg/s at the interface (as KRL publishes them), radians inside.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from pyopenshowvar.kinematics import (
    GRAVITY,
    KR6R900SIXX,
    Load,
    RobotModel,
    gravity_torques,
    jacobian,
)
from pyopenshowvar.kinematics.forward import link_frames

__all__ = [
    "IPO",
    "CycleMotion",
    "ForceEstimator",
    "JointTerms",
    "NominalDynamics",
    "RestAverage",
    "identify",
    "tare",
]

FloatArray = npt.NDArray[np.float64]
#: The KRC4's interpolation cycle (s): the published torque is the mean over one such cycle.
IPO = 0.012
#: Axis speeds (rad/s) of the friction map's knots: dense at low speed, where friction
#: changes fastest (its value at 0 is 0: friction opposes motion).
FRICTION_KNOTS = (0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2)
#: Weight of the map's smoothness (first differences between knots, per sample): a knot the
#: motion hardly reached takes its neighbours' value instead of fitting noise.
SMOOTHNESS = 0.002


def friction_basis(qd: npt.ArrayLike, knots: Sequence[float] = FRICTION_KNOTS) -> FloatArray:
    """Columns of the friction map at speeds ``qd`` (rad/s): one hat function per knot (the
    last one held constant beyond it), then the viscous slope beyond the last knot; odd in
    q̇. Friction = basis @ (values at the knots, slope)."""
    v = np.abs(np.asarray(qd, dtype=np.float64))
    grid = np.concatenate([[0.0], knots])
    unit = np.eye(len(grid))[:, 1:]
    hats = np.stack([np.interp(v, grid, unit[:, k]) for k in range(len(knots))], axis=-1)
    tail = np.maximum(v - knots[-1], 0.0)[..., None]
    return np.asarray(np.sign(np.asarray(qd))[..., None] * np.concatenate([hats, tail], axis=-1))


@dataclass(frozen=True)
class CycleMotion:
    """The measured motion of one IPO cycle: axes at its end (deg), axis speeds at its start
    and end (deg/s), and how long it lasted (s; several cycles when one was not sampled)."""

    q: FloatArray
    qd_start: FloatArray
    qd_end: FloatArray
    dt: float = IPO

    @property
    def mean_speed(self) -> FloatArray:
        """Mean axis speed over the cycle (deg/s), by the trapezoid rule."""
        return np.asarray((self.qd_start + self.qd_end) / 2.0)

    @property
    def mean_accel(self) -> FloatArray:
        """Mean axis acceleration over the cycle (deg/s²): exact from the end speeds."""
        return np.asarray((self.qd_end - self.qd_start) / self.dt)

    @property
    def q_mid(self) -> FloatArray:
        return np.asarray(self.q - self.mean_speed * self.dt / 2.0)


class NominalDynamics:
    """Gravity and point-mass inertia of the nominal model (library kinematics and masses)."""

    def __init__(self, model: RobotModel = KR6R900SIXX, load: Load | None = None) -> None:
        self.model = model
        self.load = load
        zero = link_frames(model, np.zeros(6))
        c0 = model.link_origin + model.link_com  # centres of mass at the all-zero pose, mm
        # each centre of mass in the frame that moves with its link (D-H frame j+1)
        self._local = np.einsum("jki,jk->ji", zero[1:, :3, :3], c0 - zero[1:, :3, 3])
        self._mass = np.asarray(model.link_mass, float)
        if load is not None and load.mass_kg > 0.0:
            self._mass = np.append(self._mass, load.mass_kg)
        # body j moves with axes 1..j+1 only (the load with all six)
        self._reach = (np.minimum(np.arange(7), 5)[:, None] >= np.arange(6)[None, :]).astype(float)

    def com_jacobians(self, q: npt.ArrayLike) -> FloatArray:
        """Linear Jacobians of the centres of mass (links, then the load): (n, 3, 6), m/rad."""
        frames = link_frames(self.model, q)
        com = frames[1:, :3, 3] + np.einsum("jik,jk->ji", frames[1:, :3, :3], self._local)
        if len(self._mass) > 6:
            assert self.load is not None
            flange = frames[6] @ self.model.flange
            com = np.vstack([com, flange[:3, 3] + flange[:3, :3] @ np.asarray(self.load.com_mm)])
        u = frames[:6, :3, 2] * self.model.sign[:, None]  # KUKA axis directions
        r = com[:, None, :] - frames[None, :6, :3, 3]  # (bodies, axes, 3)
        jac = np.cross(u[None, :, :], r) / 1000.0
        jac *= self._reach[: len(com), :, None]
        return np.asarray(np.swapaxes(jac, 1, 2))

    def gravity(self, q: npt.ArrayLike) -> FloatArray:
        return np.asarray(gravity_torques(self.model, q, self.load), float)

    def rigid(self, motion: CycleMotion) -> FloatArray:
        """Mean drive torque (Nm) over the cycle that holds and accelerates the point masses:
        Σ J_cᵀ m (c̈ − g) at mid-cycle, c̈ = J_c q̈ (the velocity-product terms m·r·q̇² are
        below 0.3 N of TCP force at hand-guiding speeds, < 0.5 rad/s, and left out)."""
        jac = self.com_jacobians(motion.q_mid)
        accel = jac @ np.radians(motion.mean_accel)  # (bodies, 3) m/s²
        accel[:, 2] += GRAVITY
        tau = np.einsum("bij,bi->j", jac, self._mass[:, None] * accel)
        return np.asarray(self.model.torque_sign * tau)


@dataclass(frozen=True)
class JointTerms:
    """Per-axis terms identified on the robot: rotor inertia (kg·m²), the friction map (Nm at
    each of :data:`FRICTION_KNOTS`, then the viscous slope beyond them in Nm·s/rad: shape
    ``(6, len(FRICTION_KNOTS) + 1)``), tare offset (Nm), torque noise (Nm)."""

    rotor: FloatArray = field(default_factory=lambda: np.zeros(6))
    friction: FloatArray = field(default_factory=lambda: np.zeros((6, len(FRICTION_KNOTS) + 1)))
    offset: FloatArray = field(default_factory=lambda: np.zeros(6))
    noise: FloatArray = field(default_factory=lambda: np.ones(6))

    def friction_torque(self, qd: npt.ArrayLike) -> FloatArray:
        """Friction (Nm, opposing the motion) at axis speeds ``qd`` (rad/s)."""
        return np.asarray(np.einsum("...jk,jk->...j", friction_basis(qd), self.friction))

    def torque(self, motion: CycleMotion, sign: float = 1.0) -> FloatArray:
        qd = np.radians(motion.mean_speed)
        qdd = np.radians(motion.mean_accel)
        drive = self.rotor * qdd + self.friction_torque(qd)
        return np.asarray(sign * drive + self.offset)


def tare(
    dyn: NominalDynamics, q: Sequence[npt.ArrayLike], tau: Sequence[npt.ArrayLike]
) -> tuple[FloatArray, FloatArray]:
    """Offset (mean of τ − gravity) and noise (its standard deviation) of torques measured at
    rest with nothing touching the robot, each cycle counted once. A controller without
    torque noise repeats one reading: its noise is taken as 1 µNm."""
    if not tau:
        raise ValueError("taring needs readings at rest")
    resid = np.array([np.asarray(t, float) - dyn.gravity(qq) for qq, t in zip(q, tau, strict=True)])
    spread = resid.std(axis=0, ddof=1) if len(resid) > 1 else np.zeros(6)
    return resid.mean(axis=0), np.maximum(spread, 1e-6)


def identify(
    dyn: NominalDynamics,
    motions: Sequence[CycleMotion],
    tau: Sequence[npt.ArrayLike],
    base: JointTerms,
    *,
    ridge: float = 1e-3,
) -> tuple[JointTerms, FloatArray]:
    """Fit rotor inertia and the friction map per axis to free-space motion: least squares
    with a small ridge (an axis that hardly moved gets ~0 rather than noise) and a smoothness
    penalty between the map's knots (:data:`SMOOTHNESS`). ``base`` brings the tare offset and
    noise. Returns the terms and the residual RMS per axis (Nm)."""
    if len(motions) < 10:
        raise ValueError(f"identification needs at least 10 cycles of motion, got {len(motions)}")
    sign = dyn.model.torque_sign
    y = np.array(
        [
            sign * (np.asarray(t, float) - base.offset - dyn.rigid(m))
            for m, t in zip(motions, tau, strict=True)
        ]
    )
    qd = np.radians(np.array([m.mean_speed for m in motions]))
    qdd = np.radians(np.array([m.mean_accel for m in motions]))
    n, knots = len(y), len(FRICTION_KNOTS)
    # first differences of the map's values (not of the inertia or the viscous slope)
    diff = np.zeros((knots - 1, knots + 2))
    diff[:, 1:knots] -= np.eye(knots - 1)
    diff[:, 2 : knots + 1] += np.eye(knots - 1)
    smooth = SMOOTHNESS * n * diff.T @ diff
    rotor, fric, resid = np.zeros(6), np.zeros((6, knots + 1)), np.zeros(6)
    for i in range(6):
        x = np.column_stack([qdd[:, i], friction_basis(qd[:, i])])
        scale = np.maximum(np.sqrt(np.mean(x**2, axis=0)), 1e-12)
        lhs = x.T @ x + smooth + ridge * n * np.diag(scale**2)
        c = np.maximum(np.linalg.solve(lhs, x.T @ y[:, i]), 0.0)  # never negative
        rotor[i], fric[i] = c[0], c[1:]
        resid[i] = float(np.sqrt(np.mean((y[:, i] - x @ c) ** 2)))
    return replace(base, rotor=rotor, friction=fric), resid


class ForceEstimator:
    """τ_ext = τ − model; F from Jᵥᵀ F = τ_ext (weighted least squares, N, base axes)."""

    def __init__(
        self,
        dyn: NominalDynamics,
        terms: JointTerms,
        *,
        tool: npt.ArrayLike | None = None,
    ) -> None:
        self.dyn = dyn
        self.terms = terms
        self.tool = tool

    def external(self, motion: CycleMotion, tau: npt.ArrayLike) -> FloatArray:
        """The torque (Nm) the model does not explain: the external force's share."""
        model = self.dyn.rigid(motion) + self.terms.torque(motion, self.dyn.model.torque_sign)
        return np.asarray(np.asarray(tau, float) - model)

    def force(self, q: npt.ArrayLike, tau_ext: npt.ArrayLike) -> FloatArray:
        """The TCP force (N) whose Jᵀ F best explains ``tau_ext`` at axes ``q`` (deg)."""
        a = np.asarray(jacobian(self.dyn.model, q, tool=self.tool), float)[:3].T / 1000.0
        w = 1.0 / np.square(self.terms.noise)
        lhs = a.T @ (w[:, None] * a)
        rhs = a.T @ (w * self.dyn.model.torque_sign * np.asarray(tau_ext, float))
        return np.asarray(np.linalg.solve(lhs, rhs), float)

    def estimate(self, motion: CycleMotion, tau: npt.ArrayLike) -> FloatArray:
        return self.force(motion.q_mid, self.external(motion, tau))

    def force_noise(self, q: npt.ArrayLike) -> float:
        """RMS norm (N) of the force error one cycle's torque noise causes at ``q``."""
        a = np.asarray(jacobian(self.dyn.model, q, tool=self.tool), float)[:3].T / 1000.0
        cov = np.linalg.inv(a.T @ (a / np.square(self.terms.noise)[:, None]))
        return math.sqrt(float(np.trace(cov)))


class RestAverage:
    """The force while the arm stands still, averaged over the cycles since it stopped.

    One cycle's torque noise is ~1 N of force at this arm's levers; at rest every cycle
    measures the same thing, so the mean of the distinct cycles since the arm stopped is
    accurate to noise/√n. *Still* means the app commands no motion and every measured axis
    speed is below ``speed_eps`` (deg/s) — thresholds, because encoders and speeds of a real
    arm are never bit-identical from cycle to cycle. The average is *settled* once its noise is
    below ``resolution`` (N). A torque that leaves the average's noise band (χ² of the six
    normalised deviations above ``jump``; 1 in 10⁶ by noise alone) means the force changed
    while the arm stood: the average restarts.
    """

    def __init__(
        self,
        estimator: ForceEstimator,
        *,
        speed_eps: float = 0.02,
        resolution: float = 0.15,
        jump: float = 36.0,
    ) -> None:
        self.est = estimator
        self.speed_eps = speed_eps
        self.resolution = resolution
        self.jump = jump
        self.reset()

    def reset(self) -> None:
        self.n = 0
        self._tau = np.zeros(6)
        self._q = np.zeros(6)
        self._last = ""
        self._sigma = math.inf
        self.force: FloatArray | None = None
        self.settled = False

    def update(
        self, q: FloatArray, qd: FloatArray, tau: FloatArray, tau_text: str, commanding: bool
    ) -> FloatArray | None:
        """Feed one reading; returns the averaged force while still (else None)."""
        if commanding or float(np.max(np.abs(qd))) >= self.speed_eps:
            self.reset()
            return None
        if tau_text == self._last:  # the same cycle read again: no new information
            return self.force
        noise = self.est.terms.noise
        if self.n >= 3:
            dev = (tau - self._tau / self.n) / noise
            if float(dev @ dev) > self.jump * (1.0 + 1.0 / self.n):
                self.reset()
        if self.n == 0:
            self._sigma = self.est.force_noise(q)
        self._last = tau_text
        self.n += 1
        self._tau += tau
        self._q += q
        q_mean, tau_mean = self._q / self.n, self._tau / self.n
        tau_ext = tau_mean - self.est.dyn.gravity(q_mean) - self.est.terms.offset
        self.force = self.est.force(q_mean, tau_ext)
        self.settled = self._sigma / math.sqrt(self.n) <= self.resolution
        return self.force
