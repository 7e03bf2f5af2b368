"""Geometric Jacobian, damped-least-squares velocity IK (thesis eq. 2.10), manipulability.

Units (kept explicit because they mix):

* ``jacobian(model, q)`` is ∂(TCP twist)/∂q with q = KUKA axis angles in **radians**; rows
  ``[vx, vy, vz]`` in mm/rad and ``[ωx, ωy, ωz]`` in rad/rad, all in ``$ROBROOT``; columns
  A1..A6. Column i uses the *KUKA* positive axis direction ``u_i = sign_i·z_{i-1}``, so
  ``J @ radians(dq_deg)`` is the twist produced by moving the KUKA axes by ``dq_deg``.
* Linear and angular rows have different units, so singular values, damping and
  manipulability are computed on the *scaled* Jacobian whose linear rows are divided by
  ``length_scale`` (default 1000 mm: metres). Velocity IK takes a twist ``[mm/s, rad/s]``
  and returns axis speeds in **deg/s** (the API's angle unit; eq. 4.4 adds ``dq·Δt`` to
  degrees read from ``$AXIS_ACT``).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .forward import link_frames
from .frames import FloatArray, as_transform
from .model import RobotModel

__all__ = ["dls_velocity_ik", "jacobian", "manipulability", "scaled_jacobian"]

#: Default length scale for mixing mm and rad: 1000 mm, i.e. linear rows in metres.
LENGTH_SCALE = 1000.0


def jacobian(model: RobotModel, q: npt.ArrayLike, tool: npt.ArrayLike | None = None) -> FloatArray:
    """Geometric Jacobian ``(..., 6, 6)`` of the TCP (flange · tool) in ``$ROBROOT``.

    ``v = Σ_i u_i × (p_tcp − o_{i−1})·q̇_i`` and ``ω = Σ_i u_i·q̇_i`` with q̇ in rad/s.
    """
    frames = link_frames(model, q)
    tcp = frames[..., 6, :, :] @ model.flange
    tool_m = as_transform(tool)
    if tool_m is not None:
        tcp = tcp @ tool_m
    u = frames[..., :6, :3, 2] * model.sign[:, None]  # (..., 6 axes, 3)
    r = tcp[..., None, :3, 3] - frames[..., :6, :3, 3]
    j = np.empty((*u.shape[:-2], 6, 6))
    j[..., :3, :] = np.swapaxes(np.cross(u, r), -1, -2)
    j[..., 3:, :] = np.swapaxes(u, -1, -2)
    return j


def scaled_jacobian(
    model: RobotModel,
    q: npt.ArrayLike,
    tool: npt.ArrayLike | None = None,
    length_scale: float = LENGTH_SCALE,
) -> FloatArray:
    """:func:`jacobian` with the linear rows divided by ``length_scale`` (mm → unit of scale)."""
    j = jacobian(model, q, tool)
    j[..., :3, :] /= length_scale
    return j


def _damped_inverse_apply(
    j: FloatArray, x: FloatArray, damping: float, threshold: float, transpose: bool
) -> FloatArray:
    """Solve ``J·y = x`` (or ``Jᵀ·y = x``) by SVD with singular-value-dependent damping.

    λ² = damping²·(1 − (σ_min/threshold)²) when σ_min < threshold, else 0 (Chiaverini's
    variable damping): far from singularities this is the exact inverse, near them the
    solution stays bounded instead of blowing up.
    """
    u, sv, vt = np.linalg.svd(j)
    smin = sv[..., -1]
    lam2 = np.where(smin < threshold, damping**2 * (1.0 - (smin / threshold) ** 2), 0.0)
    gain = sv / (sv**2 + lam2[..., None])
    if transpose:  # Jᵀ = V Σ Uᵀ  ->  y = U Σ⁺ Vᵀ x
        y = np.einsum("...ij,...j->...i", u, gain * np.einsum("...ij,...j->...i", vt, x))
    else:  # J = U Σ Vᵀ  ->  y = V Σ⁺ Uᵀ x
        ut_x = np.einsum("...ji,...j->...i", u, x)
        y = np.einsum("...ji,...j->...i", vt, gain * ut_x)
    return np.asarray(y)


def dls_velocity_ik(
    model: RobotModel,
    q: npt.ArrayLike,
    twist: npt.ArrayLike,
    damping: float = 0.05,
    *,
    threshold: float = 0.05,
    tool: npt.ArrayLike | None = None,
    length_scale: float = LENGTH_SCALE,
) -> FloatArray:
    """Axis speeds (deg/s, ``(..., 6)``) producing a TCP twist ``[mm/s ×3, rad/s ×3]``.

    Damped least squares ``q̇ = Jᵀ(J Jᵀ + λ² I)⁻¹ ẋ`` on the scaled Jacobian (linear part in
    ``length_scale`` units), with λ rising from 0 to ``damping`` as the smallest singular
    value falls below ``threshold``. Usable through singularities: the output stays finite and
    the twist is tracked as well as the arm allows.
    """
    js = scaled_jacobian(model, q, tool, length_scale)
    x = np.array(np.broadcast_to(np.asarray(twist, dtype=np.float64), (*js.shape[:-2], 6)))
    x[..., :3] /= length_scale
    dq = _damped_inverse_apply(js, x, damping, threshold, transpose=False)
    return np.degrees(dq)


def manipulability(
    model: RobotModel,
    q: npt.ArrayLike,
    tool: npt.ArrayLike | None = None,
    length_scale: float = LENGTH_SCALE,
) -> FloatArray:
    """Yoshikawa's measure √det(J Jᵀ) = |det J| of the scaled Jacobian (linear rows in
    ``length_scale`` units, metres by default); 0 at singularities. Shape: leading dims."""
    js = scaled_jacobian(model, q, tool, length_scale)
    return np.asarray(np.abs(np.linalg.det(js)))
