"""The benchmark's metrics (thesis §5.2.1.1–2), as plain functions on sampled series.

Direct measures:

* eq. 5.2 — position error ``a = |x_t − x_c|`` per sample, ``x_t = x_d`` (eq. 5.3) the
  target and ``x_c`` the forward kinematics of the solver's output (mm);
* eq. 5.4 — joint-configuration error ``b = |θ_t − θ_c|`` per sample (deg; the Euclidean
  norm over the joints), ``θ_t`` the joint path the target was generated from;
* eq. 5.5 — the composed cost ``α·a + β·b`` with α + β = 1 (a in mm, b in degrees, as the
  thesis mixes them);
* eqs. 5.6/5.7 — the joint effort ``T = ∫ ½‖τ‖² dt``, per joint as in the thesis' Table 5.1
  (``∫ ½ τ_i² dt``, N²·m²·s) by the trapezoidal rule over the sampled torques.

Indirect measure (the heave test): eq. 5.8 — ``δx = x_d − x_c`` between the target and the
tip in the earth frame, and eq. 5.9 — the compensation ``δθ = J⁻¹(θ)·δx``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = [
    "compensation",
    "composed_cost",
    "joint_effort",
    "joint_error",
    "position_error",
    "summary",
]

FloatArray = npt.NDArray[np.float64]


def position_error(x_t: npt.ArrayLike, x_c: npt.ArrayLike) -> FloatArray:
    """Eq. 5.2: ``|x_t − x_c|`` per sample (rows are X Y Z)."""
    d = np.asarray(x_t, dtype=np.float64) - np.asarray(x_c, dtype=np.float64)
    return np.asarray(np.linalg.norm(d, axis=-1))


def joint_error(theta_t: npt.ArrayLike, theta_c: npt.ArrayLike) -> FloatArray:
    """Eq. 5.4: ``|θ_t − θ_c|`` per sample (the norm over the joints)."""
    d = np.asarray(theta_t, dtype=np.float64) - np.asarray(theta_c, dtype=np.float64)
    return np.asarray(np.linalg.norm(d, axis=-1))


def composed_cost(a: npt.ArrayLike, b: npt.ArrayLike, alpha: float, beta: float) -> FloatArray:
    """Eq. 5.5: ``α·a + β·b``; α, β ≥ 0 with α + β = 1."""
    if alpha < 0.0 or beta < 0.0 or not math.isclose(alpha + beta, 1.0, abs_tol=1e-9):
        raise ValueError(f"alpha and beta must be >= 0 and sum to 1, got {alpha}, {beta}")
    return np.asarray(
        alpha * np.asarray(a, dtype=np.float64) + beta * np.asarray(b, dtype=np.float64)
    )


def joint_effort(t: npt.ArrayLike, tau: npt.ArrayLike) -> FloatArray:
    """Eqs. 5.6/5.7 per joint: ``∫ ½ τ_i² dt`` (trapezoidal); ``tau`` is ``(samples, joints)``.
    Their sum is ``∫ ½‖τ‖² dt``."""
    ts = np.asarray(t, dtype=np.float64)
    lagrangian = 0.5 * np.asarray(tau, dtype=np.float64) ** 2
    return np.asarray(np.trapezoid(lagrangian, ts, axis=0))


def compensation(jacobian: npt.ArrayLike, dx: npt.ArrayLike, damping: float = 1.0) -> FloatArray:
    """Eq. 5.9: ``δθ = J⁻¹(θ)·δx`` for a square position Jacobian (units of ``dx`` per unit of
    ``δθ``); near a singularity the damped inverse ``Jᵀ(JJᵀ + λ²I)⁻¹`` keeps it bounded
    (``damping`` λ in the units of ``dx``; negligible elsewhere)."""
    j = np.asarray(jacobian, dtype=np.float64)
    v = np.asarray(dx, dtype=np.float64)
    return np.asarray(j.T @ np.linalg.solve(j @ j.T + damping**2 * np.eye(j.shape[0]), v))


def summary(values: npt.ArrayLike) -> dict[str, float]:
    """RMS and maximum of a series."""
    v = np.asarray(values, dtype=np.float64)
    return {"rms": float(math.sqrt(np.mean(v**2))), "max": float(np.max(v))}
