"""The joint path of a straight TCP line: where a LIN's axes go, node by node.

The first stage of LIN planning (see :mod:`.path` for both): the line is sampled every
``LIN_STEP`` mm/deg and solved with IK in batches in the start's configuration, each solution
unwrapped to the multi-turn value nearest its neighbour, and intervals where an axis moves more
than ``MAX_STEP`` degrees are bisected; one shorter than ``MIN_STEP`` that still jumps is a
singularity on the line, and the LIN is refused (:class:`PathRefused`). A generator, yielding
after each IK batch. A LIN starting on the wrist singularity first turns A4/A6 in place
(:func:`leave_wrist_singularity`).
"""

from __future__ import annotations

import math
from collections.abc import Generator

import numpy as np

from pyopenshowvar.kinematics import RobotModel, UnreachableError, inverse, status_turn

from .profiles import FloatArray

__all__ = [
    "IK_BATCH",
    "LinGeometry",
    "PathRefused",
    "joint_path",
    "leave_wrist_singularity",
    "singularity",
]

#: Coarse sampling of the line (mm, or degrees of orientation).
LIN_STEP = 5.0
#: No axis moves more than this (deg) between two nodes of the joint path.
MAX_STEP = 2.0
#: An interval this short (mm or deg) that still jumps is a discontinuity: a singularity.
MIN_STEP = 1e-3
#: A path needing more nodes than this runs too close to a singularity to be planned.
MAX_NODES = 6000
#: Poses per IK batch (well under 1 ms each).
IK_BATCH = 32


class PathRefused(Exception):
    """The line cannot be run; the text says why (the kernel prefixes the statement)."""


class LinGeometry:
    """The straight TCP line of a LIN: ``pose(s) = (p0 + s·dp, Rot(s·rv)·R0)`` in $BASE."""

    def __init__(self, start: FloatArray, dp: FloatArray, rv: FloatArray) -> None:
        self.start = start
        self.dp = dp
        self.rv = rv
        self.length = float(np.linalg.norm(dp))
        self.angle = math.degrees(float(np.linalg.norm(rv)))

    @property
    def scale(self) -> float:
        """mm (or deg) per unit of s: what ``LIN_STEP`` and ``MIN_STEP`` measure."""
        return max(self.length, self.angle)

    def poses(self, s: FloatArray) -> FloatArray:
        """The TCP poses ``(n, 4, 4)`` at path parameters ``s``."""
        n = len(s)
        out = np.broadcast_to(self.start, (n, 4, 4)).copy()
        out[:, :3, 3] += s[:, None] * self.dp
        theta = float(np.linalg.norm(self.rv))
        if theta > 1e-15:
            k = self.rv / theta
            kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
            a = theta * s
            rot = (
                np.eye(3)
                + np.sin(a)[:, None, None] * kx
                + (1.0 - np.cos(a))[:, None, None] * (kx @ kx)
            )
            out[:, :3, :3] = rot @ self.start[:3, :3]
        return out


def leave_wrist_singularity(
    model: RobotModel, geo: LinGeometry, q0: FloatArray, tool: FloatArray, base: FloatArray
) -> tuple[FloatArray, int]:
    """Where a line that starts *on* the wrist singularity (A5 = 0, e.g. HOME) really starts.

    There only A4 ± A6 is defined, and the line leaves in one particular split of the two. The
    returned start has that split (the same TCP pose: the wrist turns in place), with the S bits
    of the branch the line continues in.
    """
    step = min(1.0, MIN_STEP / max(geo.scale, 1e-12))
    near = inverse(model, geo.poses(np.array([step]))[0], current=q0, tool=tool, base=base)
    start = inverse(model, geo.start, current=near, tool=tool, base=base)
    start = start - 360.0 * np.round((start - q0) / 360.0)  # the turn nearest the robot's
    return start, int(status_turn(model, near)[0])


def _chain(q0: FloatArray, q: FloatArray) -> FloatArray:
    """Unwrap a joint path: each step taken as its equivalent in (-180, 180]."""
    step = np.diff(np.vstack([q0, q[1:]]), axis=0)
    step = step - 360.0 * np.round(step / 360.0)
    return np.vstack([q0, q0 + np.cumsum(step, axis=0)])


def singularity(model: RobotModel, q: FloatArray) -> str:
    """Which of the KSS singularities a joint position is near."""
    # plain ASCII: the text ends up in $EMU_MESSAGE[], a KRL CHAR array (no Greek letters)
    if abs(q[4]) < 10.0:
        return "wrist (A5 = 0)"
    if abs(q[2] - model.status_phi) < 10.0:
        return f"arm-stretched (A3 = {model.status_phi:.1f})"
    return "overhead (wrist centre above A1)"


def joint_path(
    model: RobotModel,
    geo: LinGeometry,
    q0: FloatArray,
    tool: FloatArray,
    base: FloatArray,
    config: int | None = None,
) -> Generator[None, None, tuple[FloatArray, FloatArray]]:
    """Nodes ``(s, q)`` of the joint path along the line, yielding after each IK batch.

    ``config`` (S bits) defaults to the start's. Raises :class:`PathRefused` when a pose is out
    of reach or the line crosses a singularity.
    """
    if config is None:
        config = int(status_turn(model, q0)[0])

    def solve(s: FloatArray, near: FloatArray) -> FloatArray:
        return inverse(
            model, geo.poses(s), s=config, current=near, tool=tool, base=base, errors="nan"
        )

    def unreachable(s: float) -> PathRefused:
        try:
            inverse(model, geo.poses(np.array([s]))[0], s=config, tool=tool, base=base)
        except UnreachableError as exc:
            return PathRefused(f"path not reachable at {s:.0%}: {exc}")
        return PathRefused(f"path not reachable at {s:.0%}")

    n = max(2, math.ceil(geo.scale / LIN_STEP) + 1)
    s = np.linspace(0.0, 1.0, n)
    q = np.empty((n, 6))
    q[0] = q0
    q[-1] = solve(s[-1:], q0)  # the target first: an unreachable one is refused at once
    if np.isnan(q[-1, 0]):
        raise unreachable(1.0)
    for i in range(1, n - 1, IK_BATCH):
        j = min(i + IK_BATCH, n - 1)
        q[i:j] = solve(s[i:j], q0)
        yield
    bad = np.flatnonzero(np.isnan(q[:, 0]))
    if len(bad):
        raise unreachable(float(s[bad[0]]))
    q = _chain(q0, q)
    while True:
        jump = np.max(np.abs(np.diff(q, axis=0)), axis=1)
        wide = np.flatnonzero(jump > MAX_STEP)
        if not len(wide):
            return s, q
        short = wide[(s[wide + 1] - s[wide]) * geo.scale < MIN_STEP]
        if len(short):
            k = int(short[0])
            where = singularity(model, q[k])
            raise PathRefused(f"path crosses the {where} singularity near {s[k]:.0%}")
        if len(s) + len(wide) > MAX_NODES:
            k = int(wide[np.argmax(jump[wide])])
            where = singularity(model, q[k])
            raise PathRefused(f"path runs too close to the {where} singularity near {s[k]:.0%}")
        mid = 0.5 * (s[wide] + s[wide + 1])
        qm = np.empty((len(wide), 6))
        for i in range(0, len(wide), IK_BATCH):
            qm[i : i + IK_BATCH] = solve(mid[i : i + IK_BATCH], q[wide[i : i + IK_BATCH]])
            yield
        lost = np.flatnonzero(np.isnan(qm[:, 0]))
        if len(lost):
            raise unreachable(float(mid[lost[0]]))
        order = np.argsort(np.concatenate([s, mid]), kind="stable")
        s = np.concatenate([s, mid])[order]
        q = _chain(q0, np.vstack([q, qm])[order])
