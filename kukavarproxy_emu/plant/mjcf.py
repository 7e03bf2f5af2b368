"""The MuJoCo model (MJCF) of the physical robot, generated from :class:`~.params.Bodies`.

One body per link, chained exactly as the standard D-H table: link j's body frame is the
D-H frame j-1, whose z axis is joint j's axis, so the child body sits at
``Rz(offset_j)·Tz(d_j)·Tx(a_j)·Rx(α_j)`` in its parent and the hinge axis is ``(0, 0, sign_j)``.
With that axis MuJoCo's joint angle *is* the KUKA axis angle and a joint torque is the drive
torque about the positive KUKA axis, the convention of ``$TORQUE_AXIS_ACT``.

A payload ($LOAD) is a rigid body welded to link 6 at the load's CM frame. Friction and the
servo are applied by :mod:`.dynamic` as generalised forces, so the MJCF has no joint damping:
with the semi-implicit Euler integrator, M(q)·q̈ = τ_applied − bias(q, q̇) holds exactly in
every step, which the tests check against an independent rigid-body computation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pyopenshowvar.krl import Struct

from .frames import FloatArray, dh_matrix, frame_matrix
from .params import Bodies

__all__ = ["GRAVITY", "Payload", "build_mjcf", "payload_of"]

#: Standard gravity, m/s².
GRAVITY = 9.81
#: Smallest inertia moment given to a payload body (a point mass has none; MuJoCo needs > 0).
_MIN_INERTIA = 1e-9


@dataclass(frozen=True)
class Payload:
    """A $LOAD: mass M (kg), CM frame X Y Z A B C (mm, deg, flange frame), J (kg·m², principal
    moments about the CM frame's axes)."""

    mass: float
    cm: tuple[float, float, float, float, float, float] = (0.0,) * 6
    inertia: tuple[float, float, float] = (0.0, 0.0, 0.0)


def _num(value: object) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    return float(value) if ok and math.isfinite(float(value)) else 0.0  # type: ignore[arg-type]


def payload_of(value: object) -> Payload | None:
    """The payload of a ``$LOAD`` value; None for no load (M <= 0, or not a LOAD struct).
    Missing members count as 0, as on a controller where they were never set."""
    if not isinstance(value, Struct):
        return None
    mass = _num(value.get("M"))
    if mass <= 0.0:
        return None
    cm, j = value.get("CM"), value.get("J")
    frame = tuple(_num(cm.get(k)) for k in "XYZABC") if isinstance(cm, Struct) else (0.0,) * 6
    moments = (
        tuple(max(_num(j.get(k)), 0.0) for k in "XYZ") if isinstance(j, Struct) else (0.0,) * 3
    )
    return Payload(mass, frame, moments)  # type: ignore[arg-type]


def _quat(rot: FloatArray) -> str:
    """Unit quaternion (w x y z) of a rotation matrix (Shepperd's method)."""
    m = rot
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = (0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = ((m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s)
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = ((m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s)
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = ((m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s)
    return " ".join(repr(float(v)) for v in q)


def _vec(v: FloatArray | tuple[float, ...], scale: float = 1.0) -> str:
    return " ".join(repr(float(x) * scale) for x in v)


def _pose(t: FloatArray) -> str:
    """``pos`` (m) and ``quat`` attributes of a 4×4 transform in mm."""
    return f'pos="{_vec(t[:3, 3], 1e-3)}" quat="{_quat(t[:3, :3])}"'


def _full_inertia(moments: FloatArray, axes: FloatArray) -> str:
    """MJCF ``fullinertia`` (ixx iyy izz ixy ixz iyz) of principal ``moments`` about ``axes``."""
    i = axes @ np.diag(moments) @ axes.T
    return _vec((i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]))


def build_mjcf(
    bodies: Bodies,
    *,
    timestep: float,
    payload: Payload | None = None,
    tool: FloatArray | None = None,
) -> str:
    """The MJCF text of the physical robot (plus ``payload``; site ``tcp`` at ``tool``)."""
    armature = bodies.armature
    lines = [
        '<mujoco model="robot">',
        # balanceinertia: a $LOAD inertia J that no rigid body can have is made physical
        '  <compiler angle="radian" balanceinertia="true"/>',
        f'  <option timestep="{timestep!r}" integrator="Euler" gravity="0 0 {-GRAVITY!r}">',
        # autoreset off: a blown-up state must reach the plant's own guard, not jump to q = 0
        '    <flag contact="disable" constraint="disable" autoreset="disable"/>',
        "  </option>",
        "  <worldbody>",
    ]
    parent = np.eye(4)
    for j in range(6):
        pad = "  " * (j + 2)
        lines.append(f'{pad}<body name="link{j + 1}" {_pose(parent)}>')
        lines.append(
            f'{pad}  <joint name="A{j + 1}" type="hinge" axis="0 0 {float(bodies.sign[j])!r}"'
            f' armature="{float(armature[j])!r}"/>'
        )
        lines.append(
            f'{pad}  <inertial pos="{_vec(bodies.com[j], 1e-3)}" mass="{float(bodies.mass[j])!r}"'
            f' fullinertia="{_full_inertia(bodies.inertia[j], bodies.inertia_axes[j])}"/>'
        )
        parent = dh_matrix(bodies.a[j], bodies.alpha[j], bodies.d[j], bodies.offset[j])
    pad = "  " * 8
    flange = parent @ bodies.flange  # in link 6's body frame
    tcp = flange @ tool if tool is not None else flange
    lines.append(f'{pad}<site name="flange" {_pose(flange)}/>')
    lines.append(f'{pad}<site name="tcp" {_pose(tcp)}/>')
    if payload is not None and payload.mass > 0.0:
        inertia = " ".join(repr(max(float(v), _MIN_INERTIA)) for v in payload.inertia)
        lines.append(f'{pad}<body name="payload" {_pose(flange @ frame_matrix(payload.cm))}>')
        lines.append(
            f'{pad}  <inertial pos="0 0 0" mass="{float(payload.mass)!r}" diaginertia="{inertia}"/>'
        )
        lines.append(f"{pad}</body>")
    for j in reversed(range(6)):
        lines.append("  " * (j + 2) + "</body>")
    lines += ["  </worldbody>", "</mujoco>"]
    return "\n".join(lines)
