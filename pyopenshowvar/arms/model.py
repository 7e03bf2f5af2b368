"""An arm as data: a serial chain of revolute and prismatic joints with limits and inertials.

Every source (a standard or modified D-H table, a URDF-like chain, a URDF file, the
kinematics package's :class:`~pyopenshowvar.kinematics.RobotModel`) becomes the same chain:

    T(q) = base · Π_i (origin_i · motion_i(q_i)) · flange

``origin_i`` is the fixed transform from the previous link frame to joint i's frame, and
``motion_i`` turns about (revolute) or slides along (prismatic) the joint's unit ``axis`` in
that frame; link i's frame is the joint frame after the motion (the URDF convention).
Units at the API are the toolkit's: millimetres and degrees (prismatic joints in mm,
speeds in deg/s or mm/s); inertials in kg, mm and kg·m². Unknown speeds, accelerations and
torques are NaN. All computations are batched over leading axes of ``q``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt

from ..kinematics.frames import FloatArray, as_transform, matrix_to_frame
from .ik import IKResult, solve

if TYPE_CHECKING:
    from ..kinematics.model import RobotModel

__all__ = ["Arm", "Inertial", "Joint", "JointType", "Source"]

JointType = Literal["revolute", "prismatic"]


def _ro(a: npt.ArrayLike, shape: tuple[int, ...], what: str) -> FloatArray:
    arr = np.array(a, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"{what}: expected shape {shape}, got {arr.shape}")
    arr.flags.writeable = False  # arms are shared (catalogue cache): no in-place edits
    return arr


@dataclass(frozen=True)
class Source:
    """Where an arm's numbers come from (shown by ``kvp arms show``)."""

    text: str = ""
    url: str = ""
    commit: str = ""
    licence: str = ""
    notes: str = ""


@dataclass(frozen=True, eq=False)
class Inertial:
    """Mass properties of one link: mass (kg), centre of mass (mm, link frame) and the
    inertia tensor about the centre of mass in link-frame axes (kg·m²; None if unknown)."""

    mass: float
    com: FloatArray = field(default_factory=lambda: np.zeros(3))
    inertia: FloatArray | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mass) and self.mass >= 0.0):
            raise ValueError(f"mass must be a finite number >= 0, got {self.mass}")
        object.__setattr__(self, "com", _ro(self.com, (3,), "com"))
        if self.inertia is not None:
            object.__setattr__(self, "inertia", _ro(self.inertia, (3, 3), "inertia"))


@dataclass(frozen=True, eq=False)
class Joint:
    """One joint: its fixed ``origin`` (4×4, mm) in the previous link frame, unit ``axis``
    in the joint frame, position limits (deg or mm) and optional dynamic limits (NaN if
    unknown): ``max_speed`` (deg/s, mm/s), ``max_accel`` (deg/s², mm/s²), ``max_effort``
    (Nm, N). ``inertial`` belongs to the link the joint moves."""

    name: str
    type: JointType
    origin: FloatArray
    axis: FloatArray
    lower: float
    upper: float
    max_speed: float = math.nan
    max_accel: float = math.nan
    max_effort: float = math.nan
    inertial: Inertial | None = None

    def __post_init__(self) -> None:
        if self.type not in ("revolute", "prismatic"):
            raise ValueError(f"joint {self.name}: type must be revolute or prismatic")
        object.__setattr__(self, "origin", _ro(self.origin, (4, 4), f"joint {self.name} origin"))
        axis = np.array(self.axis, dtype=np.float64).reshape(-1)
        norm = float(np.linalg.norm(axis)) if axis.shape == (3,) else 0.0
        if norm < 1e-9:
            raise ValueError(f"joint {self.name}: axis must be a non-zero 3-vector")
        object.__setattr__(self, "axis", _ro(axis / norm, (3,), f"joint {self.name} axis"))
        if not (math.isfinite(self.lower) and math.isfinite(self.upper)):
            raise ValueError(f"joint {self.name}: limits must be finite")
        if self.lower >= self.upper:
            raise ValueError(f"joint {self.name}: lower limit {self.lower} >= upper {self.upper}")
        for what in ("max_speed", "max_accel", "max_effort"):
            v = float(getattr(self, what))
            if not (math.isnan(v) or v > 0.0):
                raise ValueError(f"joint {self.name}: {what} must be > 0 (or unknown), got {v}")

    @property
    def revolute(self) -> bool:
        return self.type == "revolute"


@dataclass(frozen=True, eq=False)
class Arm:
    """A serial arm: joints from the base outwards, plus the fixed ``base`` and ``flange``
    transforms (4×4, mm). ``fk`` gives the flange frame (KUKA arms: the FLANGE / ``$TOOL``
    = ``$NULLFRAME`` frame) in the arm's base frame (KUKA: ``$ROBROOT``).

    ``kuka`` is the closed-form model (a :class:`~pyopenshowvar.kinematics.RobotModel`) for
    KUKA six-axis arms with a spherical wrist, None for other arms; ``model_name`` is what a
    KRC answers for ``$MODEL_NAME[]``.
    """

    name: str
    joints: tuple[Joint, ...]
    base: FloatArray = field(default_factory=lambda: np.eye(4))
    flange: FloatArray = field(default_factory=lambda: np.eye(4))
    home: FloatArray | None = None
    base_inertial: Inertial | None = None
    source: Source = field(default_factory=Source)
    key: str = ""
    family: str = ""
    model_name: str = ""
    kuka: RobotModel | None = None

    def __post_init__(self) -> None:
        if not self.joints:
            raise ValueError(f"{self.name}: an arm needs at least one joint")
        object.__setattr__(self, "joints", tuple(self.joints))
        object.__setattr__(self, "base", _ro(self.base, (4, 4), "base"))
        object.__setattr__(self, "flange", _ro(self.flange, (4, 4), "flange"))
        names = [j.name for j in self.joints]
        if len(set(names)) != len(names):
            raise ValueError(f"{self.name}: joint names must be unique, got {names}")
        home = self.mid if self.home is None else self.home
        object.__setattr__(self, "home", _ro(home, (self.dof,), "home"))
        # The chain as constant matrices: origin·motion(θ) = P + sinθ·Q + cosθ·R (revolute)
        # or P + d·Q (prismatic), so a batched FK is three array ops and a matmul per joint.
        n = self.dof
        p, q, r = np.zeros((n, 4, 4)), np.zeros((n, 4, 4)), np.zeros((n, 4, 4))
        for i, j in enumerate(self.joints):
            u = j.axis
            if j.revolute:
                a4, k4, c4 = np.zeros((4, 4)), np.zeros((4, 4)), np.zeros((4, 4))
                a4[:3, :3] = np.outer(u, u)
                a4[3, 3] = 1.0
                k4[:3, :3] = [[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]]
                c4[:3, :3] = np.eye(3) - np.outer(u, u)
                p[i], q[i], r[i] = j.origin @ a4, j.origin @ k4, j.origin @ c4
            else:
                s4 = np.zeros((4, 4))
                s4[:3, 3] = u
                p[i], q[i] = j.origin, j.origin @ s4
        object.__setattr__(self, "_pqr", (p, q, r))

    # ------------------------------------------------------------------------ descriptors
    @property
    def home_q(self) -> FloatArray:
        """The home configuration (always set: the mid-range pose unless the file names one)."""
        assert self.home is not None
        return self.home

    @property
    def dof(self) -> int:
        return len(self.joints)

    @cached_property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @cached_property
    def joint_types(self) -> tuple[JointType, ...]:
        return tuple(j.type for j in self.joints)

    @cached_property
    def revolute(self) -> npt.NDArray[np.bool_]:
        return np.array([j.revolute for j in self.joints])

    def _column(self, what: str) -> FloatArray:
        return _ro([float(getattr(j, what)) for j in self.joints], (self.dof,), what)

    @cached_property
    def lower(self) -> FloatArray:
        """Lower position limits (deg / mm)."""
        return self._column("lower")

    @cached_property
    def upper(self) -> FloatArray:
        """Upper position limits (deg / mm)."""
        return self._column("upper")

    @cached_property
    def max_speed(self) -> FloatArray:
        """Max joint speeds (deg/s / mm/s; NaN unknown)."""
        return self._column("max_speed")

    @cached_property
    def max_accel(self) -> FloatArray:
        """Max joint accelerations (deg/s² / mm/s²; NaN unknown)."""
        return self._column("max_accel")

    @cached_property
    def max_effort(self) -> FloatArray:
        """Max joint torques / forces (Nm / N; NaN unknown)."""
        return self._column("max_effort")

    @cached_property
    def mid(self) -> FloatArray:
        """The mid-range pose (the IK benchmark's seed)."""
        return _ro(
            [(j.lower + j.upper) / 2.0 for j in self.joints], (len(self.joints),), "mid-range"
        )

    @property
    def inertials(self) -> tuple[Inertial | None, ...]:
        """Inertials of the moving links (one per joint; None where unknown)."""
        return tuple(j.inertial for j in self.joints)

    def within_limits(self, q: npt.ArrayLike, tol: float = 1e-9) -> npt.NDArray[np.bool_]:
        """Per configuration (leading shape): True when every joint is inside its limits."""
        qa = self._q(q)
        return np.asarray(np.all((qa >= self.lower - tol) & (qa <= self.upper + tol), axis=-1))

    # ----------------------------------------------------------------------- kinematics
    def _q(self, q: npt.ArrayLike) -> FloatArray:
        qa = np.asarray(q, dtype=np.float64)
        if qa.shape[-1:] != (self.dof,):
            raise ValueError(
                f"{self.name} has {self.dof} joints; configurations need a last dimension of "
                f"{self.dof}, got shape {qa.shape}"
            )
        return qa

    def link_frames(self, q: npt.ArrayLike) -> FloatArray:
        """Link frames 1..n in the base frame: shape ``(..., n, 4, 4)`` (mm)."""
        qa = self._q(q)
        lead = qa.shape[:-1]
        flat = qa.reshape(-1, self.dof)
        frames = self._frames(flat)
        return frames.reshape(*lead, self.dof, 4, 4)

    def _frames(self, flat: FloatArray) -> FloatArray:
        """Link frames of flat configurations ``(N, n)`` in API units: ``(N, n, 4, 4)``."""
        rad = np.radians(flat)
        rev = self.revolute
        if self._all_revolute:
            return self._chain(np.sin(rad), np.cos(rad))
        return self._chain(np.where(rev, np.sin(rad), flat), np.where(rev, np.cos(rad), 0.0))

    @cached_property
    def _all_revolute(self) -> bool:
        return bool(np.all(self.revolute))

    def _chain(self, a: FloatArray, b: FloatArray) -> FloatArray:
        """Frames from per-joint ``a`` = sin θ or the displacement (mm) and ``b`` = cos θ or 0.

        All joint steps are built at once (few numpy calls matter more than flops here);
        only the product along the chain is sequential.
        """
        p, qm, r = self._pqr  # type: ignore[attr-defined]
        out = p + a[..., None, None] * qm + b[..., None, None] * r
        if not self._base_identity:
            out[:, 0] = self.base @ out[:, 0]
        for i in range(1, self.dof):
            np.matmul(out[:, i - 1], out[:, i], out=out[:, i])
        return np.asarray(out)

    @cached_property
    def _base_identity(self) -> bool:
        return bool(np.array_equal(self.base, np.eye(4)))

    def fk(self, q: npt.ArrayLike, tool: npt.ArrayLike | None = None) -> FloatArray:
        """Flange (or ``tool``) frame in the base frame: ``(..., 4, 4)`` in mm.

        ``tool`` is a 4×4 or XYZABC transform from the flange to a TCP (KUKA's ``$TOOL``).
        """
        qa = self._q(q)
        lead = qa.shape[:-1]
        t = self._frames(qa.reshape(-1, self.dof))[:, -1] @ self.flange
        tool_m = as_transform(tool)
        if tool_m is not None:
            t = t @ tool_m
        return t.reshape(*lead, 4, 4)

    def fk_pose(self, q: npt.ArrayLike, tool: npt.ArrayLike | None = None) -> FloatArray:
        """Flange (or tool) pose as KUKA X, Y, Z, A, B, C (mm, degrees): ``(..., 6)``."""
        return matrix_to_frame(self.fk(q, tool))

    def jacobian(self, q: npt.ArrayLike, tool: npt.ArrayLike | None = None) -> FloatArray:
        """Geometric Jacobian of the flange (or tool) point in the base frame: ``(..., 6, n)``.

        Rows ``[vx, vy, vz]`` (mm) and ``[ωx, ωy, ωz]`` (rad); columns per joint, per
        **radian** for revolute and per **mm** for prismatic joints (the kinematics package
        uses the same units), so ``J @ dq`` with dq in rad / mm is the flange twist.
        """
        qa = self._q(q)
        lead = qa.shape[:-1]
        frames = self._frames(qa.reshape(-1, self.dof))
        tcp = frames[:, -1] @ self.flange
        tool_m = as_transform(tool)
        if tool_m is not None:
            tcp = tcp @ tool_m
        j = self._jacobian(frames, tcp[:, :3, 3])
        return j.reshape(*lead, 6, self.dof)

    @cached_property
    def _axes(self) -> FloatArray:
        return np.stack([j.axis for j in self.joints])

    @cached_property
    def _basis_axes(self) -> tuple[npt.NDArray[np.intp], FloatArray] | None:
        """(column, sign) per joint when every axis is ±x, ±y or ±z (D-H tables, most URDFs)."""
        k = np.argmax(np.abs(self._axes), axis=1)
        sign = self._axes[np.arange(self.dof), k]
        return (k, sign) if np.all(np.abs(sign) == 1.0) else None

    def _world_axes(self, frames: FloatArray) -> FloatArray:
        """Joint axes in the base frame for flat frames ``(N, n, 4, 4)``: ``(N, n, 3)``."""
        if self._basis_axes is not None:
            k, sign = self._basis_axes
            cols = np.swapaxes(frames[..., :3, :3], -1, -2)  # adjacent advanced indices below
            return np.asarray(cols[:, np.arange(self.dof), k, :] * sign[:, None])
        return np.asarray((frames[..., :3, :3] @ self._axes[:, :, None])[..., 0])

    def _jacobian(self, frames: FloatArray, point: FloatArray) -> FloatArray:
        """Jacobian of flat frames ``(N, n, 4, 4)`` at points ``(N, 3)``: ``(N, 6, n)``."""
        w = self._world_axes(frames)
        lin = np.cross(w, point[:, None, :] - frames[..., :3, 3])
        rev = self.revolute
        j = np.empty((frames.shape[0], 6, self.dof))
        j[:, :3] = np.swapaxes(np.where(rev[None, :, None], lin, w), 1, 2)
        j[:, 3:] = np.swapaxes(np.where(rev[None, :, None], w, 0.0), 1, 2)
        return j

    # ------------------------------------------------------------------------------- IK
    def ik(
        self,
        target: npt.ArrayLike,
        seed: npt.ArrayLike | None = None,
        *,
        errors: Literal["raise", "nan"] = "raise",
        **options: Any,
    ) -> FloatArray:
        """Joint values reaching ``target``: a 4×4 pose, XYZABC ``(…, 6)`` or a position XYZ
        ``(…, 3)`` (position-only IK), each possibly batched; returns ``(…, dof)``.

        ``options`` are those of :func:`pyopenshowvar.arms.ik.solve` (``preferred``, ``tool``,
        ``method``, ``tol``, ``timeout``, ``rng``, ...). An unsolved target raises
        :class:`~pyopenshowvar.kinematics.UnreachableError` (``errors="nan"``: NaN rows).
        """
        return solve(self, target, seed, **options).value(errors)

    def solve_ik(
        self, target: npt.ArrayLike, seed: npt.ArrayLike | None = None, **kw: Any
    ) -> IKResult:
        """Like :meth:`ik`, returning the full :class:`~pyopenshowvar.arms.ik.IKResult`."""
        return solve(self, target, seed, **kw)

    # ------------------------------------------------------------------------- display
    def describe(self) -> dict[str, Any]:
        """Plain data for ``kvp arms show`` / JSON (units mm, deg)."""

        def num(v: float) -> float | None:
            return None if math.isnan(v) else round(float(v), 9)

        return {
            "key": self.key,
            "name": self.name,
            "family": self.family,
            "dof": self.dof,
            "model_name": self.model_name,
            "closed_form_ik": self.kuka is not None,
            "home": [float(v) for v in self.home],  # type: ignore[union-attr]
            "flange_at_home": [round(float(v), 6) for v in self.fk_pose(self.home_q)],
            "joints": [
                {
                    "name": j.name,
                    "type": j.type,
                    "lower": num(j.lower),
                    "upper": num(j.upper),
                    "max_speed": num(j.max_speed),
                    "max_accel": num(j.max_accel),
                    "max_effort": num(j.max_effort),
                    "mass": None if j.inertial is None else j.inertial.mass,
                }
                for j in self.joints
            ],
            "source": {
                "text": self.source.text,
                "url": self.source.url,
                "commit": self.source.commit,
                "licence": self.source.licence,
                "notes": self.source.notes,
            },
        }
