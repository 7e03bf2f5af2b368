"""Robot models: a serial 6R arm as data (D-H table, KUKA axis mapping, limits, masses).

The thesis architecture defines a robot by its D-H table and joints, with interchangeable
solvers on top; :class:`RobotModel` is that definition. The KR 6 R900 sixx is built in
(:data:`KR6R900SIXX`: KUKA's link lengths and KR AGILUS sixx limits and speeds from the public
URDFs of kroshu/kuka_robot_descriptions and ros-industrial/kuka_experimental, masses from KUKA's
KR 6 R900-2 URDF); any other
arm is loaded from TOML or JSON with :meth:`RobotModel.from_file` (schema in docs/kinematics.md).

Conventions (all at the API: millimetres, degrees, kilograms):

* Standard (distal) D-H, ``T_i = Rz(θ_i)·Tz(d_i)·Tx(a_i)·Rx(α_i)``, and the KUKA axis angle
  ``q_i`` maps to ``θ_i = sign_i·q_i + offset_i``. Frame 0 is ``$ROBROOT``.
* ``flange`` is the fixed transform from the last D-H frame to the KUKA FLANGE frame (identity
  for the KR 6, whose θ6 offset of 180° already lines the frames up).
* The mass model follows reference §3.3: link *j* has mass ``link_mass[j]`` and its centre of
  mass sits at ``link_origin[j] + link_com[j]`` (base frame, all-zero pose) and moves with the
  link. ``link_origin`` is only a bookkeeping point (the joint origin in the reference table);
  give zeros and absolute COMs if that is easier.
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .frames import FloatArray, as_transform, matrix_to_frame

__all__ = ["KR6R900SIXX", "RobotModel"]

_AXES = ("A1", "A2", "A3", "A4", "A5", "A6")


def _vec(value: npt.ArrayLike, shape: tuple[int, ...], what: str) -> FloatArray:
    arr = np.array(value, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"{what}: expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: values must be finite")
    # Read-only so a model shared by the emulator and a client cannot be altered in place.
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class RobotModel:
    """A serial 6R arm; arrays are read-only numpy arrays (lists are accepted and converted).

    ``dh`` rows are ``(a mm, alpha deg, d mm, theta_offset deg, sign ±1)`` for axes 1..6.
    """

    name: str
    dh: FloatArray
    lower: FloatArray
    upper: FloatArray
    max_speed: FloatArray
    max_accel: FloatArray
    link_mass: FloatArray = field(default_factory=lambda: np.zeros(6))
    link_com: FloatArray = field(default_factory=lambda: np.zeros((6, 3)))
    link_origin: FloatArray = field(default_factory=lambda: np.zeros((6, 3)))
    flange: FloatArray = field(default_factory=lambda: np.eye(4))
    home: FloatArray = field(default_factory=lambda: np.zeros(6))
    max_torque: FloatArray = field(default_factory=lambda: np.full(6, np.inf))
    #: Sign applied to every torque this package reports (KUKA's own sign is unsourced).
    torque_sign: float = 1.0

    def __post_init__(self) -> None:
        # frozen=True forbids normal assignment; converting inputs here is the documented escape.
        conv = object.__setattr__
        conv(self, "dh", _vec(self.dh, (6, 5), "dh"))
        for name in ("lower", "upper", "max_speed", "max_accel", "link_mass", "home"):
            conv(self, name, _vec(getattr(self, name), (6,), name))
        mt = np.array(self.max_torque, dtype=np.float64)
        if mt.shape != (6,):
            raise ValueError(f"max_torque: expected shape (6,), got {mt.shape}")
        mt.flags.writeable = False
        conv(self, "max_torque", mt)
        conv(self, "link_com", _vec(self.link_com, (6, 3), "link_com"))
        conv(self, "link_origin", _vec(self.link_origin, (6, 3), "link_origin"))
        fl = as_transform(self.flange)
        conv(self, "flange", _vec(fl if fl is not None else np.eye(4), (4, 4), "flange"))
        conv(self, "torque_sign", float(self.torque_sign))
        if not np.all(np.isin(self.dh[:, 4], (-1.0, 1.0))):
            raise ValueError("dh: the sign column must be +1 or -1")
        if np.any(self.lower >= self.upper):
            bad = [_AXES[i] for i in np.flatnonzero(self.lower >= self.upper)]
            raise ValueError(f"lower limit must be below upper limit ({', '.join(bad)})")
        if np.any(self.max_speed <= 0) or np.any(self.max_accel <= 0):
            raise ValueError("max_speed and max_accel must be positive")
        if np.any(self.link_mass < 0):
            raise ValueError("link_mass must not be negative")

    # Equality compares values: two models loaded from the same file are the same robot.
    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RobotModel):
            return NotImplemented
        return (
            self.name == other.name
            and self.torque_sign == other.torque_sign
            and all(
                np.array_equal(getattr(self, f), getattr(other, f))
                for f in (
                    "dh",
                    "lower",
                    "upper",
                    "max_speed",
                    "max_accel",
                    "link_mass",
                    "link_com",
                    "link_origin",
                    "flange",
                    "home",
                    "max_torque",
                )
            )
        )

    def __hash__(self) -> int:
        return hash((self.name, self.dh.tobytes(), self.lower.tobytes(), self.upper.tobytes()))

    # ----------------------------------------------------------------------------- D-H views
    @property
    def a(self) -> FloatArray:
        """D-H link lengths a_i (mm)."""
        return self.dh[:, 0]

    @property
    def alpha(self) -> FloatArray:
        """D-H twists α_i (degrees)."""
        return self.dh[:, 1]

    @property
    def d(self) -> FloatArray:
        """D-H offsets d_i (mm)."""
        return self.dh[:, 2]

    @property
    def offset(self) -> FloatArray:
        """θ offsets (degrees): θ_i = sign_i·q_i + offset_i."""
        return self.dh[:, 3]

    @property
    def sign(self) -> FloatArray:
        """Axis signs (±1): θ_i = sign_i·q_i + offset_i."""
        return self.dh[:, 4]

    @cached_property
    def status_phi(self) -> float:
        """A3 angle (deg) where the wrist centre lies on the line A2→A3 (S bit 1 threshold).

        The wrist centre seen from axis 3 is at angle θ3 + atan2(-sin α3·d4, a3) in the arm
        plane; it lines up with A2→A3 (frame 2's x axis) when that angle is 0. For the KR 6
        this gives atan(35/420) = 4.76°.
        """
        psi = math.atan2(-math.sin(math.radians(self.alpha[2])) * self.d[3], self.a[2])
        theta3 = -math.degrees(psi)
        return float((theta3 - self.offset[2]) / self.sign[2])

    @cached_property
    def reach(self) -> float:
        """Upper bound of the distance from axis 2 to the wrist centre (mm)."""
        return float(abs(self.a[1]) + math.hypot(self.a[2], self.d[3]))

    # --------------------------------------------------------------------------- limits
    def limit_mask(self, q: npt.ArrayLike, tol: float = 1e-9) -> npt.NDArray[np.bool_]:
        """Per pose (leading shape) True when every axis is inside [lower, upper] (± tol deg)."""
        qa = np.asarray(q, dtype=np.float64)
        ok = (qa >= self.lower - tol) & (qa <= self.upper + tol)
        return np.asarray(np.all(ok, axis=-1))

    def within_limits(self, q: npt.ArrayLike, tol: float = 1e-9) -> bool:
        """True when the axis vector (or every vector of a batch) is inside the limits."""
        return bool(np.all(self.limit_mask(q, tol)))

    def limit_violations(self, q: npt.ArrayLike, tol: float = 1e-9) -> list[str]:
        """Human-readable violations of one axis vector, e.g. ``"A2 -195 < -190"``; [] if none."""
        qa = np.asarray(q, dtype=np.float64).reshape(6)
        out: list[str] = []
        for i in range(6):
            if qa[i] < self.lower[i] - tol:
                out.append(f"{_AXES[i]} {qa[i]:.6g} < {self.lower[i]:.6g}")
            elif qa[i] > self.upper[i] + tol:
                out.append(f"{_AXES[i]} {qa[i]:.6g} > {self.upper[i]:.6g}")
        return out

    # ---------------------------------------------------------------------- serialisation
    def to_dict(self) -> dict[str, Any]:
        """Plain data in the file schema (one table per axis), ready for JSON."""
        axes = []
        for i in range(6):
            ax: dict[str, Any] = {
                "name": _AXES[i],
                "a": float(self.a[i]),
                "alpha": float(self.alpha[i]),
                "d": float(self.d[i]),
                "theta": float(self.offset[i]),
                "sign": int(self.sign[i]),
                "lower": float(self.lower[i]),
                "upper": float(self.upper[i]),
                "max_speed": float(self.max_speed[i]),
                "max_accel": float(self.max_accel[i]),
                "mass": float(self.link_mass[i]),
                "com": [float(v) for v in self.link_com[i]],
                "origin": [float(v) for v in self.link_origin[i]],
                "home": float(self.home[i]),
            }
            if math.isfinite(self.max_torque[i]):
                ax["max_torque"] = float(self.max_torque[i])
            axes.append(ax)
        return {
            "name": self.name,
            "torque_sign": self.torque_sign,
            "flange": [float(v) for v in matrix_to_frame(self.flange)],
            "axis": axes,
        }

    def to_json(self) -> str:
        """The model as JSON text (loadable with :meth:`from_file`)."""
        return json.dumps(self.to_dict(), indent=2)

    def to_toml(self) -> str:
        """The model as TOML text (loadable with :meth:`from_file`); repr() keeps floats exact."""

        def val(v: Any) -> str:
            if isinstance(v, str):
                return json.dumps(v)  # a JSON string is a valid TOML basic string
            if isinstance(v, list):
                return "[" + ", ".join(val(x) for x in v) + "]"
            return repr(v)

        d = self.to_dict()
        lines = [f"{k} = {val(d[k])}" for k in ("name", "torque_sign", "flange")]
        for ax in d["axis"]:
            lines += ["", "[[axis]]"] + [f"{k} = {val(v)}" for k, v in ax.items()]
        return "\n".join(lines) + "\n"

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RobotModel:
        """Build a model from the file schema (see docs/kinematics.md)."""
        axes = data.get("axis")
        if not isinstance(axes, list) or len(axes) != 6:
            raise ValueError("a model needs exactly 6 [[axis]] tables")

        def col(key: str, default: Any = None) -> list[Any]:
            out = []
            for i, ax in enumerate(axes):
                if key not in ax:
                    if default is None:
                        raise ValueError(f"axis {i + 1}: missing {key!r}")
                    out.append(default)
                else:
                    out.append(ax[key])
            return out

        dh = np.column_stack(
            [col("a"), col("alpha"), col("d"), col("theta", 0.0), col("sign", 1.0)]
        ).astype(np.float64)
        flange = data.get("flange", [0.0] * 6)
        return cls(
            name=str(data.get("name", "robot")),
            dh=dh,
            lower=np.array(col("lower"), dtype=np.float64),
            upper=np.array(col("upper"), dtype=np.float64),
            max_speed=np.array(col("max_speed"), dtype=np.float64),
            max_accel=np.array(col("max_accel"), dtype=np.float64),
            link_mass=np.array(col("mass", 0.0), dtype=np.float64),
            link_com=np.array(col("com", [0.0, 0.0, 0.0]), dtype=np.float64),
            link_origin=np.array(col("origin", [0.0, 0.0, 0.0]), dtype=np.float64),
            flange=np.array(flange, dtype=np.float64),
            home=np.array(col("home", 0.0), dtype=np.float64),
            max_torque=np.array(col("max_torque", math.inf), dtype=np.float64),
            torque_sign=float(data.get("torque_sign", 1.0)),
        )

    @classmethod
    def from_file(cls, path: str | Path) -> RobotModel:
        """Load a model from a ``.toml`` or ``.json`` file (chosen by suffix; TOML otherwise)."""
        p = Path(path)
        raw = p.read_bytes()
        try:
            data = json.loads(raw) if p.suffix.lower() == ".json" else tomllib.loads(raw.decode())
        except (json.JSONDecodeError, tomllib.TOMLDecodeError) as exc:
            raise ValueError(f"{p}: not a valid model file: {exc}") from exc
        try:
            return cls.from_dict(data)
        except (ValueError, TypeError, KeyError) as exc:
            raise ValueError(f"{p}: {exc}") from exc


#: The KUKA KR 6 R900 sixx (KR AGILUS 1st gen.) with the reference values.
KR6R900SIXX = RobotModel(
    name="KUKA KR 6 R900 sixx",
    # a, alpha, d, theta offset, sign — reference §1.3 (verified against the URDF to 4.5e-13 mm)
    dh=np.array(
        [
            [25.0, -90.0, 400.0, 0.0, -1.0],
            [455.0, 0.0, 0.0, 0.0, 1.0],
            [35.0, -90.0, 0.0, -90.0, 1.0],
            [0.0, 90.0, 420.0, 0.0, -1.0],
            [0.0, -90.0, 0.0, 0.0, 1.0],
            [0.0, 0.0, 80.0, 180.0, -1.0],
        ]
    ),
    lower=np.array([-170.0, -190.0, -120.0, -185.0, -120.0, -350.0]),
    upper=np.array([170.0, 45.0, 156.0, 185.0, 120.0, 350.0]),
    max_speed=np.array([360.0, 300.0, 360.0, 381.0, 388.0, 615.0]),
    max_accel=np.array([1241.0, 395.0, 1800.0, 7624.0, 7767.0, 15377.0]),
    # §3.3: KR 6 R900-2 inertials re-expressed in sixx frames (approximate, see reference)
    link_mass=np.array([8.416, 16.793, 5.988, 4.700, 1.613, 0.734]),
    link_com=np.array(
        [
            [6.4, 16.3, -85.4],
            [147.4, 17.0, 4.5],
            [41.7, 18.5, 12.3],
            [277.6, 9.4, 1.4],
            [9.3, 24.0, -0.8],
            [-16.7, 0.0, 0.0],
        ]
    ),
    # Joint origins at the all-zero pose (A1 at z 400, A2, A3, 35 above A3, wrist, flange).
    link_origin=np.array(
        [
            [0.0, 0.0, 400.0],
            [25.0, 0.0, 400.0],
            [480.0, 0.0, 400.0],
            [480.0, 0.0, 435.0],
            [900.0, 0.0, 435.0],
            [980.0, 0.0, 435.0],
        ]
    ),
    flange=np.eye(4),
    home=np.array([0.0, -90.0, 90.0, 0.0, 0.0, 0.0]),
    # Effort limits of KUKA's KR 6 R900-2 URDF (§3.1), approximate caps only.
    max_torque=np.array([334.8, 260.7, 137.8, 43.3, 45.7, 23.3]),
    torque_sign=1.0,
)
