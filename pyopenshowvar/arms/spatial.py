"""Small rigid-body helpers of the arms package: URDF origins, rotation logs, batched.

URDF writes a fixed transform as ``xyz`` plus ``rpy`` (roll, pitch, yaw about the fixed x,
y, z axes, i.e. ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``); D-H tables are products of elementary
transforms. Everything here works on numpy arrays with any leading shape.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ..kinematics.frames import FloatArray

__all__ = [
    "origin",
    "rot_x",
    "rot_z",
    "rotation_log",
    "rpy_from_matrix",
    "trans",
]


def _snap(v: float) -> float:
    # cos(90°) is 6e-17, not 0; exact zeros keep table poses exact (as the D-H code does)
    return 0.0 if abs(v) < 1e-15 else v


def rot_x(angle: float) -> FloatArray:
    """4×4 rotation about x by ``angle`` radians."""
    c, s = _snap(math.cos(angle)), _snap(math.sin(angle))
    return np.array([[1.0, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def rot_z(angle: float) -> FloatArray:
    """4×4 rotation about z by ``angle`` radians."""
    c, s = _snap(math.cos(angle)), _snap(math.sin(angle))
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])


def trans(x: float, y: float, z: float) -> FloatArray:
    """4×4 translation."""
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


def origin(xyz: npt.ArrayLike, rpy: npt.ArrayLike) -> FloatArray:
    """The URDF ``<origin xyz rpy>`` transform (rpy in radians): ``Trans(xyz)·Rz·Ry·Rx``."""
    r, p, y = (float(v) for v in np.asarray(rpy, dtype=np.float64).reshape(3))
    cr, sr = _snap(math.cos(r)), _snap(math.sin(r))
    cp, sp = _snap(math.cos(p)), _snap(math.sin(p))
    cy, sy = _snap(math.cos(y)), _snap(math.sin(y))
    t = np.eye(4)
    t[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    t[:3, 3] = np.asarray(xyz, dtype=np.float64).reshape(3)
    return t


def rpy_from_matrix(t: npt.ArrayLike) -> FloatArray:
    """URDF roll, pitch, yaw (radians) of a rotation (top-left 3×3 of ``t``)."""
    m = np.asarray(t, dtype=np.float64)[:3, :3]
    pitch = math.atan2(-m[2, 0], math.hypot(m[0, 0], m[1, 0]))
    if math.hypot(m[0, 0], m[1, 0]) < 1e-12:  # gimbal lock: put everything into roll
        return np.array([math.atan2(-m[1, 2], m[1, 1]), pitch, 0.0])
    return np.array([math.atan2(m[2, 1], m[2, 2]), pitch, math.atan2(m[1, 0], m[0, 0])])


def rotation_log(r: FloatArray) -> FloatArray:
    """Rotation vectors (axis·angle, radians) of rotation matrices ``(..., 3, 3)``.

    Uses the skew part and the trace together (exact near 0), and the symmetric part near
    π where the skew part vanishes, so the IK error never loses its direction.
    """
    v = np.stack(
        [r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]],
        axis=-1,
    )
    s = 0.5 * np.linalg.norm(v, axis=-1)
    c = 0.5 * (r[..., 0, 0] + r[..., 1, 1] + r[..., 2, 2] - 1.0)
    angle = np.arctan2(s, c)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(s > 1e-9, angle / (2.0 * s), 0.5 + angle**2 / 12.0)
    out = v * scale[..., None]
    near_pi = (s <= 1e-6) & (c < 0.0)
    if np.any(near_pi):
        # R ≈ 2aaᵀ − I: the axis is the dominant column of R + I (sign from the skew part)
        rp = r[near_pi] + np.eye(3)
        k = np.argmax(np.einsum("nii->ni", rp), axis=-1)
        col = rp[np.arange(len(k)), :, k]
        axis = col / np.linalg.norm(col, axis=-1, keepdims=True)
        sgn = np.where(np.einsum("ni,ni->n", axis, v[near_pi]) < 0.0, -1.0, 1.0)
        out[near_pi] = axis * (sgn * angle[near_pi])[:, None]
    return np.asarray(out)
