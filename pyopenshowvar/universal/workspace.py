"""The box that encloses an arm's workspace, the targets of the accuracy test, normalisation.

The thesis' solvers "normalise the target according to the workspace of the manipulator", so
that one target cost means the same for a 0.5 m youBot and a 13 m crane, and its accuracy
test solves "512 equally-spaced target positions in the volume box that encloses the
workspace" (§3.2.1.1). :func:`workspace_of` finds that box: the tip positions of many random
configurations within the limits, then each of the six extremes pushed outwards by projected
gradient ascent (sampling alone stops short of the true extremes). ``scale`` is the box's
largest side: errors "in % of the workspace" are per cent of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from ..arms.model import Arm
from ..kinematics.frames import FloatArray
from .pointfk import PointFK

__all__ = ["Workspace", "grid_targets", "workspace_of"]

#: Random configurations sampled for the box, and the extremes refined per direction.
SAMPLES = 20_000
REFINE = 8
REFINE_STEPS = 60


@dataclass(frozen=True, eq=False)
class Workspace:
    """An axis-aligned box in the arm's base frame (mm)."""

    lower: FloatArray
    upper: FloatArray

    @property
    def centre(self) -> FloatArray:
        return np.asarray((self.lower + self.upper) / 2.0)

    @property
    def size(self) -> FloatArray:
        return np.asarray(self.upper - self.lower)

    @property
    def scale(self) -> float:
        """The box's largest side (mm): one unit of the normalised coordinates."""
        return float(np.max(self.size))

    def normalise(self, x: npt.ArrayLike) -> FloatArray:
        """Positions (mm) relative to the centre, in units of :attr:`scale`."""
        return np.asarray((np.asarray(x, dtype=np.float64) - self.centre) / self.scale)

    def contains(self, x: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        xa = np.asarray(x, dtype=np.float64)
        return np.asarray(np.all((xa >= self.lower) & (xa <= self.upper), axis=-1))


def grid_targets(box: Workspace, per_axis: int = 8) -> FloatArray:
    """``per_axis``³ equally spaced points spanning the box, faces included, in serpentine
    order (consecutive targets are neighbours, as an operator's successive inputs are)."""
    if per_axis < 2:
        raise ValueError("per_axis must be at least 2")
    axes = [np.linspace(box.lower[k], box.upper[k], per_axis) for k in range(3)]
    out: list[tuple[float, float, float]] = []
    for i, x in enumerate(axes[0]):
        ys = axes[1] if i % 2 == 0 else axes[1][::-1]
        for j, y in enumerate(ys):
            zs = axes[2] if (i * per_axis + j) % 2 == 0 else axes[2][::-1]
            out.extend((x, y, z) for z in zs)
    return np.array(out)


def workspace_of(arm: Arm, tool: npt.ArrayLike | None = None, *, seed: int = 0) -> Workspace:
    """The box enclosing every tip position the arm reaches within its limits (cached)."""
    if tool is None:
        return _cached(arm, seed)
    return _compute(arm, PointFK(arm, tool), seed)


@lru_cache(maxsize=32)
def _cached(arm: Arm, seed: int) -> Workspace:
    return _compute(arm, PointFK(arm), seed)


def _compute(arm: Arm, fk: PointFK, seed: int) -> Workspace:
    rng = np.random.default_rng(seed)
    lo, hi = arm.lower, arm.upper
    q = rng.uniform(lo, hi, size=(SAMPLES, arm.dof))
    # the corners of the joint box too: extremes often sit at joint limits
    corners = np.array(np.meshgrid(*zip(lo, hi, strict=True))).reshape(arm.dof, -1).T
    q = np.concatenate([q, corners[:4096]])
    p = fk(q)
    lower, upper = p.min(axis=0), p.max(axis=0)
    span = hi - lo
    for k in range(3):
        for sign in (-1.0, 1.0):
            order = np.argsort(sign * p[:, k])[-REFINE:]
            best = _ascend(fk, q[order], k, sign, lo, hi, span)
            if sign > 0:
                upper[k] = max(upper[k], best)
            else:
                lower[k] = min(lower[k], -best)
    return Workspace(lower, upper)


def _ascend(
    fk: PointFK, q: FloatArray, k: int, sign: float, lo: FloatArray, hi: FloatArray,
    span: FloatArray,
) -> float:  # fmt: skip
    """Push ``sign·x_k`` of the tip up from configurations ``q``: coordinate-wise finite
    differences, steps that shrink when they stop improving, everything within the limits.
    Returns the best ``sign·x_k`` found."""
    n = q.shape[1]
    step = np.full(len(q), 0.02)  # fraction of each joint's range
    value = sign * fk(q)[:, k]
    eye = np.eye(n)
    for _ in range(REFINE_STEPS):
        h = 1e-4 * span
        probes = q[:, None, :] + eye[None] * h
        grad = (sign * fk(probes)[..., k] - value[:, None]) / h  # per unit of each joint
        g = grad * span
        norm = np.max(np.abs(g), axis=1, keepdims=True)
        d = np.where(norm > 0, g / np.where(norm > 0, norm, 1.0), 0.0)
        trial = np.clip(q + step[:, None] * span * d, lo, hi)
        tv = sign * fk(trial)[:, k]
        better = tv > value
        q = np.where(better[:, None], trial, q)
        value = np.where(better, tv, value)
        step = np.where(better, np.minimum(step * 1.5, 0.2), step * 0.5)
        if np.all(step < 1e-7):
            break
    return float(np.max(value)) if math.isfinite(float(np.max(value))) else -math.inf
