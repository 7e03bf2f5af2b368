"""What the monitor polls, and the robot state parsed from one ``read_many`` answer.

Every refresh reads all panel variables and the watch list in ONE pipelined ``read_many``;
the software limits are constant and are read only until they are known (again after a
reconnect), with ``$MODEL_NAME[]``, which names the arm (:mod:`..armpick`): its catalogue
limits stand in where the controller does not answer the software limits, and the panel
names the arm. A variable that cannot be read or parsed leaves its previous value in place, so
a controller without ``$TORQUE_AXIS_ACT`` still shows joints and pose.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from pyopenshowvar import ReadResult, Struct, parse_value
from pyopenshowvar.errors import KrlValueError

from ..armpick import ArmChoice, choose_arm

AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
POSE = ("X", "Y", "Z", "A", "B", "C", "S", "T")

#: Read on every refresh.
PANEL_VARIABLES = (
    "$AXIS_ACT",
    "$POS_ACT",
    "$TORQUE_AXIS_ACT[]",
    "$OV_PRO",
    "$PRO_STATE1",
    "$PRO_NAME1[]",
    "$MODE_OP",
    "$VEL_ACT",
)
#: Read until known (constant while connected).
LIMIT_VARIABLES = ("$SOFTN_END[]", "$SOFTP_END[]", "$MODEL_NAME[]")
#: Samples kept for the plots (20 s at 10 Hz).
HISTORY = 200


def _parse(result: ReadResult | None) -> Any:
    if result is None or not result.ok or result.text is None:
        return None
    try:
        return parse_value(result.text)
    except (KrlValueError, ValueError):
        return None


def _num(value: Any) -> float:
    """A member as float; NaN when missing or not a number."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    return math.nan


def _floats(value: Any, count: int = 6) -> list[float] | None:
    if isinstance(value, list) and len(value) >= count:
        try:
            return [float(v) for v in value[:count]]
        except (TypeError, ValueError):
            return None
    return None


@dataclass
class RobotState:
    """The latest values the panels show, plus the recent history for the plots."""

    joints: list[float] = field(default_factory=lambda: [math.nan] * 6)
    torques: list[float] = field(default_factory=lambda: [math.nan] * 6)
    lower: list[float] | None = None
    upper: list[float] | None = None
    #: The arm given by the user (``--robot``); None: the one ``$MODEL_NAME[]`` names.
    given: ArmChoice | None = None
    #: The arm the panel shows (None until ``$MODEL_NAME[]`` was read, or ``given``).
    arm: ArmChoice | None = None
    #: Where :attr:`lower` / :attr:`upper` come from: "controller" or "catalogue".
    limits_from: str = ""
    pose: dict[str, float | int] = field(default_factory=dict)
    override: int | None = None
    program_state: str = ""
    program_name: str = ""
    mode: str = ""
    velocity: float | None = None
    watch: dict[str, str] = field(default_factory=dict)
    updates: int = 0
    joint_history: list[deque[float]] = field(
        default_factory=lambda: [deque(maxlen=HISTORY) for _ in range(6)]
    )
    torque_history: list[deque[float]] = field(
        default_factory=lambda: [deque(maxlen=HISTORY) for _ in range(6)]
    )

    def names_to_read(self, watch: list[str]) -> list[str]:
        """The names of the next poll: panels, limits while unknown, then the watch list."""
        names = list(PANEL_VARIABLES)
        if self.lower is None or self.upper is None:
            names += LIMIT_VARIABLES
        names += [w for w in watch if w not in names]
        return names

    def forget_limits(self) -> None:
        """Read the limits again (after a reconnect: it may be another controller)."""
        self.lower = self.upper = None
        self.arm = None

    def update(self, results: dict[str, ReadResult], watch: list[str]) -> None:
        """Take one poll's answers."""
        axis = _parse(results.get("$AXIS_ACT"))
        if isinstance(axis, Struct):
            self.joints = [_num(axis.get(a)) for a in AXES]
        torques = _floats(_parse(results.get("$TORQUE_AXIS_ACT[]")))
        if torques is not None:
            self.torques = torques
        pose = _parse(results.get("$POS_ACT"))
        if isinstance(pose, Struct):
            self.pose = {k: pose[k] for k in POSE if k in pose}  # type: ignore[misc]
        self._limits(results)
        override = _parse(results.get("$OV_PRO"))
        if isinstance(override, int) and not isinstance(override, bool):
            self.override = override
        for attr, name in (
            ("program_state", "$PRO_STATE1"),
            ("program_name", "$PRO_NAME1[]"),
            ("mode", "$MODE_OP"),
        ):
            value = _parse(results.get(name))
            if value is not None:
                setattr(self, attr, str(value))
        vel = _parse(results.get("$VEL_ACT"))
        if isinstance(vel, int | float) and not isinstance(vel, bool):
            self.velocity = float(vel)
        for name in watch:
            r = results.get(name)
            if r is not None:
                self.watch[name] = r.text if r.ok and r.text is not None else f"<{_why(r)}>"
        for i in range(6):
            self.joint_history[i].append(self.joints[i])
            self.torque_history[i].append(self.torques[i])
        self.updates += 1

    def _limits(self, results: dict[str, ReadResult]) -> None:
        """The software limits: the controller's, else the named arm's catalogue limits."""
        name = results.get("$MODEL_NAME[]")
        if name is not None:
            text = _parse(name)
            self.arm = choose_arm(text if isinstance(text, str) else "", self.given)
        lower = _floats(_parse(results.get("$SOFTN_END[]")))
        upper = _floats(_parse(results.get("$SOFTP_END[]")))
        if lower is not None and upper is not None:
            self.lower, self.upper, self.limits_from = lower, upper, "controller"
        elif name is not None and self.arm is not None and self.arm.key:
            model = self.arm.model
            self.lower, self.upper = model.lower.tolist(), model.upper.tolist()
            self.limits_from = "catalogue"


def _why(result: ReadResult) -> str:
    from pyopenshowvar import UnknownVariableError

    return "unknown variable" if isinstance(result.error, UnknownVariableError) else "read failed"
