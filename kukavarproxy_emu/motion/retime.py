"""The last check of a LIN's timing: the axis accelerations on the set-points themselves.

:class:`~.path.PathLimits` bounds every axis acceleration ``q'·s̈ + q''·ṡ²`` with the slope and
curvature of the joint path *at its IK nodes*. Close to a singularity (the arm stretched, the
wrist near A5 = 0) the curvature between two nodes can grow faster than the nodes sample it,
and the set-points the drives get then ask an axis for more than its limit (a random LIN with
4.5 kg ending near the arm-stretched singularity asked A2 for 1.22× its limit; the first chord
of a path can understate its slope, 1.34× in a first cycle).

A KRC limits the axis accelerations of a CP motion on what it commands. So does
:func:`check_accelerations`: it samples the planned profile every quarter IPO cycle, from the
standing position before it to the one after it, solves those poses with IK as the kernel
will, and takes second differences over one cycle at each of the four phases (a motion queued
behind another starts at any phase of the cycle): the accelerations the drives see. A
difference that straddles the start or the stop is divided by the share of its window inside
the motion, so that the motion's own part keeps the limit whatever stands or moves next to it
(an exact stop whose next motion starts within the same cycle adds the two parts). Where one
exceeds the limit, the acceleration rows of the nodes under it are tightened by the excess
(:meth:`~.path.PathLimits.tighten`) and the profile is planned again; a motion within its
limits keeps its timing exactly.

:func:`blend_ratio` checks a C_DIS window between two LINs the same way (the kernel superposes
the lines in Cartesian space, so in the window the axes follow neither joint path).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator

import numpy as np

from .joint_path import IK_BATCH, LinGeometry
from .path import PathLimits
from .profiles import Curve, FloatArray, Profile
from .segments import Segment

__all__ = ["blend_ratio", "check_accelerations"]

#: Rounds of tightening before the profile is slowed down as a whole.
ROUNDS = 8
#: Where a sample exceeds its limit, the rows under it aim this far below it.
AIM = 0.97
#: Phases of the IPO cycle checked (samples every ipo / PHASES, differences over one cycle).
PHASES = STEP = 4
#: The smallest share of a difference's window inside the motion that is scaled up to the
#: whole window (below it, the motion's share is too brief to say what it asks of the axis).
MIN_SHARE = 0.25
#: Ratios up to this count as within the limit (float rounding).
TOLERANCE = 1e-9

Solve = Callable[[FloatArray, FloatArray], FloatArray]
PoseSolve = Callable[[FloatArray, FloatArray], FloatArray]


def _sampled_ratio(
    limits: PathLimits, curve: Curve, solve: Solve, h: float
) -> Generator[None, None, tuple[FloatArray, FloatArray]]:
    """Per sample ``t = j·h`` of the profile: the worst axis acceleration / limit, and ``s``.

    The samples run from one cycle before the start to one after the end (the robot stands
    there), so the start and the stop are second differences like any other."""
    profile = Profile(*curve)
    n = math.ceil(profile.duration / h) + 2 * STEP
    times = np.arange(-STEP, n + 1) * h
    s = np.array([profile.s_at(float(t)) for t in times])
    near = np.column_stack([np.interp(s, limits.s, limits.q[:, i]) for i in range(6)])
    q = np.empty_like(near)
    for i in range(0, len(s), IK_BATCH):
        q[i : i + IK_BATCH] = solve(s[i : i + IK_BATCH], near[i : i + IK_BATCH])
        yield
    q = q - 360.0 * np.round((q - near) / 360.0)  # the turn the joint path is on
    acc = np.abs(q[2 * STEP :] - 2.0 * q[STEP:-STEP] + q[: -2 * STEP]) / (STEP * h) ** 2
    # A difference that straddles the start or the stop weighs the motion's own acceleration
    # with the part of its window inside the motion; the rest is the robot standing. Another
    # motion may take that part (an exact stop, the next one starting within the same cycle),
    # so the motion's own share must keep the limit by itself: divide by its weight.
    centre = np.asarray(times[STEP:-STEP], dtype=np.float64) / (STEP * h)  # in cycles
    inside = _tri_cdf(profile.duration / (STEP * h) - centre) - _tri_cdf(-centre)
    with np.errstate(invalid="ignore"):
        ratio = np.nan_to_num(np.max(acc / limits.a_limit, axis=1))
    ratio = ratio / np.maximum(inside, MIN_SHARE)
    return ratio, s


def _tri_cdf(u: FloatArray) -> FloatArray:
    """Share of a second difference's weight (a triangle over ``[-1, 1]`` cycles) below ``u``."""
    u = np.clip(u, -1.0, 1.0)
    return np.asarray(np.where(u <= 0.0, 0.5 * (1.0 + u) ** 2, 1.0 - 0.5 * (1.0 - u) ** 2))


def check_accelerations(
    limits: PathLimits, curve: Curve, bw: Curve, solve: Solve, ipo: float
) -> Generator[None, None, tuple[Curve, Curve]]:
    """``(curve, bw)`` of :meth:`PathLimits.plan`, re-planned until the set-points sampled at
    ``PHASES`` phases of the cycle keep every axis within its acceleration limit (module
    docstring).

    ``solve(s, near)`` gives the axes at path parameters ``s`` (IK nearest ``near``)."""
    h = ipo / PHASES
    factor = np.ones(len(limits.s))
    for _ in range(ROUNDS):
        ratio, s = yield from _sampled_ratio(limits, curve, solve, h)
        over = np.flatnonzero(ratio > 1.0 + TOLERANCE)
        if not len(over):
            return curve, bw
        scale = np.ones(len(factor))
        for j in over:
            # difference j spans samples j .. j + 2·STEP: the nodes under that stretch of s
            lo = max(int(np.searchsorted(limits.s, s[j], side="right")) - 1, 0)
            hi = int(np.searchsorted(limits.s, s[j + 2 * STEP], side="left"))
            np.minimum(scale[lo : hi + 1], AIM / ratio[j], out=scale[lo : hi + 1])
        factor *= scale
        limits.tighten(factor)
        curve, bw = yield from limits.plan()
    # still above (should not happen): the whole profile slower; its accelerations scale with ṡ²
    ratio, _ = yield from _sampled_ratio(limits, curve, solve, h)
    worst = float(np.max(ratio))
    if worst > 1.0 + TOLERANCE:
        k = AIM / worst
        curve, bw = (curve[0], curve[1] * k), (bw[0], bw[1] * k)
    return curve, bw


#: Seconds before the window and after the next segment's head that a blend's check
#: samples besides them (the tail's braking and the head's ramp use the checked rows).
BLEND_REACH = 0.1


def blend_ratio(
    cur: Segment, nxt: Segment, base: FloatArray, solve: PoseSolve, ipo: float
) -> float:
    """The worst axis acceleration / limit of two LINs blended by :func:`.segments.blend`.

    The kernel superposes their Cartesian displacements from ``base`` (``cur``'s start pose)
    and solves each cycle with IK, so in the window the axes follow neither line: the blend's
    own rows (the axis speeds at the window's two ends) miss the joint path's curvature there.
    Sampled like :func:`check_accelerations`, from just before the tail the blend re-timed to
    just after the head; run at once (no slices: the caller may have to undo the blend, which
    is only safe while no cycle ran)."""
    assert cur.blend_at is not None
    h = ipo / PHASES
    t0 = max(cur.t, cur.blend_at - BLEND_REACH)
    t1 = cur.blend_at + min(nxt.duration, nxt.profile.time_at(nxt.head_end) + BLEND_REACH)
    times = t0 + np.arange(-STEP, math.ceil((t1 - t0) / h) + STEP + 1) * h
    s_a = np.array([cur.profile.s_at(float(t)) for t in times])
    s_b = np.array([nxt.profile.s_at(float(t) - cur.blend_at) for t in times])
    # the kernel's pose: cur's part of the line from base, then nxt's on top of it
    poses = LinGeometry(base, cur.delta, cur.rotvec).poses(s_a)
    turn = LinGeometry(np.eye(4), nxt.delta, nxt.rotvec).poses(s_b)
    poses[:, :3, 3] += turn[:, :3, 3]
    poses[:, :3, :3] = turn[:, :3, :3] @ poses[:, :3, :3]
    guess = _node_q(cur, s_a) + _node_q(nxt, s_b) - _node_q(nxt, np.zeros(1))
    q = solve(poses, guess)
    q = q - 360.0 * np.round((q - guess) / 360.0)
    acc = np.abs(q[2 * STEP :] - 2.0 * q[STEP:-STEP] + q[: -2 * STEP]) / ipo**2
    limit = np.minimum(cur.limits.a_limit, nxt.limits.a_limit)  # type: ignore[union-attr]
    with np.errstate(invalid="ignore"):
        return float(np.nan_to_num(np.max(acc / limit)))


def _node_q(seg: Segment, s: FloatArray) -> FloatArray:
    """The axes of ``seg``'s joint path at ``s``, linear between its IK nodes."""
    limits = seg.limits
    assert isinstance(limits, PathLimits)
    return np.column_stack([np.interp(s, limits.s, limits.q[:, i]) for i in range(6)])
