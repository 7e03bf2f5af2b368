"""Forward kinematics of ONE pose with plain Python floats, for code that needs one per cycle.

:func:`~.forward.fk_matrix` is batched numpy: on a single pose its per-call overhead (a dozen
small arrays, five 4×4 matmuls) costs ~40 µs, more than the arithmetic. The simulated robot
publishes one ``$POS_ACT`` per 12 ms cycle, for every robot of a cell, so
:class:`SinglePoseFK` does the same chain with the D-H constants precomputed and floats only
(~10 µs). Same conventions and results as :func:`~.forward.forward` (to ~1e-12; a property test
checks it): ``inv(BASE) · FLANGE(q) · TOOL`` as X, Y, Z (mm) and A, B, C (degrees) in
(-180°, 180°], A = 0 at the B = ±90° singularity.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from .frames import ABC_SINGULAR_COS
from .model import RobotModel

__all__ = ["SinglePoseFK"]

#: A 3×4 rigid transform as 12 floats, row-major: r11 r12 r13 px r21 r22 r23 py r31 r32 r33 pz.
Rt = tuple[float, float, float, float, float, float, float, float, float, float, float, float]

_DEG = math.pi / 180.0


def _rt(m: npt.ArrayLike) -> Rt:
    a = np.asarray(m, dtype=np.float64)
    return tuple(float(v) for v in a[:3, :4].reshape(12))  # type: ignore[return-value]


def _mul(a: Sequence[float], b: Sequence[float]) -> Rt:
    a11, a12, a13, ax, a21, a22, a23, ay, a31, a32, a33, az = a
    b11, b12, b13, bx, b21, b22, b23, by, b31, b32, b33, bz = b
    return (
        a11 * b11 + a12 * b21 + a13 * b31,
        a11 * b12 + a12 * b22 + a13 * b32,
        a11 * b13 + a12 * b23 + a13 * b33,
        a11 * bx + a12 * by + a13 * bz + ax,
        a21 * b11 + a22 * b21 + a23 * b31,
        a21 * b12 + a22 * b22 + a23 * b32,
        a21 * b13 + a22 * b23 + a23 * b33,
        a21 * bx + a22 * by + a23 * bz + ay,
        a31 * b11 + a32 * b21 + a33 * b31,
        a31 * b12 + a32 * b22 + a33 * b32,
        a31 * b13 + a32 * b23 + a33 * b33,
        a31 * bx + a32 * by + a33 * bz + az,
    )


def _clean(deg: float) -> float:
    # as frames._clean: no rounding noise or -0.0 in KRC text, angles in (-180°, 180°]
    if abs(deg) < 1e-12:
        return 0.0
    return deg + 360.0 if deg <= -180.0 else deg + 0.0


class SinglePoseFK:
    """``fk(q)`` of one robot model: the TCP frame of axis angles ``q`` (A1..A6, degrees).

    ``tool`` ($TOOL, TCP in the flange) and ``base`` ($BASE in ``$ROBROOT``) are 4×4
    transforms or None (``$NULLFRAME``); set them once with :meth:`set_frames` (a KRC changes
    them rarely), not per call.
    """

    __slots__ = ("_base_inv", "_flange", "_joints", "_phi", "_tool")

    def __init__(self, model: RobotModel) -> None:
        joints = []
        for a, alpha, d, offset, sign in zip(
            model.a, model.alpha, model.d, model.offset, model.sign, strict=True
        ):
            ca, sa = math.cos(math.radians(alpha)), math.sin(math.radians(alpha))
            # cos(±90°) is 6e-17, not 0: rounded like dh_transforms does
            ca = 0.0 if abs(ca) < 1e-15 else ca
            sa = 0.0 if abs(sa) < 1e-15 else sa
            joints.append((float(sign), float(offset), float(a), float(d), ca, sa))
        self._joints = tuple(joints)
        self._phi = float(model.status_phi)
        flange = np.asarray(model.flange, dtype=np.float64)
        self._flange: Rt | None = None if np.array_equal(flange, np.eye(4)) else _rt(flange)
        self._tool: Rt | None = None
        self._base_inv: Rt | None = None

    def set_frames(self, tool: npt.ArrayLike | None, base: npt.ArrayLike | None) -> None:
        """The 4×4 ``$TOOL`` and ``$BASE`` transforms (None: the null frame)."""
        self._tool = None if tool is None else _rt(tool)
        if base is None:
            self._base_inv = None
        else:
            b = np.asarray(base, dtype=np.float64)
            inv = np.eye(4)
            inv[:3, :3] = b[:3, :3].T
            inv[:3, 3] = -b[:3, :3].T @ b[:3, 3]
            self._base_inv = _rt(inv)

    def _chain(self, q: Sequence[float], joints: int = 6) -> Rt:
        cos, sin = math.cos, math.sin
        t: Rt | None = None
        for (sign, offset, a, d, ca, sa), qi in zip(self._joints[:joints], q, strict=False):
            theta = (sign * qi + offset) * _DEG
            ct, st = cos(theta), sin(theta)
            link = (ct, -st * ca, st * sa, a * ct, st, ct * ca, -ct * sa, a * st, 0.0, sa, ca, d)
            t = link if t is None else _mul(t, link)
        assert t is not None
        return t

    def matrix(self, q: Sequence[float]) -> Rt:
        """The TCP transform as 12 floats (see :data:`Rt`)."""
        t = self._chain(q)
        if self._flange is not None:
            t = _mul(t, self._flange)
        if self._tool is not None:
            t = _mul(t, self._tool)
        if self._base_inv is not None:
            t = _mul(self._base_inv, t)
        return t

    def frame(self, q: Sequence[float]) -> tuple[float, float, float, float, float, float]:
        """X, Y, Z (mm), A, B, C (degrees) of the TCP, as :func:`~.forward.forward`."""
        r11, r12, _, x, r21, r22, _, y, r31, r32, r33, z = self.matrix(q)
        cb = math.hypot(r11, r21)
        b = math.atan2(-r31, cb)
        if cb < ABC_SINGULAR_COS:
            a = 0.0
            c = math.atan2(r12, r22) if r31 < 0.0 else math.atan2(-r12, r22)
        else:
            a = math.atan2(r21, r11)
            c = math.atan2(r32, r33)
        return (x, y, z, _clean(math.degrees(a)), _clean(math.degrees(b)), _clean(math.degrees(c)))

    def status_turn(self, q: Sequence[float]) -> tuple[int, int]:
        """KUKA ``(S, T)`` of ``q``, as :func:`~.forward.status_turn` (reference §2.1)."""
        qs = [float(v) for v in q]
        wrist = self._chain(qs, 5)  # axes 4, 5, 6 meet at the origin of D-H frame 5
        sign, offset = self._joints[0][:2]
        theta1 = (sign * qs[0] + offset) * _DEG
        x_a1 = wrist[3] * math.cos(theta1) + wrist[7] * math.sin(theta1)
        a5 = qs[4]
        s = (
            (1 if x_a1 < 0.0 else 0)
            + (2 if qs[2] >= self._phi else 0)
            + (4 if (0.0 > a5 >= -180.0) or a5 >= 180.0 else 0)
        )
        t = sum(1 << i for i, v in enumerate(qs) if v < 0.0)
        return s, t
