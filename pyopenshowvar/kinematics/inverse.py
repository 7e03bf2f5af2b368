"""Closed-form inverse kinematics (thesis eq. 2.9) for KUKA-style spherical-wrist arms.

Supported geometry (the KR 6 R900 sixx and the usual 6R industrial arm): axes 2 and 3 parallel
(α2 = 0), |α1| = |α3| = |α4| = |α5| = 90°, no lateral offset (d2 = d3 = 0) and a spherical wrist
(a4 = a5 = a6 = 0, d5 = 0). Other models raise ``ValueError``.

Solution structure, per pose: 2 shoulder choices (wrist centre in front of / behind axis 1) ×
2 elbow choices × 2 wrist flips = up to 8. Multi-turn equivalents (q ± 360°) are considered for
every axis whose limits allow them (A2, A4 and A6 of the KR 6), because the KUKA T bits tell
them apart. At singularities the free angle is taken from ``current`` (or the model's home):
A1 when the wrist centre is on axis 1, A4 when A5 = 0 (only A4 ± A6 is defined there).

Selection in :func:`inverse` is separable per axis: every constraint (limits, T bit i, S bit 1
on A3, S bit 2 on A5) and the squared joint distance to ``current`` depend on one axis only,
so the best multi-turn choice is found axis by axis, which keeps batches of 10⁴ poses cheap.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Literal

import numpy as np
import numpy.typing as npt

from .errors import UnreachableError
from .forward import dh_transforms, status_turn
from .frames import FloatArray, as_transform, inv_transform
from .model import RobotModel

__all__ = ["inverse", "inverse_all"]

# A value this close to a bit's boundary (deg, or mm for the overhead test) matches either bit,
# so a pose computed from A6 = 0 is still found with T bit 5 clear despite -1e-14 round-off.
_BIT_TOL = 1e-9
_LIMIT_TOL = 1e-9
# |sin θ5| below this is the wrist singularity; the reach test allows this much rounding.
_WRIST_EPS = 1e-10
_REACH_EPS = 1e-10


@lru_cache(maxsize=32)
def _check_structure(model: RobotModel) -> None:
    al = model.alpha
    ok = (
        al[1] == 0.0
        and all(abs(abs(al[i]) - 90.0) < 1e-12 for i in (0, 2, 3, 4))
        and model.d[1] == 0.0
        and model.d[2] == 0.0
        and model.a[3] == 0.0
        and model.a[4] == 0.0
        and model.a[5] == 0.0
        and model.d[4] == 0.0
    )
    if not ok:
        raise ValueError(
            f"{model.name}: closed-form IK needs a KUKA-style spherical-wrist arm "
            "(alpha2 = 0, |alpha1,3,4,5| = 90, d2 = d3 = 0, a4 = a5 = a6 = 0, d5 = 0)"
        )


def _rx(alpha_deg: float) -> FloatArray:
    r = math.radians(alpha_deg)
    c, s = round(math.cos(r), 15), round(math.sin(r), 15)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rz(theta: FloatArray) -> FloatArray:
    c, s = np.cos(theta), np.sin(theta)
    r = np.zeros((*theta.shape, 3, 3))
    r[..., 0, 0], r[..., 0, 1], r[..., 1, 0], r[..., 1, 1] = c, -s, s, c
    r[..., 2, 2] = 1.0
    return r


def _flange_targets(
    model: RobotModel,
    pose: npt.ArrayLike,
    tool: npt.ArrayLike | None,
    base: npt.ArrayLike | None,
) -> FloatArray:
    """The last D-H frame in $ROBROOT for a TCP pose given in $BASE."""
    t = as_transform(pose)
    assert t is not None
    base_m, tool_m = as_transform(base), as_transform(tool)
    if base_m is not None:
        t = base_m @ t
    if tool_m is not None:
        t = t @ inv_transform(tool_m)
    if not np.array_equal(model.flange, np.eye(4)):
        t = t @ inv_transform(model.flange)
    return t


def _solve(model: RobotModel, t6: FloatArray, hint: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Base solutions of flat ``t6 (N, 4, 4)``: KUKA axes ``(N, 8, 6)`` (NaN where unreachable)
    in (-180, 180], and the signed distance of the wrist centre beyond reach ``(N,)`` (mm)."""
    _check_structure(model)
    n = t6.shape[0]
    hint_theta = np.radians(model.sign * hint + model.offset)  # (N, 6)
    a1, a2, a3 = model.a[0], model.a[1], model.a[2]
    d1, d4, d6 = model.d[0], model.d[3], model.d[5]
    al = np.radians(model.alpha)
    s1 = round(math.sin(al[0]))

    r6 = t6[:, :3, :3]
    # z5 in base: R6·Rx(-α6)·e_z (equals z6 when α6 = 0)
    z5 = r6 @ np.array([0.0, math.sin(al[5]), math.cos(al[5])])
    w = t6[:, :3, 3] - d6 * z5 - r6 @ np.array([model.a[5], 0.0, 0.0])

    # --- axis 1: the arm plane contains the wrist centre; front and back (overhead) choice
    rho = np.hypot(w[:, 0], w[:, 1])
    phi = np.where(rho < 1e-9, hint_theta[:, 0], np.arctan2(w[:, 1], w[:, 0]))
    th1 = np.stack([phi, phi + np.pi], axis=1)  # (N, 2)

    # wrist centre in frame 1: x along the arm, y1 = sin(α1)·z0 (α1 = ±90°), no lateral part
    c1, sn1 = np.cos(th1), np.sin(th1)
    radial = c1 * w[:, None, 0] + sn1 * w[:, None, 1] - a1
    px = radial
    py = s1 * (w[:, None, 2] - d1)

    # --- axes 2, 3: planar 2R with the forearm seen from axis 3 as length lf at angle psi
    lf = math.hypot(a3, d4)
    psi = math.atan2(-math.sin(al[2]) * d4, a3)
    r2 = px**2 + py**2
    cos_b = (r2 - a2**2 - lf**2) / (2.0 * a2 * lf)
    dist = np.sqrt(r2)
    beyond = np.maximum(dist - (abs(a2) + lf), (abs(a2) - lf) - dist)  # (N, 2)
    ok12 = np.abs(cos_b) <= 1.0 + _REACH_EPS
    beta = np.arccos(np.clip(cos_b, -1.0, 1.0))
    beta = np.stack([beta, -beta], axis=2)  # (N, 2 shoulder, 2 elbow)
    th3 = beta - psi
    th2 = np.arctan2(py, px)[..., None] - np.arctan2(lf * np.sin(beta), a2 + lf * np.cos(beta))
    th1b = np.broadcast_to(th1[..., None], th2.shape)

    th4, th5, th6 = _wrist(model, r6, th1b, th2, th3, hint_theta)

    shape = (n, 2, 2, 2)
    theta = np.stack(
        [
            np.broadcast_to(th1b[..., None], shape),
            np.broadcast_to(th2[..., None], shape),
            np.broadcast_to(th3[..., None], shape),
            th4,
            th5,
            th6,
        ],
        axis=-1,
    )
    q = (np.degrees(theta) - model.offset) / model.sign
    q = 180.0 - (180.0 - q) % 360.0  # wrap into (-180, 180]
    q = np.where(ok12[:, :, None, None, None], q, np.nan)
    return q.reshape(n, 8, 6), beyond.min(axis=1)


def _wrist(
    model: RobotModel,
    r6: FloatArray,
    th1b: FloatArray,
    th2: FloatArray,
    th3: FloatArray,
    hint_theta: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """θ4, θ5, θ6 ``(N, 2, 2, 2)`` (rad, D-H) for each arm solution ``θ1..θ3 (N, 2, 2)``:
    R36 = R3ᵀ·R6 = Rz(θ4)·Rx(α4)·Rz(θ5)·Rx(α5)·Rz(θ6)·Rx(α6), both wrist flips; at the wrist
    singularity θ4 comes from the hint."""
    sign, off = model.sign, np.radians(model.offset)
    al = np.radians(model.alpha)
    s4, s5 = round(math.sin(al[3])), round(math.sin(al[4]))
    q123 = np.zeros((r6.shape[0], 2, 2, 6))
    q123[..., 0] = (th1b - off[0]) / sign[0]
    q123[..., 1] = (th2 - off[1]) / sign[1]
    q123[..., 2] = (th3 - off[2]) / sign[2]
    t = dh_transforms(model, np.degrees(q123))
    r3 = (t[..., 0, :3, :3] @ t[..., 1, :3, :3]) @ t[..., 2, :3, :3]
    m = np.swapaxes(r3, -1, -2) @ r6[:, None, None] @ _rx(model.alpha[5]).T  # (N,2,2,3,3)

    c5 = -s4 * s5 * m[..., 2, 2]
    s5abs = np.hypot(m[..., 0, 2], m[..., 1, 2])
    singular = s5abs < _WRIST_EPS
    th5 = np.stack([np.arctan2(s5abs, c5), np.arctan2(-s5abs, c5)], axis=-1)  # (N,2,2,2)
    sg = np.array([1.0, -1.0])
    with np.errstate(invalid="ignore", divide="ignore"):
        th4 = np.arctan2(s5 * m[..., 1, 2, None] * sg, s5 * m[..., 0, 2, None] * sg)
        th6 = np.arctan2(-s4 * m[..., 2, 1, None] * sg, s4 * m[..., 2, 0, None] * sg)
    if np.any(singular):
        # Only θ4 ± θ6 is defined: keep θ4 from the hint and solve Rz(θ6) = Qᵀ·Rz(θ4)ᵀ·M.
        th4_h = np.broadcast_to(hint_theta[:, 3, None, None, None], th5.shape)
        q = _rx(model.alpha[3]) @ _rz(th5) @ _rx(model.alpha[4])
        nmat = np.swapaxes(q, -1, -2) @ np.swapaxes(_rz(th4_h), -1, -2) @ m[..., None, :, :]
        th6_s = np.arctan2(nmat[..., 1, 0], nmat[..., 0, 0])
        sing = np.broadcast_to(singular[..., None], th5.shape)
        th4 = np.where(sing, th4_h, th4)
        th6 = np.where(sing, th6_s, th6)
    return th4, th5, th6


@lru_cache(maxsize=32)
def _turn_candidates(model: RobotModel) -> FloatArray:
    """Per axis, the multiples of 360° that can land inside the limits: (6, K), NaN-padded."""
    kmax = int(np.ceil(np.max(np.abs(np.concatenate([model.lower, model.upper]))) / 360.0)) + 1
    ks = np.arange(-kmax, kmax + 1, dtype=np.float64)
    lo, hi = -180.0 + 360.0 * ks, 180.0 + 360.0 * ks
    useful = (hi[None, :] >= model.lower[:, None]) & (lo[None, :] <= model.upper[:, None])
    out = np.where(useful, 360.0 * ks[None, :], np.nan)
    out.flags.writeable = False  # cached and shared between calls
    return out


def inverse_all(
    model: RobotModel,
    pose: npt.ArrayLike,
    *,
    tool: npt.ArrayLike | None = None,
    base: npt.ArrayLike | None = None,
    hint: npt.ArrayLike | None = None,
    limits: bool = False,
) -> FloatArray:
    """All closed-form solutions (KUKA axes, degrees) of a TCP pose (4×4 or XYZABC).

    One pose → ``(n, 6)`` with the distinct solutions (n ≤ 8, 0 if out of reach), angles in
    (-180°, 180]. A batch ``(..., 4, 4)`` / ``(..., 6)`` → ``(..., 8, 6)`` NaN-padded.
    ``limits=True`` keeps only solutions inside the software limits and adds their multi-turn
    equivalents (e.g. A6 = 10° and -350°). ``hint`` supplies A1/A4 at singularities.
    """
    t6 = _flange_targets(model, pose, tool, base)
    lead = t6.shape[:-2]
    flat = t6.reshape(-1, 4, 4)
    h = np.broadcast_to(
        np.asarray(model.home if hint is None else hint, dtype=np.float64), (*lead, 6)
    )
    sols, _ = _solve(model, flat, h.reshape(-1, 6))
    if limits:
        turns = _turn_candidates(model)
        k = turns.shape[1]
        grids = np.meshgrid(*[np.arange(k)] * 6, indexing="ij")
        combos = np.stack([g.ravel() for g in grids], axis=-1)
        add = turns[np.arange(6), combos]  # (k**6, 6)
        add = add[~np.any(np.isnan(add), axis=1)]
        cand = sols[:, :, None, :] + add[None, None, :, :]
        ok = model.limit_mask(cand, _LIMIT_TOL)
        cand = np.where(ok[..., None], cand, np.nan).reshape(flat.shape[0], -1, 6)
        sols = cand
    if len(lead) > 0:
        if limits:
            # keep the batch rectangular: valid rows first, padded to the longest
            valid = ~np.isnan(sols[..., 0])
            order = np.argsort(~valid, axis=1, kind="stable")
            sols = np.take_along_axis(sols, order[..., None], axis=1)
            width = max(int(valid.sum(axis=1).max()), 1)
            sols = sols[:, :width]
        return sols.reshape(*lead, -1, 6)
    rows = sols[0][~np.isnan(sols[0, :, 0])]
    uniq: list[FloatArray] = []
    for r in rows:
        if not any(np.max(np.abs(r - u)) < 1e-9 for u in uniq):
            uniq.append(r)
    return np.array(uniq).reshape(-1, 6)


def inverse(
    model: RobotModel,
    pose: npt.ArrayLike,
    *,
    s: int | npt.ArrayLike | None = None,
    t: int | npt.ArrayLike | None = None,
    current: npt.ArrayLike | None = None,
    tool: npt.ArrayLike | None = None,
    base: npt.ArrayLike | None = None,
    errors: Literal["raise", "nan"] = "raise",
) -> FloatArray:
    """KUKA axes (degrees) reaching a TCP pose, like the KRC resolves a PTP to a POS.

    ``pose`` is XYZABC ``(..., 6)`` or ``(..., 4, 4)`` of the TCP in $BASE. Among all
    solutions (incl. multi-turn equivalents) inside the software limits, those matching the
    requested ``s`` (bits 0..2) and ``t`` are kept; of these the one nearest ``current``
    (Euclidean joint distance, default ``model.home``) wins. Raises :class:`UnreachableError`
    naming the reason, or with ``errors="nan"`` returns NaN rows for failed poses of a batch.
    """
    t6 = _flange_targets(model, pose, tool, base)
    lead = t6.shape[:-2]
    flat = t6.reshape(-1, 4, 4)
    n = flat.shape[0]
    ref = np.broadcast_to(
        np.asarray(model.home if current is None else current, dtype=np.float64), (*lead, 6)
    ).reshape(n, 6)
    base_q, beyond = _solve(model, flat, ref)  # (N, 8, 6)

    turns = _turn_candidates(model)  # (6, K)
    cand = base_q[..., None] + turns[None, None, :, :]  # (N, 8, 6, K)
    ok = (cand >= model.lower[:, None] - _LIMIT_TOL) & (cand <= model.upper[:, None] + _LIMIT_TOL)
    if t is not None:
        tb = np.broadcast_to(np.asarray(t, dtype=np.int64), lead).reshape(n)
        want_neg = ((tb[:, None] >> np.arange(6)) & 1).astype(bool)  # (N, 6)
        neg = cand < 0.0
        ok &= (neg == want_neg[:, None, :, None]) | (np.abs(cand) < _BIT_TOL)
    group_ok = np.ones(base_q.shape[:2], dtype=bool)
    if s is not None:
        sb = np.broadcast_to(np.asarray(s, dtype=np.int64), lead).reshape(n)
        # bit 0 (overhead) depends on the shoulder choice only: x of the wrist in the A1 frame
        x_a1 = _wrist_x_a1(model, base_q, flat)
        over = x_a1 < 0.0
        group_ok = (over == ((sb[:, None] & 1) == 1)) | (np.abs(x_a1) < _BIT_TOL)
        a3 = cand[:, :, 2, :]
        want1 = ((sb >> 1) & 1).astype(bool)[:, None, None]
        ok[:, :, 2, :] &= ((a3 >= model.status_phi) == want1) | (
            np.abs(a3 - model.status_phi) < _BIT_TOL
        )
        a5 = cand[:, :, 4, :]
        bit2 = ((a5 < 0.0) & (a5 >= -180.0)) | (a5 >= 180.0)
        want2 = ((sb >> 2) & 1).astype(bool)[:, None, None]
        ok[:, :, 4, :] &= (bit2 == want2) | (np.abs(a5) < _BIT_TOL)
    ok &= ~np.isnan(cand)
    cost = np.where(ok, (cand - ref[:, None, :, None]) ** 2, np.inf)
    best_k = np.argmin(cost, axis=-1)  # (N, 8, 6)
    best_cost = np.take_along_axis(cost, best_k[..., None], axis=-1)[..., 0]
    total = np.where(group_ok, best_cost.sum(axis=-1), np.inf)  # (N, 8)
    pick = np.argmin(total, axis=-1)
    chosen = np.take_along_axis(cand, best_k[..., None], axis=-1)[..., 0]  # (N, 8, 6)
    out = chosen[np.arange(n), pick]
    failed = ~np.isfinite(total[np.arange(n), pick])
    if np.any(failed):
        if errors == "raise":
            i = int(np.flatnonzero(failed)[0])
            idx = tuple(int(v) for v in np.unravel_index(i, lead))
            where = f"pose {idx} of {n}: " if lead else ""
            raise UnreachableError(where + _explain(model, base_q[i], beyond[i], s, t, i, lead, n))
        out[failed] = np.nan
    return np.asarray(out.reshape(*lead, 6), dtype=np.float64)


def _wrist_x_a1(model: RobotModel, base_q: FloatArray, t6: FloatArray) -> FloatArray:
    """Wrist-centre x in the A1 frame for each solution ``(N, 8)`` (sign = shoulder choice)."""
    al6 = math.radians(model.alpha[5])
    r6 = t6[:, :3, :3]
    w = t6[:, :3, 3] - model.d[5] * (r6 @ np.array([0.0, math.sin(al6), math.cos(al6)]))
    th1 = np.radians(model.sign[0] * base_q[..., 0] + model.offset[0])
    return np.asarray(np.cos(th1) * w[:, None, 0] + np.sin(th1) * w[:, None, 1])


def _explain(
    model: RobotModel,
    sols: FloatArray,
    beyond: float,
    s: int | npt.ArrayLike | None,
    t: int | npt.ArrayLike | None,
    i: int,
    lead: tuple[int, ...],
    n: int,
) -> str:
    """Why pose i has no acceptable solution, for the error message."""
    valid = sols[~np.isnan(sols[:, 0])]
    if len(valid) == 0:
        return (
            f"out of reach for {model.name}: the wrist centre is {beyond:.3f} mm beyond "
            f"the arm's range (reach {model.reach:.1f} mm from axis 2)"
        )
    parts = []
    seen: list[FloatArray] = []
    for q in valid:
        if any(np.allclose(q, v, atol=1e-9) for v in seen):
            continue  # singular poses repeat a solution
        seen.append(q)
        qs = _best_turns(model, q) + 0.0
        viol = model.limit_violations(qs, _LIMIT_TOL)
        st = status_turn(model, qs)
        desc = "A " + " ".join(f"{v:.3f}" for v in qs) + f" (S {st[0]} T {st[1]})"
        parts.append(desc + (": " + ", ".join(viol) if viol else ""))
    want = []
    if s is not None:
        want.append(f"S {int(np.broadcast_to(np.asarray(s), lead).reshape(n)[i])}")
    if t is not None:
        want.append(f"T {int(np.broadcast_to(np.asarray(t), lead).reshape(n)[i])}")
    asked = f" with {' '.join(want)}" if want else ""
    return (
        f"no solution{asked} inside the software limits of {model.name}; "
        f"solutions: {'; '.join(parts)}"
    )


def _best_turns(model: RobotModel, q: FloatArray) -> FloatArray:
    """q with each axis shifted by the 360° multiple that violates its limits least."""
    turns = _turn_candidates(model)
    cand = q[:, None] + turns
    over = np.maximum(model.lower[:, None] - cand, cand - model.upper[:, None])
    over = np.where(np.isnan(cand), np.inf, np.maximum(over, 0.0) + 1e-9 * np.abs(turns))
    return np.asarray(cand[np.arange(6), np.argmin(over, axis=1)])
