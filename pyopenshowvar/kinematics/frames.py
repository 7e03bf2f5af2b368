"""KUKA frames: XYZABC ⇄ homogeneous transforms, batched over leading dimensions.

KUKA writes an orientation as A, B, C (degrees) with R = Rz(A)·Ry(B)·Rx(C), the intrinsic
Z-Y'-X'' order. A FRAME ``{X, Y, Z, A, B, C}`` is the transform ``Trans(X, Y, Z)·R``.

The B = ±90° case (gimbal lock) follows the controller: a real KRC4 reported ``A 0.0`` and put
the whole rotation about the vertical into C (reference §1.4). We do the same whenever
``cos B < ABC_SINGULAR_COS`` (1e-5, i.e. |B| within ≈0.00057° of 90°). In that band the
returned A, B, C reproduce the rotation only to ≈1e-5 rad, exactly as the controller's numbers do.

Every function takes and returns degrees and millimetres; arrays broadcast over leading
dimensions, so one call converts a whole path.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = [
    "ABC_SINGULAR_COS",
    "FloatArray",
    "abc_from_matrix",
    "as_transform",
    "frame_to_matrix",
    "inv_transform",
    "matrix_from_abc",
    "matrix_to_frame",
    "pose_to_matrix",
    "rotation_angle_deg",
]

FloatArray = npt.NDArray[np.float64]

#: Below this value of cos B the A/B/C extraction uses the controller's B = ±90° rule.
ABC_SINGULAR_COS = 1e-5


def matrix_from_abc(a: npt.ArrayLike, b: npt.ArrayLike, c: npt.ArrayLike) -> FloatArray:
    """Rotation matrix Rz(A)·Ry(B)·Rx(C) for angles in degrees; shape ``(..., 3, 3)``."""
    ar, br, cr = (np.radians(np.asarray(v, dtype=np.float64)) for v in (a, b, c))
    ar, br, cr = np.broadcast_arrays(ar, br, cr)
    ca, sa = np.cos(ar), np.sin(ar)
    cb, sb = np.cos(br), np.sin(br)
    cc, sc = np.cos(cr), np.sin(cr)
    r = np.empty((*ar.shape, 3, 3))
    # Written out instead of three matmuls: it is the hot path of batched FK/IK conversions.
    r[..., 0, 0] = ca * cb
    r[..., 0, 1] = ca * sb * sc - sa * cc
    r[..., 0, 2] = ca * sb * cc + sa * sc
    r[..., 1, 0] = sa * cb
    r[..., 1, 1] = sa * sb * sc + ca * cc
    r[..., 1, 2] = sa * sb * cc - ca * sc
    r[..., 2, 0] = -sb
    r[..., 2, 1] = cb * sc
    r[..., 2, 2] = cb * cc
    return r


def abc_from_matrix(r: npt.ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """KUKA A, B, C (degrees) of rotation matrices ``(..., 3, 3)`` (or the top-left of 4×4).

    Returns three arrays of the leading shape (0-d arrays for a single matrix; ``float(a)``
    works), each angle in (-180°, 180°] (B in [-90°, 90°]). Near B = ±90° (``cos B < ABC_SINGULAR_COS``) A is 0 and C carries the rotation:
    ``C = atan2(r12, r22)`` for B = +90°, ``atan2(-r12, r22)`` for B = -90°.
    """
    m = np.asarray(r, dtype=np.float64)[..., :3, :3]
    r11, r21, r31 = m[..., 0, 0], m[..., 1, 0], m[..., 2, 0]
    cb = np.hypot(r11, r21)
    singular = cb < ABC_SINGULAR_COS
    b = np.arctan2(-r31, cb)
    a = np.where(singular, 0.0, np.arctan2(r21, r11))
    c_regular = np.arctan2(m[..., 2, 1], m[..., 2, 2])
    # At B = +90° R = [[0, sin(C-A), .], [0, cos(C-A), .], ...]; at -90° r12 = -sin(A+C).
    c_singular = np.where(
        r31 < 0.0, np.arctan2(m[..., 0, 1], m[..., 1, 1]), np.arctan2(-m[..., 0, 1], m[..., 1, 1])
    )
    c = np.where(singular, c_singular, c_regular)
    return _clean(np.degrees(a)), _clean(np.degrees(b)), _clean(np.degrees(c))


def _clean(deg: FloatArray) -> FloatArray:
    # Rounding noise (1e-15°) and -0.0 would print as "A -0.0" / "-1.2E-15" in KRC text.
    deg = np.where(np.abs(deg) < 1e-12, 0.0, deg) + 0.0
    # atan2 gives -180° for a -0.0 sine (a flange pointing straight down comes out as
    # A -180.0): fold it to +180 so every angle is in the documented (-180°, 180°].
    return np.where(deg <= -180.0, deg + 360.0, deg)


def frame_to_matrix(
    x: npt.ArrayLike,
    y: npt.ArrayLike,
    z: npt.ArrayLike,
    a: npt.ArrayLike,
    b: npt.ArrayLike,
    c: npt.ArrayLike,
) -> FloatArray:
    """Homogeneous transform ``(..., 4, 4)`` of a KUKA FRAME (mm, degrees)."""
    r = matrix_from_abc(a, b, c)
    xs, ys, zs = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x, y, z)))
    shape = np.broadcast_shapes(r.shape[:-2], xs.shape)
    t = np.zeros((*shape, 4, 4))
    t[..., :3, :3] = r
    t[..., 0, 3] = xs
    t[..., 1, 3] = ys
    t[..., 2, 3] = zs
    t[..., 3, 3] = 1.0
    return t


def pose_to_matrix(pose: npt.ArrayLike) -> FloatArray:
    """Homogeneous transform ``(..., 4, 4)`` of XYZABC vectors ``(..., 6)``."""
    p = np.asarray(pose, dtype=np.float64)
    if p.shape[-1:] != (6,):
        raise ValueError(f"a pose is X, Y, Z, A, B, C (last dimension 6), got shape {p.shape}")
    return frame_to_matrix(p[..., 0], p[..., 1], p[..., 2], p[..., 3], p[..., 4], p[..., 5])


def matrix_to_frame(t: npt.ArrayLike) -> FloatArray:
    """XYZABC ``(..., 6)`` (mm, degrees) of homogeneous transforms ``(..., 4, 4)``."""
    m = np.asarray(t, dtype=np.float64)
    a, b, c = abc_from_matrix(m)
    return np.stack([m[..., 0, 3], m[..., 1, 3], m[..., 2, 3], a, b, c], axis=-1)


def as_transform(frame: npt.ArrayLike | None) -> FloatArray | None:
    """Accept a 4×4 transform or an XYZABC 6-vector (each possibly batched); ``None`` stays."""
    if frame is None:
        return None
    f = np.asarray(frame, dtype=np.float64)
    if f.shape[-2:] == (4, 4):
        return f
    if f.shape[-1:] == (6,):
        return pose_to_matrix(f)
    raise ValueError(f"a frame is a 4x4 transform or X, Y, Z, A, B, C; got shape {f.shape}")


def inv_transform(t: npt.ArrayLike) -> FloatArray:
    """Inverse of rigid transforms ``(..., 4, 4)`` (Rᵀ, -Rᵀp), cheaper and exacter than inv."""
    m = np.asarray(t, dtype=np.float64)
    out = np.zeros_like(m)
    rt = np.swapaxes(m[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rt, m[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def rotation_angle_deg(r1: npt.ArrayLike, r2: npt.ArrayLike) -> FloatArray:
    """Angle (degrees) of the rotation between two orientations (…, 3, 3) or (…, 4, 4)."""
    m1 = np.asarray(r1, dtype=np.float64)[..., :3, :3]
    m2 = np.asarray(r2, dtype=np.float64)[..., :3, :3]
    d = np.swapaxes(m1, -1, -2) @ m2
    # Use the skew part and the trace together: arccos alone loses precision near 0.
    s = 0.5 * np.linalg.norm(
        np.stack(
            [d[..., 2, 1] - d[..., 1, 2], d[..., 0, 2] - d[..., 2, 0], d[..., 1, 0] - d[..., 0, 1]],
            axis=-1,
        ),
        axis=-1,
    )
    c = 0.5 * (np.trace(d, axis1=-2, axis2=-1) - 1.0)
    return np.asarray(np.degrees(np.arctan2(s, c)), dtype=np.float64)
