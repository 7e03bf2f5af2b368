"""The plant's own frame arithmetic: a D-H link transform and a KUKA FRAME as 4×4 matrices.

Both the model file's reader (:mod:`.params`) and the MJCF writer (:mod:`.mjcf`) build bodies
from these; they are the plant's own (numpy only), not the client library's kinematics, so the
emulated robot never shares its numbers with the apps that estimate it.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

__all__ = ["FloatArray", "dh_matrix", "frame_matrix"]

FloatArray = npt.NDArray[np.float64]


def dh_matrix(a: float, alpha: float, d: float, theta: float) -> FloatArray:
    """Standard D-H link transform ``Rz(θ)·Tz(d)·Tx(a)·Rx(α)`` (mm, degrees)."""
    ct, st = np.cos(np.radians(theta)), np.sin(np.radians(theta))
    ca, sa = np.cos(np.radians(alpha)), np.sin(np.radians(alpha))
    return np.array(
        [[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0.0, sa, ca, d],
         [0.0, 0.0, 0.0, 1.0]]
    )  # fmt: skip


def frame_matrix(xyzabc: FloatArray | tuple[float, ...]) -> FloatArray:
    """KUKA FRAME (mm, deg; R = Rz(A)·Ry(B)·Rx(C)) as a 4×4 transform."""
    x, y, z, a, b, c = (float(v) for v in xyzabc)
    ca, sa = math.cos(math.radians(a)), math.sin(math.radians(a))
    cb, sb = math.cos(math.radians(b)), math.sin(math.radians(b))
    cc, sc = math.cos(math.radians(c)), math.sin(math.radians(c))
    return np.array(
        [[ca * cb, ca * sb * sc - sa * cc, ca * sb * cc + sa * sc, x],
         [sa * cb, sa * sb * sc + ca * cc, sa * sb * cc - ca * sc, y],
         [-sb, cb * sc, cb * cc, z],
         [0.0, 0.0, 0.0, 1.0]]
    )  # fmt: skip
