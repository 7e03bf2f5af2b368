"""Planned motion segments (PTP in axis space, LIN in Cartesian space) and their geometry.

A segment is what the advance run hands to the main run: a start, a displacement and a
:class:`~.profiles.Trapezoid` for its path parameter. The kernel superposes the displacement of
the running segments (two while an approximation blends one into the next), so a segment only
has to say how far along it is; it never knows the absolute position.

LIN orientation is interpolated as a rotation about one fixed axis (the axis-angle of
``R_end · R_startᵀ``, applied in the base frame), i.e. a slerp: the orientation turns at a
constant angular rate about one axis, unlike an A/B/C lerp whose axis wanders.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
import numpy.typing as npt

from .profiles import Trapezoid

__all__ = ["Kind", "Segment", "rotation_log", "rotvec_matrix"]

FloatArray = npt.NDArray[np.float64]


class Kind(Enum):
    PTP = "PTP"
    LIN = "LIN"


@dataclass(eq=False)
class Segment:
    """One planned motion.

    ``delta`` is the axis displacement (deg, PTP) or the TCP translation (mm, LIN);
    ``rotvec`` the LIN rotation (rad, axis × angle, base frame). ``end_q`` is the planned end
    axis position (for a LIN the IK solution of the end pose, checked at planning time).
    ``approx`` says whether the main run may blend into the next segment; ``blend_fraction``
    is the remaining part of ``s`` below which blending may begin (from $APO).
    """

    kind: Kind
    profile: Trapezoid
    delta: FloatArray
    end_q: FloatArray
    approx: bool = False
    blend_fraction: float = 0.0
    rotvec: FloatArray = field(default_factory=lambda: np.zeros(3))
    label: str = ""
    #: Profile time elapsed (s of planned time, at 100 % override).
    t: float = 0.0

    @property
    def duration(self) -> float:
        return self.profile.duration

    @property
    def done(self) -> bool:
        return self.t >= self.profile.duration

    def blend_start(self, following: Segment) -> float:
        """When ``following`` may start, superposed on this one (profile time).

        Never before the remaining fraction fell under ``blend_fraction`` ($APO), and never
        before ``duration − min(t_dec, following.t_acc)``: inside that window this segment's
        speed falls linearly while the next one's rises no faster than linearly, so their sum
        never exceeds the larger of the two peaks, i.e. never exceeds a speed limit.
        """
        if not self.approx or following.kind is not self.kind:
            return self.duration
        window = min(self.profile.t_acc, following.profile.t_acc)
        by_distance = self.profile.time_at_remaining(self.blend_fraction)
        return max(by_distance, self.duration - window)


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
