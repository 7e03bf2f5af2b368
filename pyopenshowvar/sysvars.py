"""The KRC4 system variables: types, access, value ranges and a KRC4's texts at HOME.

KRC facts both sides use: the emulator's variable store (:mod:`kukavarproxy_emu.store`)
declares each entry and parses its initial literal with the entry's type; the apps explain a
refused write with an entry's access and range. The table is data only. The robot model updates the read-only
motion variables later through ``VariableStore.set_system``; the values here are the state of
a KR 6 R900 sixx standing at HOME (A1..A6 = 0, -90, 90, 0, 0, 0) on a KRC4 in ``#AUT``.

Figures: the variables and their texts as captured from KRC4s in public clients, KUKA's KR AGILUS
sixx limits (kroshu/kuka_robot_descriptions, ros-industrial/kuka_experimental), the holding
torques of KUKA's KR 6 R900-2 masses at the HOME pose. Initial values can be replaced per name with
``system_variables(overrides)``, e.g. ``{"$MODE_OP": "#T1"}`` for a teach-mode controller;
another arm (``--robot``) replaces the arm's own ones (``kukavarproxy_emu.robots.RobotSpec.sysvar_overrides``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

__all__ = ["INT_MAX", "INT_MIN", "SYSTEM_VARIABLES", "SysVar", "system_variables"]

# KRL INT is a 32-bit signed integer.
INT_MIN = -(2**31)
INT_MAX = 2**31 - 1

# An array initialiser is a tuple of element literals (one per element) or one literal that
# every element gets; a scalar's is one literal. None leaves the variable uninitialised.
Init = str | tuple[str, ...] | None


@dataclass(frozen=True, slots=True)
class SysVar:
    """One system variable; ``type_name`` is the element type for arrays (``CHAR`` for text)."""

    name: str
    type_name: str
    dims: tuple[int, ...] = ()
    read_only: bool = True
    init: Init = None
    value_range: tuple[int, int] | None = None
    doc: str = ""


def _axes(*first: float, fill: float = 0.0, count: int = 12) -> tuple[str, ...]:
    """Element literals for an axis array: the robot axes given, then the rest filled."""
    values = [*first, *([fill] * (count - len(first)))]
    return tuple(repr(float(v)) for v in values)


def _ints(*first: int, fill: int = 0, count: int = 12) -> tuple[str, ...]:
    return tuple(str(v) for v in [*first, *([fill] * (count - len(first)))])


_ZERO_FRAME = "{FRAME: X 0.0, Y 0.0, Z 0.0, A 0.0, B 0.0, C 0.0}"
_HOME_AXIS = (
    "{E6AXIS: A1 0.0, A2 -90.0, A3 90.0, A4 0.0, A5 0.0, A6 0.0,"
    " E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)
# Flange pose at HOME with $TOOL = $BASE = $NULLFRAME (reference §1.5).
_HOME_POS = (
    "{E6POS: X 525.0, Y 0.0, Z 890.0, A 0.0, B 90.0, C 0.0, S 2, T 2,"
    " E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)
_NO_LOAD = (
    "{LOAD: M 0.0, CM {FRAME: X 0.0, Y 0.0, Z 0.0, A 0.0, B 0.0, C 0.0},"
    " J {INERTIA: X 0.0, Y 0.0, Z 0.0}}"
)

SYSTEM_VARIABLES: tuple[SysVar, ...] = (
    # --- axis and Cartesian position (driven by the robot model) ---
    SysVar("$AXIS_ACT", "E6AXIS", init=_HOME_AXIS, doc="set-point axis position, deg"),
    SysVar("$AXIS_ACT_MEAS", "E6AXIS", init=_HOME_AXIS, doc="measured axis position, deg"),
    SysVar("$POS_ACT", "E6POS", init=_HOME_POS, doc="set-point TCP pose in $BASE"),
    SysVar("$POS_ACT_MES", "E6POS", init=_HOME_POS, doc="TCP pose from measured axes"),
    SysVar("$VEL_ACT", "REAL", init="0.0", doc="TCP speed, m/s"),
    SysVar("$DIST_NEXT", "REAL", init="0.0", doc="distance to the next target, mm"),
    # --- drive data, one entry per axis, 7..12 = E1..E6 ---
    # Holding torques at HOME from the mass model (reference §3.3), Nm.
    SysVar("$TORQUE_AXIS_ACT", "REAL", (12,), init=_axes(0.0, -24.78, -25.5, -0.8, -0.6, 0.0)),
    # Effort limits of the KR 6 R900-2 URDF as approximate caps (reference §3.1), Nm.
    SysVar("$TORQUE_AXIS_MAX", "REAL", (12,), init=_axes(334.8, 260.7, 137.8, 43.3, 45.7, 23.3)),
    SysVar("$CURR_ACT", "REAL", (12,), init=_axes(), doc="motor current, % of max"),
    SysVar("$VEL_AXIS_ACT", "REAL", (12,), init=_axes(), doc="axis speed, % of max"),
    SysVar("$VEL_AXIS_MA", "REAL", (12,), init=_axes(*[4500.0] * 6), doc="max motor speed"),
    SysVar("$MOT_TEMP", "INT", (12,), init=_ints(*[300] * 6), doc="motor temperature, K"),
    # Software limit switches (reference §3.1); external axes are unlimited in practice.
    SysVar("$SOFTN_END", "REAL", (12,), init=_axes(-170, -190, -120, -185, -120, -350, fill=-5000)),
    SysVar("$SOFTP_END", "REAL", (12,), init=_axes(170, 45, 156, 185, 120, 350, fill=5000)),
    # --- overrides and motion parameters (writable over KUKAVARPROXY) ---
    SysVar("$OV_PRO", "INT", read_only=False, init="100", value_range=(0, 100)),
    SysVar("$OV_JOG", "INT", read_only=False, init="100", value_range=(0, 100)),
    SysVar("$VEL", "CP", read_only=False, init="{CP 2.0, ORI1 400.0, ORI2 400.0}"),
    SysVar("$ACC", "CP", read_only=False, init="{CP 10.0, ORI1 1000.0, ORI2 1000.0}"),
    SysVar("$VEL_AXIS", "INT", (12,), read_only=False, init="100", value_range=(0, 100)),
    SysVar("$ACC_AXIS", "INT", (12,), read_only=False, init="100", value_range=(0, 100)),
    SysVar("$APO", "APO", read_only=False, init="{CVEL 100, CPTP 50, CDIS 0.0, CORI 0.0}"),
    SysVar("$ADVANCE", "INT", read_only=False, init="3", value_range=(0, 5)),
    SysVar("$TOOL", "FRAME", read_only=False, init=_ZERO_FRAME),
    SysVar("$BASE", "FRAME", read_only=False, init=_ZERO_FRAME),
    SysVar("$LOAD", "LOAD", read_only=False, init=_NO_LOAD, doc="payload (none)"),
    SysVar("$TIMER", "INT", (32,), read_only=False, init="0", doc="ms timers"),
    SysVar("$NULLFRAME", "FRAME", init=_ZERO_FRAME),
    SysVar("$WORLD", "FRAME", init=_ZERO_FRAME),
    SysVar("$ROBROOT", "FRAME", init=_ZERO_FRAME),
    # --- controller state ---
    SysVar("$MODE_OP", "MODE_OP", init="#AUT", doc="#T1, #T2, #AUT or #EX"),
    SysVar("$PRO_STATE1", "PRO_STATE", init="#P_FREE", doc="robot interpreter"),
    SysVar("$PRO_STATE0", "PRO_STATE", init="#P_ACTIVE", doc="submit interpreter (SPS)"),
    SysVar("$PRO_NAME1", "CHAR", (24,), init='""', doc="selected robot program"),
    SysVar("$PRO_NAME0", "CHAR", (24,), init='"SPS"', doc="submit program"),
    SysVar("$DRIVES_ON", "BOOL", init="TRUE"),
    # TRUE while a stop message is active (the robot program was stopped by an error).
    SysVar("$STOPMESS", "BOOL", init="FALSE"),
    # Emulator only: text of the message that stopped the robot program ("" = none); see
    # docs/emulator-robot.md. A KRC shows it on the smartPAD, which KVP cannot read.
    SysVar("$EMU_MESSAGE", "CHAR", (128,), init='""', doc="last robot error message"),
    SysVar("$PERI_RDY", "BOOL", init="TRUE"),
    # $ALARM_STOP is active-low: TRUE means the emergency-stop circuit is closed (no alarm).
    SysVar("$ALARM_STOP", "BOOL", init="TRUE"),
    SysVar("$POWER_FAIL", "BOOL", init="FALSE"),
    # Operator safety (the safety gate): TRUE = closed; open in #AUT/#EX stops the robot.
    SysVar("$USER_SAF", "BOOL", init="TRUE"),
    # Inputs come from the field bus and outputs from the robot/SPS program: neither can be
    # written through KUKAVARPROXY (JOpenShowVar's documentation; copy a global in the SPS).
    SysVar("$IN", "BOOL", (4096,), init="FALSE"),
    SysVar("$OUT", "BOOL", (4096,), init="FALSE"),
    # --- identity (also answered to UDP discovery as KUKA|$MODEL_NAME[]|$KR_SERIALNO) ---
    SysVar("$ROBNAME", "CHAR", (32,), init='"KR6-EMULATOR"'),
    SysVar("$MODEL_NAME", "CHAR", (32,), init='"#KR6R900SIXX C4SR FLR"'),
    SysVar("$TRAFONAME", "CHAR", (32,), init='"#KR6R900SIXX C4SR FLR"'),
    SysVar("$KR_SERIALNO", "INT", init="123456"),
)


def system_variables(overrides: Mapping[str, str | Sequence[str]] | None = None) -> list[SysVar]:
    """The table with some initial literals replaced (names are case-insensitive).

    A sequence replaces an array's element literals; a single literal sets every element.
    Raises ``KeyError`` for a name that is not in the table, so typos do not pass silently.
    """
    table = list(SYSTEM_VARIABLES)
    if not overrides:
        return table
    index = {var.name: i for i, var in enumerate(table)}
    for name, init in overrides.items():
        key = name.strip().upper()
        if key not in index:
            raise KeyError(f"not a system variable of the emulator: {name!r}")
        value: Init = init if isinstance(init, str) else tuple(init)
        table[index[key]] = replace(table[index[key]], init=value)
    return table
