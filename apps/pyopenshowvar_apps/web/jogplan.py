"""What one jog press asks of the KVP_JOG program: increment, accelerations, credit (pure).

The KRL side (``krl/kvp_jog.src``) plans one small increment per pass with ``$ADVANCE = 1``
and approximation, so the robot never runs more than about three increments ahead of the
PC. Everything here is arithmetic on the request; :mod:`.jog` does the I/O.

An increment lasts one :data:`CADENCE`. Its profile is a triangle (the speed limits are set
high), so its length ``v·T`` and acceleration ``v/T`` make it last exactly ``T`` to the peak
and ``T`` back; consecutive increments overlap by half, which sums to a constant speed ``v``.
A release therefore costs at most about ``3·T`` of motion: the increment that just started, the
one planned behind it, and their ramps. :data:`AXIS_SPEED` keeps ``v/T`` within each axis'
acceleration limit, so the jog speeds are what the drives can stop from in one cadence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from pyopenshowvar.kinematics import RobotModel

__all__ = [
    "AXIS_KEYS",
    "AXIS_SPEED",
    "CADENCE",
    "CART_KEYS",
    "CART_SPEED",
    "CREDIT",
    "STEP_SIZES",
    "JogPlan",
    "JogRequest",
    "plan_jog",
]

Frame = Literal["axis", "base", "tool"]
FloatArray = npt.NDArray[np.float64]

#: Seconds from the start of one increment to the start of the next (its profile takes twice
#: that). The advance run plans the next increment in the IPO cycle (12 ms) after one starts,
#: before it is needed; a release leaves at most about 3 cadences of motion (60 ms).
CADENCE = 0.020
#: Increments the robot may plan beyond the count the PC last saw: the robot's own watchdog.
#: 5 × 20 ms = 100 ms of motion if the PC (or the link to it) goes silent mid-jog.
CREDIT = 5
#: Jog speeds at 100 % jog override, deg/s. Each stays under ``max_accel · CADENCE`` of the
#: KR 6 R900 sixx (A2: 395 deg/s² · 20 ms = 7.9 deg/s) and under about 250 mm/s at the flange
#: when the arm is stretched (the T1 speed limit).
AXIS_SPEED = (15.0, 7.5, 15.0, 30.0, 30.0, 45.0)
#: Cartesian jog speeds at 100 %: mm/s for X/Y/Z, deg/s for A/B/C.
CART_SPEED = (100.0, 30.0)
#: Step-mode increments offered by the page: degrees for axes, mm (deg for A/B/C) otherwise.
STEP_SIZES = (0.1, 1.0, 10.0)
AXIS_KEYS = ("A1", "A2", "A3", "A4", "A5", "A6")
CART_KEYS = ("X", "Y", "Z", "A", "B", "C")
_MODES = {"axis": 1, "base": 2, "tool": 3}


@dataclass(frozen=True, slots=True)
class JogRequest:
    """One press of a jog button."""

    frame: Frame
    key: str
    direction: int
    #: Step mode: distance of the step (deg or mm); ``None`` = continuous while held.
    step: float | None = None
    #: Jog override, 1..100 %.
    override: float = 50.0

    def __post_init__(self) -> None:
        if self.frame not in _MODES:
            raise ValueError(f"frame must be axis, base or tool, not {self.frame!r}")
        keys = AXIS_KEYS if self.frame == "axis" else CART_KEYS
        if self.key not in keys:
            raise ValueError(f"{self.frame} jog keys are {', '.join(keys)}, not {self.key!r}")
        if self.direction not in (-1, 1):
            raise ValueError("direction must be +1 or -1")
        if self.step is not None and not (0.0 < self.step <= max(STEP_SIZES)):
            raise ValueError(f"step must be in (0, {max(STEP_SIZES):g}]")
        if not (1.0 <= self.override <= 100.0):
            raise ValueError("override must be 1..100 %")

    @property
    def index(self) -> int:
        keys = AXIS_KEYS if self.frame == "axis" else CART_KEYS
        return keys.index(self.key)

    @property
    def label(self) -> str:
        sign = "+" if self.direction > 0 else "-"
        return f"{self.frame} {self.key}{sign}" + (f" step {self.step:g}" if self.step else "")


@dataclass(frozen=True, slots=True)
class JogPlan:
    """The variables one press writes, in order, and what the robot will do."""

    mode: int
    #: ``JOG_AX`` or ``JOG_FR``: the increment the program reads when it plans.
    target: str
    #: The increment as a vector (6 axes, or X Y Z A B C).
    increment: FloatArray
    #: KRL literal of the increment.
    literal: str
    #: Acceleration settings: (``JOG_ACC`` %, ``JOG_ACC_CP`` m/s², ``JOG_ACC_ORI`` deg/s²).
    acc: tuple[int, float, float]
    #: Step mode: the exact number of increments; continuous: ``None``.
    count: int | None
    #: Jog speed (deg/s or mm/s).
    speed: float

    def start_writes(self, until: int) -> list[tuple[str, str]]:
        """Everything a press writes (``until``: the first JOG_UNTIL); ``JOG_MODE`` last, so
        the program sees a whole command."""
        acc, acc_cp, acc_ori = self.acc
        return [
            ("JOG_ACC", str(acc)),
            ("JOG_ACC_CP", _num(acc_cp)),
            ("JOG_ACC_ORI", _num(acc_ori)),
            (self.target, self.literal),
            ("JOG_UNTIL", str(until)),
            ("JOG_MODE", str(self.mode)),
        ]

    def stop_writes(self) -> list[tuple[str, str]]:
        """Zero the increment first: the motion the program plans next reads it."""
        return [(self.target, _literal(self.target, np.zeros(6))), ("JOG_UNTIL", "0"),
                ("JOG_MODE", "0")]  # fmt: skip

    def until(self, start: int, seen: int, credit: int) -> int:
        """JOG_UNTIL once JOG_COUNT reads ``seen`` (it read ``start`` at the press): ``credit``
        more increments, and in step mode never past the step."""
        limit = seen + credit
        if self.count is not None:
            limit = min(limit, start + self.count)
        return limit


def _num(x: float) -> str:
    text = f"{x:.6g}"
    return text if any(c in text for c in ".e") else text + ".0"


def _literal(target: str, vec: FloatArray) -> str:
    keys = AXIS_KEYS if target == "JOG_AX" else CART_KEYS
    return "{" + ", ".join(f"{k} {_num(float(v))}" for k, v in zip(keys, vec, strict=True)) + "}"


def plan_jog(req: JogRequest, model: RobotModel, *, cadence: float = CADENCE) -> JogPlan:
    """Increment, accelerations and count for ``req`` (see the module docstring)."""
    scale = req.override / 100.0
    inc = np.zeros(6)
    acc_pct, acc_cp, acc_ori = 100, 1.0, 100.0
    if req.frame == "axis":
        speed = AXIS_SPEED[req.index] * scale
        a_max = float(model.max_accel[req.index])
        # $ACC_AXIS is an INT % on a KRC; rounding moves the cadence a little, not the speed.
        acc_pct = max(1, min(100, round(100.0 * speed / cadence / a_max)))
        target = "JOG_AX"
    else:
        speed = CART_SPEED[0 if req.index < 3 else 1] * scale
        if req.index < 3:
            acc_cp = speed / cadence / 1000.0
        else:
            acc_ori = speed / cadence
        target = "JOG_FR"
    step = speed * cadence
    count = None
    if req.step is not None:
        count = max(1, math.ceil(req.step / step - 1e-9))
        step = req.step / count  # equal increments that add up to exactly the step
    inc[req.index] = req.direction * step
    return JogPlan(
        mode=_MODES[req.frame],
        target=target,
        increment=inc,
        literal=_literal(target, inc),
        acc=(acc_pct, acc_cp, acc_ori),
        count=count,
        speed=speed,
    )
