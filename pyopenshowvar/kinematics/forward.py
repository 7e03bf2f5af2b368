"""Forward kinematics (thesis eq. 4.12) and KUKA status/turn bits, batched with numpy.

``fk_matrix`` returns what a KRC reports as ``$POS_ACT`` with ``$ROBROOT`` = world:
the ``$TOOL`` TCP in ``$BASE``, i.e. ``inv(BASE) · FLANGE(q) · TOOL``, where
``FLANGE(q) = Π_i T_i(θ_i) · model.flange`` and ``θ_i = sign_i·q_i + offset_i``.
Axis vectors are KUKA A1..A6 in degrees, shape ``(..., 6)``; results keep the leading shape.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from .frames import FloatArray, as_transform, inv_transform, matrix_to_frame
from .model import RobotModel

__all__ = [
    "IntArray",
    "dh_transforms",
    "fk_matrix",
    "forward",
    "link_frames",
    "status_bits",
    "status_turn",
    "turn_bits",
]

IntArray = npt.NDArray[np.int64]


def _axes(q: npt.ArrayLike) -> FloatArray:
    qa = np.asarray(q, dtype=np.float64)
    if qa.shape[-1:] != (6,):
        raise ValueError(f"axis vectors are A1..A6 (last dimension 6), got shape {qa.shape}")
    return qa


def dh_transforms(model: RobotModel, q: npt.ArrayLike) -> FloatArray:
    """The six D-H link transforms ``T_i = Rz(θ)·Tz(d)·Tx(a)·Rx(α)``: shape ``(..., 6, 4, 4)``."""
    qa = _axes(q)
    theta = np.radians(model.sign * qa + model.offset)
    ct, st = np.cos(theta), np.sin(theta)
    alpha = np.radians(model.alpha)
    ca, sa = np.cos(alpha), np.sin(alpha)
    # cos(±90°) is 6e-17, not 0; rounding it keeps the all-zero pose exactly on the table values.
    ca = np.where(np.abs(ca) < 1e-15, 0.0, ca)
    sa = np.where(np.abs(sa) < 1e-15, 0.0, sa)
    t = np.zeros((*qa.shape[:-1], 6, 4, 4))
    t[..., 0, 0] = ct
    t[..., 0, 1] = -st * ca
    t[..., 0, 2] = st * sa
    t[..., 0, 3] = model.a * ct
    t[..., 1, 0] = st
    t[..., 1, 1] = ct * ca
    t[..., 1, 2] = -ct * sa
    t[..., 1, 3] = model.a * st
    t[..., 2, 1] = sa
    t[..., 2, 2] = ca
    t[..., 2, 3] = model.d
    t[..., 3, 3] = 1.0
    return t


def link_frames(model: RobotModel, q: npt.ArrayLike) -> FloatArray:
    """D-H frames 0..6 in ``$ROBROOT``: shape ``(..., 7, 4, 4)``; frame 0 is the identity.

    Frame i-1 carries axis i (its z axis; KUKA's positive direction is ``sign_i·z_{i-1}``).
    Frame 6 is the last D-H frame; the KUKA flange is ``frames[..., 6, :, :] @ model.flange``.
    """
    t = dh_transforms(model, q)
    frames = np.empty((*t.shape[:-3], 7, 4, 4))
    frames[..., 0, :, :] = np.eye(4)
    acc = t[..., 0, :, :]
    frames[..., 1, :, :] = acc
    for i in range(1, 6):
        acc = acc @ t[..., i, :, :]
        frames[..., i + 1, :, :] = acc
    return frames


def _flange(model: RobotModel, q: npt.ArrayLike) -> FloatArray:
    t = dh_transforms(model, q)
    acc = t[..., 0, :, :]
    for i in range(1, 6):
        acc = acc @ t[..., i, :, :]
    if not np.array_equal(model.flange, np.eye(4)):
        acc = acc @ model.flange
    return acc


def fk_matrix(
    model: RobotModel,
    q: npt.ArrayLike,
    tool: npt.ArrayLike | None = None,
    base: npt.ArrayLike | None = None,
) -> FloatArray:
    """TCP pose ``inv(BASE) · FLANGE(q) · TOOL`` as ``(..., 4, 4)`` (mm).

    ``tool`` ($TOOL, TCP in the flange frame) and ``base`` ($BASE, in ``$ROBROOT``) are 4×4
    transforms or XYZABC vectors; ``None`` means ``$NULLFRAME``. Either may be batched.
    """
    t = _flange(model, q)
    tool_m = as_transform(tool)
    if tool_m is not None:
        t = t @ tool_m
    base_m = as_transform(base)
    if base_m is not None:
        t = inv_transform(base_m) @ t
    return t


def forward(
    model: RobotModel,
    q: npt.ArrayLike,
    tool: npt.ArrayLike | None = None,
    base: npt.ArrayLike | None = None,
) -> FloatArray:
    """TCP pose as KUKA ``X, Y, Z, A, B, C`` (mm, degrees), shape ``(..., 6)``."""
    return matrix_to_frame(fk_matrix(model, q, tool, base))


def turn_bits(q: npt.ArrayLike) -> IntArray:
    """KUKA T: bit i-1 set when Ai < 0 strictly (even -4e-6° sets it, reference §2.1)."""
    qa = _axes(q)
    weights = np.array([1, 2, 4, 8, 16, 32], dtype=np.int64)
    return np.asarray(np.sum((qa < 0.0) * weights, axis=-1), dtype=np.int64)


def status_bits(model: RobotModel, q: npt.ArrayLike) -> IntArray:
    """KUKA S (bits 0..2) of axis vectors, by the rules of reference §2.1.

    * bit 0: wrist centre behind axis 1 (x < 0 in the A1 frame: the overhead area);
    * bit 1: A3 ≥ ``model.status_phi`` (4.76° for the KR 6);
    * bit 2: A5 < 0, more exactly A5 ∈ [-180°, 0°) or A5 ≥ 180°.
    """
    qa = _axes(q)
    frames = link_frames(model, qa)
    # Spherical wrist: axes 4, 5, 6 meet at the origin of D-H frame 5 (= frame 4 here).
    wrist = frames[..., 5, :3, 3] - frames[..., 0, :3, 3]
    x_a1 = np.einsum("...i,...i->...", wrist, frames[..., 1, :3, 0])
    bit0 = x_a1 < 0.0
    bit1 = qa[..., 2] >= model.status_phi
    a5 = qa[..., 4]
    bit2 = ((a5 < 0.0) & (a5 >= -180.0)) | (a5 >= 180.0)
    return np.asarray(bit0 * 1 + bit1 * 2 + bit2 * 4, dtype=np.int64)


def status_turn(model: RobotModel, q: npt.ArrayLike) -> tuple[int | IntArray, int | IntArray]:
    """KUKA ``(S, T)``: Python ints for one axis vector, int arrays for a batch."""
    qa = _axes(q)
    s, t = status_bits(model, qa), turn_bits(qa)
    if qa.ndim == 1:
        return int(s), int(t)
    return s, t
