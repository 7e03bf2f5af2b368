"""Statics: gravity holding torques, payload ($LOAD), and τ = Jᵀ F (thesis eq. 4.5) both ways.

Sign convention (the reference found no source for KUKA's sign of ``$TORQUE_AXIS_ACT``): every
torque here is the torque the *drive* exerts about the positive KUKA axis to hold the arm,
multiplied by ``sign`` (default ``model.torque_sign``, +1). Gravity: ``τ_i = −u_i · Σ_{j≥i}
(c_j − p_i) × m_j·g`` with g = (0, 0, −9.81) m/s², so a negative τ2 at HOME lifts the arm.
Wrenches: F = [Fx, Fy, Fz (N), Mx, My, Mz (Nm)] is what the robot's TCP exerts *on the
environment*, expressed in ``$ROBROOT`` at the TCP; the drives then supply τ = Jᵀ F (eq. 4.5).
Both terms have the same sense, so ``gravity_torques(...) + wrench_to_torques(...)`` is the
total holding torque. Lengths are converted mm → m so torques are in Nm.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from ..krl import Struct
from .forward import link_frames
from .frames import FloatArray
from .jacobian import _damped_inverse_apply, scaled_jacobian
from .model import RobotModel

__all__ = ["GRAVITY", "Load", "gravity_torques", "torques_to_wrench", "wrench_to_torques"]

#: Standard gravity used by the reference table (m/s²).
GRAVITY = 9.81


@dataclass(frozen=True)
class Load:
    """A payload like KUKA's ``$LOAD``: mass M (kg) and centre of mass CM (mm, flange frame)."""

    mass_kg: float
    com_mm: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0))

    def __post_init__(self) -> None:
        if not self.mass_kg >= 0.0:
            raise ValueError(f"load mass must be >= 0 kg, got {self.mass_kg}")
        object.__setattr__(self, "com_mm", tuple(float(v) for v in self.com_mm))
        if len(self.com_mm) != 3:
            raise ValueError("load centre of mass is X, Y, Z in mm")

    @classmethod
    def from_krl(cls, value: object) -> Load | None:
        """A ``$LOAD`` value (``{LOAD: M .., CM {FRAME: X .., Y .., Z ..}, J ..}``) as a Load.

        None when it is not a struct or declares no mass (KUKA's "no load"); missing members
        count as 0, as on a controller where they were never set.
        """
        if not isinstance(value, Struct):
            return None
        mass = _number(value.get("M"))
        cm = value.get("CM")
        com = (0.0, 0.0, 0.0)
        if isinstance(cm, Struct):
            com = (_number(cm.get("X")), _number(cm.get("Y")), _number(cm.get("Z")))
        return cls(mass, com) if mass > 0.0 else None


def _number(value: object) -> float:
    return float(value) if isinstance(value, int | float) and not isinstance(value, bool) else 0.0


@lru_cache(maxsize=32)
def _com_local(model: RobotModel) -> FloatArray:
    """COM of each link in its own moving D-H frame (frame j+1 moves with link j), mm."""
    zero = link_frames(model, np.zeros(6))
    c0 = model.link_origin + model.link_com  # base frame, all-zero pose
    rot = zero[1:, :3, :3]
    org = zero[1:, :3, 3]
    local: FloatArray = np.asarray(np.einsum("jki,jk->ji", rot, c0 - org))  # Rᵀ (c0 - o)
    local.flags.writeable = False
    return local


def gravity_torques(
    model: RobotModel,
    q: npt.ArrayLike,
    load: Load | None = None,
    *,
    sign: float | None = None,
    g: float = GRAVITY,
) -> FloatArray:
    """Static holding torques (Nm, ``(..., 6)``) of the link masses plus an optional payload."""
    frames = link_frames(model, q)
    local = _com_local(model)
    com = frames[..., 1:, :3, 3] + np.einsum("...jik,jk->...ji", frames[..., 1:, :3, :3], local)
    masses = model.link_mass
    if load is not None and load.mass_kg > 0.0:
        flange = frames[..., 6, :, :] @ model.flange
        cl = flange[..., :3, 3] + flange[..., :3, :3] @ np.asarray(load.com_mm)
        com = np.concatenate([com, cl[..., None, :]], axis=-2)
        masses = np.append(masses, load.mass_kg)
    com_m = com / 1000.0
    force = np.zeros((len(masses), 3))
    force[:, 2] = -g * masses  # (n_bodies, 3), the same in every pose
    # Σ_{j≥i} (c_j − p_i) × F_j = Σ_{j≥i} c_j × F_j − p_i × Σ_{j≥i} F_j; reverse cumulative sums.
    moment = np.cross(com_m, force)
    tail_m = np.flip(np.cumsum(np.flip(moment, -2), axis=-2), -2)[..., :6, :]
    tail_f = np.flip(np.cumsum(np.flip(force, -2), axis=-2), -2)[:6]
    p = frames[..., :6, :3, 3] / 1000.0
    total = tail_m - np.cross(p, tail_f)
    u = frames[..., :6, :3, 2] * model.sign[:, None]
    s = model.torque_sign if sign is None else sign
    return np.asarray(-s * np.einsum("...ij,...ij->...i", u, total))


def wrench_to_torques(
    model: RobotModel,
    q: npt.ArrayLike,
    wrench: npt.ArrayLike,
    tool: npt.ArrayLike | None = None,
    *,
    sign: float | None = None,
) -> FloatArray:
    """τ = Jᵀ F (Nm, ``(..., 6)``) for F = [N, N, N, Nm, Nm, Nm] at the TCP in $ROBROOT."""
    j_si = scaled_jacobian(model, q, tool, 1000.0)  # linear rows in m/rad
    f = np.asarray(wrench, dtype=np.float64)
    s = model.torque_sign if sign is None else sign
    return np.asarray(s * np.einsum("...ji,...j->...i", j_si, f))


def torques_to_wrench(
    model: RobotModel,
    q: npt.ArrayLike,
    tau: npt.ArrayLike,
    damping: float = 0.05,
    *,
    threshold: float = 0.05,
    tool: npt.ArrayLike | None = None,
    sign: float | None = None,
) -> FloatArray:
    """The TCP wrench F (``(..., 6)``, N and Nm) with Jᵀ F = τ, in the least-squares sense.

    Away from singularities this inverts :func:`wrench_to_torques` exactly; near them the
    damping (SI-scaled Jacobian, see :mod:`.jacobian`) keeps F bounded where a joint torque
    says nothing about a force component.
    """
    j_si = scaled_jacobian(model, q, tool, 1000.0)
    s = model.torque_sign if sign is None else sign
    t = np.array(np.broadcast_to(np.asarray(tau, dtype=np.float64), (*j_si.shape[:-2], 6))) / s
    return _damped_inverse_apply(j_si, t, damping, threshold, transpose=True)
