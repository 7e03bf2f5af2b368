"""Planned motion segments (PTP in axis space, LIN in Cartesian space) and approximation.

A segment is what the advance run hands to the main run: a displacement, the limits of its path
parameter and a :class:`~.profiles.Profile` of that parameter over time. The kernel superposes
the displacements of the running segments (two while an approximation blends one into the
next), so a segment only has to say how far along it is; it never knows the absolute position.

**Approximation** (reference §5: start at the given distance, at most half the segment, within
limits). When the next motion is planned in time, :func:`blend` re-times the tail of the current
segment and the head of the next one so that, from the moment the current one has
``blend_fraction`` of its path left, one decelerates linearly to rest while the other
accelerates linearly from rest, over the same time ``T``. During that window every axis speed is
a convex combination of the two end speeds (never above a limit) and every acceleration is
``(v_next − v_cur) / T``; if that exceeds a limit (a reversal, a sharp corner), both segments
enter the window slower — the distance stays where ``$APO`` says, the speed gives. A segment
never starts slowing down for its next window before the window it was blended in by has
ended (three superposed motions would add their accelerations): if it would have to, it stops
exactly instead.

LIN orientation is interpolated as a rotation about one fixed axis (the axis-angle of
``R_end · R_startᵀ``, applied in the base frame), i.e. a slerp: the orientation turns at a
constant angular rate about one axis, unlike an A/B/C lerp whose axis wanders.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from .joint_path import PathRefused
from .path import PathLimits
from .profiles import Curve, FloatArray, Profile, pl_min, ramp_curve, scalar_limits

__all__ = ["ConstLimits", "Kind", "Segment", "blend", "rotation_log", "rotvec_matrix"]


class Kind(Enum):
    PTP = "PTP"
    LIN = "LIN"


class ConstLimits:
    """The path-parameter limits of a PTP: ``Δq`` is constant, so are ``ṡ_max`` and ``s̈_max``."""

    def __init__(self, delta: FloatArray, v_axis: FloatArray, a_axis: FloatArray) -> None:
        self.delta = delta
        self.a_axis = a_axis
        self.v, self.a = scalar_limits(delta, v_axis, a_axis)

    def adapt(self, v: float, a: float) -> None:
        """Lower the limits of ``s`` to ``(v, a)`` (the motors' torque, :mod:`.dynamics`); the
        axis accelerations, which blends and override ramps respect, scale with ``a``."""
        if a < self.a:
            self.a_axis = self.a_axis * (a / self.a)
        self.v, self.a = min(v, self.v), min(a, self.a)

    def xcap_on(self, s0: float, s1: float) -> float:
        return self.v * self.v

    def derivatives(self, s: float) -> tuple[FloatArray, FloatArray]:
        return self.delta, np.zeros(6)

    def backward(
        self, s_end: float, x_end: float, above: Curve | None = None
    ) -> Generator[None, None, Curve]:
        yield from ()
        ends = np.array([0.0, s_end])
        return ends, np.array([x_end + 2.0 * self.a * s_end, x_end])

    def forward(self, s_start: float, x_start: float, below: Curve) -> Generator[None, None, Curve]:
        # ``below`` is this segment's own braking curve, which the ramp already respects
        yield from ()
        return ramp_curve(s_start, x_start, 1.0, 0.0, self.v * self.v, self.a)

    def plan(self) -> Generator[None, None, tuple[Curve, Curve]]:
        yield from ()
        if math.isinf(self.v):
            return (np.array([1.0]), np.array([0.0])), (np.array([0.0, 1.0]), np.zeros(2))
        cap = self.v * self.v
        curve = ramp_curve(0.0, 0.0, 1.0, 0.0, cap, self.a)
        s_d = 1.0 - cap / (2.0 * self.a)  # braking from the cap must start here
        if s_d > 0.0:
            return curve, (np.array([0.0, s_d, 1.0]), np.array([cap, cap, 0.0]))
        return curve, (np.array([0.0, 1.0]), np.array([2.0 * self.a, 0.0]))


Limits = ConstLimits | PathLimits


@dataclass(eq=False)
class Segment:
    """One planned motion.

    ``delta`` is the axis displacement (deg, PTP) or the TCP translation (mm, LIN);
    ``rotvec`` the LIN rotation (rad, axis × angle, base frame). ``end_q`` is the planned end
    axis position (for a LIN the end of the joint path checked at planning time).
    ``approx`` says whether the main run may blend into the next segment; ``blend_fraction`` is
    the part of ``s`` left when blending starts ($APO, at most 0.5). ``bw`` is the fastest
    curve that still stops at the end (the limit for re-timing the head). ``blend_at`` is set
    when the next segment was blended in: the profile time at which it starts.
    """

    kind: Kind
    profile: Profile
    limits: Limits
    bw: Curve
    delta: FloatArray
    end_q: FloatArray
    approx: bool = False
    blend_fraction: float = 0.0
    rotvec: FloatArray = field(default_factory=lambda: np.zeros(3))
    label: str = ""
    #: Cartesian window rows of a LIN: (vector per unit s, its acceleration limit).
    cartesian: list[tuple[FloatArray, float]] = field(default_factory=list)
    #: Profile time elapsed (s of planned time, at 100 % override).
    t: float = 0.0
    blend_at: float | None = None
    #: Where (in s) the window in which this segment was blended in ends: the motion before
    #: it is done there, and this segment's own tail window may not begin earlier.
    head_end: float = 0.0

    @property
    def duration(self) -> float:
        return self.profile.duration

    @property
    def done(self) -> bool:
        return self.t >= self.profile.duration

    @property
    def progress(self) -> float:
        """Where along its path the segment is (0..1)."""
        return self.profile.s_at(self.t)

    def rates(self, t: float | None = None) -> tuple[FloatArray, FloatArray]:
        """Axis velocity (deg/s) and acceleration (deg/s²) at 100 %, now or at profile time t."""
        s, v, u = self.profile.at(self.t if t is None else t)
        qp, qpp = self.limits.derivatives(s)
        return qp * v, qp * u + qpp * (v * v)

    def mean_velocity(self, dtau: float) -> FloatArray:
        """Mean axis velocity (deg per s of profile time) over the next ``dtau`` of profile."""
        s0, s1 = self.profile.s_at(self.t), self.profile.s_at(self.t + dtau)
        qp, _ = self.limits.derivatives(0.5 * (s0 + s1))
        return qp * ((s1 - s0) / dtau)

    def axis_accel(self) -> FloatArray:
        """The axis acceleration limits this segment was planned with (deg/s²)."""
        return self.limits.a_axis


def blend(
    cur: Segment, nxt: Segment, progress: Callable[[], float], ease: float = 1.0
) -> Generator[None, None, bool]:
    """Re-time ``cur``'s tail and ``nxt``'s head for approximation (module docstring).

    ``ease`` (≤ 1) scales the window's accelerations further down (the speeds by its root):
    for LINs, whose axes in the window follow neither line (:func:`.retime.blend_ratio`).

    ``progress()`` says where ``cur`` is now (it may run while this yields). Returns False,
    changing nothing, when no approximation is possible: no ``$APO``, a zero-length segment,
    a PTP↔LIN change, or ``cur`` already too far along to reach the window's entry speed.
    """
    frac = cur.blend_fraction
    if not cur.approx or cur.kind is not nxt.kind or frac <= 0.0:
        return False
    if cur.duration <= 0.0 or nxt.duration <= 0.0:
        return False
    s_b = 1.0 - frac
    if progress() >= s_b:
        return False
    v_a = math.sqrt(min(cur.profile.x_at(s_b), cur.limits.xcap_on(s_b, 1.0)))
    v_b = math.sqrt(nxt.limits.xcap_on(0.0, 0.5))
    if v_a <= 0.0 or v_b <= 0.0:
        return False
    # the head covers v_b/v_a times the tail's distance, at most half of the next segment
    frac_b = min(0.5, v_b * frac / v_a)
    v_b = min(frac_b * v_a / frac, math.sqrt(float(np.interp(frac_b, *nxt.bw))))
    frac_b = v_b * frac / v_a
    # window acceleration: |v_b·W_next − v_a·W_cur| ≤ a_lim·T with T = 2·frac / v_a
    w_a, _ = cur.limits.derivatives(1.0)
    w_b, _ = nxt.limits.derivatives(0.0)
    rows = [(np.abs(v_b * w_b - v_a * w_a), np.minimum(cur.axis_accel(), nxt.axis_accel()))]
    for (vec_a, cart_lim), (vec_b, _same) in zip(cur.cartesian, nxt.cartesian, strict=True):
        dv_cart = float(np.linalg.norm(v_b * vec_b - v_a * vec_a))
        rows.append((np.array([dv_cart]), np.array([cart_lim])))
    lam2 = 1.0
    for dv, lim in rows:
        moving = dv > 1e-12
        if np.any(moving):
            lam2 = min(lam2, float(np.min(2.0 * frac * lim[moving] / (v_a * dv[moving]))))
    lam = math.sqrt(lam2 * ease)
    v_a, v_b = lam * v_a, lam * v_b
    old = cur.profile.curve()
    try:
        tail = yield from cur.limits.backward(s_b, v_a * v_a, above=old)
        head = yield from nxt.limits.forward(frac_b, v_b * v_b, nxt.bw)
    except (ValueError, PathRefused):
        return False
    mid = pl_min(tail, old)
    # braking starts at the node before the first one the new curve passes slower
    slower = np.flatnonzero(mid[1] < np.interp(mid[0], *old) * (1.0 - 1e-9) - 1e-12)
    if len(slower) and mid[0][max(int(slower[0]) - 1, 0)] < cur.head_end - 1e-9:
        # slowing down for this window would begin inside the window cur was blended in by:
        # three motions would superpose and their accelerations add. Stop exactly instead.
        return False
    keep = old[0] < mid[0][0]
    new_cur = (
        np.concatenate([old[0][keep], mid[0], [1.0]]),
        np.concatenate([old[1][keep], mid[1], [0.0]]),
    )
    new_nxt = (np.concatenate([[0.0], head[0]]), np.concatenate([[0.0], head[1]]))
    now = progress()
    if now >= s_b or np.interp(now, *new_cur) < np.interp(now, *old) - 1e-9:
        return False  # it would have to have slowed down already
    try:
        cur_profile, nxt_profile = Profile(*new_cur), Profile(*new_nxt)
    except ValueError:
        return False
    cur.profile, nxt.profile = cur_profile, nxt_profile
    cur.blend_at = cur_profile.time_at(s_b)
    nxt.head_end = frac_b
    return True


def rotvec_matrix(rv: FloatArray) -> FloatArray:
    """Rotation matrix of an axis-angle vector (rad), Rodrigues' formula."""
    angle = float(np.linalg.norm(rv))
    if angle < 1e-15:
        return np.eye(3)
    k = rv / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.asarray(np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx))


def rotation_log(r: FloatArray) -> FloatArray:
    """Axis-angle vector (rad) of a rotation matrix; the inverse of :func:`rotvec_matrix`."""
    cos = max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0))
    angle = math.acos(cos)
    if angle < 1e-12:
        return np.zeros(3)
    if math.pi - angle < 1e-6:  # 180°: the axis is the dominant column of (R + I) / 2
        b = (r + np.eye(3)) / 2.0
        i = int(np.argmax(np.diag(b)))
        axis = b[:, i] / math.sqrt(max(b[i, i], 1e-300))
        return np.asarray(axis * angle, dtype=np.float64)
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return np.asarray(w * (angle / (2.0 * math.sin(angle))), dtype=np.float64)
