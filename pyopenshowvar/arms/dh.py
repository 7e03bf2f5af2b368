"""Denavit-Hartenberg tables (standard and modified) as joint chains.

The thesis' architecture adds a manipulator "simply by defining its standard D-H table and
its joint limits"; its crane table (Table 3.3) is written in the modified (Craig) form. Both
become the chain of :mod:`.model` here:

* standard (distal): ``T_i = Rz(θ_i)·Tz(d_i)·Tx(a_i)·Rx(α_i)``: joint i moves about / along
  z of frame i-1, and the fixed rest ``Tz(d)·Tx(a)·Rx(α)`` goes into the next origin;
* modified (proximal): ``T_i = Rx(α_{i-1})·Tx(a_{i-1})·Rz(θ_i)·Tz(d_i)``: the link frame is
  the D-H frame itself.

A row's variable is ``θ = sign·q + theta`` (revolute) or ``d = sign·q + d`` (prismatic); a
``fixed`` row has no variable (the crane table's last row, the tip). Inertials written in
the D-H frame i of a standard table are moved into the chain's link frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..kinematics.frames import FloatArray
from .model import Inertial
from .spatial import rot_x, rot_z, trans

__all__ = ["DHRow", "dh_chain"]

Convention = Literal["standard", "modified"]


@dataclass(frozen=True)
class DHRow:
    """One table row: lengths in mm, angles in radians, ``type`` revolute/prismatic/fixed."""

    type: str
    a: float
    alpha: float
    d: float
    theta: float
    sign: float = 1.0


def _move_inertial(inertial: Inertial | None, t: FloatArray) -> Inertial | None:
    """An inertial given in frame B, expressed in frame A where ``t`` = A→B."""
    if inertial is None:
        return None
    com = t[:3, :3] @ inertial.com + t[:3, 3]
    rot = t[:3, :3]
    inertia = None if inertial.inertia is None else rot @ inertial.inertia @ rot.T
    return Inertial(inertial.mass, com, inertia)


def dh_chain(
    rows: list[DHRow],
    convention: Convention,
    inertials: list[Inertial | None] | None = None,
) -> tuple[list[tuple[FloatArray, FloatArray]], FloatArray, list[Inertial | None]]:
    """``(origin, axis)`` per moving row, the trailing fixed transform (to be followed by the
    file's flange), and the inertials moved into link frames (moving rows only)."""
    inertials = inertials or [None] * len(rows)
    pending = np.eye(4)
    out: list[tuple[FloatArray, FloatArray]] = []
    links: list[Inertial | None] = []
    for row, inertial in zip(rows, inertials, strict=True):
        axis = np.array([0.0, 0.0, row.sign])
        if convention == "modified":
            head = pending @ rot_x(row.alpha) @ trans(row.a, 0.0, 0.0)
            if row.type == "fixed":
                pending = head @ rot_z(row.theta) @ trans(0.0, 0.0, row.d)
                continue
            # Rz(θ) and Tz(d) commute, so the variable part can come last in either case
            out.append((head @ rot_z(row.theta) @ trans(0.0, 0.0, row.d), axis))
            links.append(inertial)
            pending = np.eye(4)
        else:
            tail = trans(0.0, 0.0, row.d) @ trans(row.a, 0.0, 0.0) @ rot_x(row.alpha)
            if row.type == "fixed":
                pending = pending @ rot_z(row.theta) @ tail
                continue
            if row.type == "revolute":
                out.append((pending @ rot_z(row.theta), axis))
                rest = tail
            else:
                out.append((pending @ rot_z(row.theta) @ trans(0.0, 0.0, row.d), axis))
                rest = trans(row.a, 0.0, 0.0) @ rot_x(row.alpha)
            links.append(_move_inertial(inertial, rest))
            pending = rest
    return out, pending, links
