"""From KRC variables to Robotics-model values: what is read each poll, and what it means.

Pure functions, no I/O: the poller hands in the typed values it read and gets back
``{key: value}`` for the nodes of :class:`~.cellnodes.RobotNodes`. The mapping (also the table
in docs/gateway.md):

=====================================  =====================================================
KRC variable                           OPC 40010-1 node
=====================================  =====================================================
``$AXIS_ACT`` A1..A6 (deg)             Axes/Ax ParameterSet/ActualPosition (°)
``$VEL_AXIS_ACT[]`` (% of max speed)   Axes/Ax ParameterSet/ActualSpeed (°/s, × max speed)
``$TORQUE_AXIS_ACT[]`` (Nm)            PowerTrains/PowerTrainx/Motorx ParameterSet/ActualTorque*
``$CURR_ACT[]`` (% of max current)     PowerTrains/PowerTrainx/Motorx ParameterSet/ActualCurrent*
``$MOT_TEMP[]`` (K)                    Motorx ParameterSet/MotorTemperature (°C)
``$OV_PRO``                            MotionDevice ParameterSet/SpeedOverride
``$DRIVES_ON``                         MotionDevice ParameterSet/InControl
``$PRO_NAME1[]``, ``$PRO_STATE1``      TaskControls/RobotInterpreter (name, loaded, state)
``$PRO_NAME0[]``, ``$PRO_STATE0``      TaskControls/SubmitInterpreter
``$MODE_OP``                           SafetyStates OperationalMode
``$ALARM_STOP`` (active low)           EmergencyStop; EmergencyStopFunctions/EmergencyStop
``$USER_SAF`` (FALSE: guard open)      ProtectiveStopFunctions/OperatorSafety (#AUT, #EX only)
``$STOPMESS``                          ProtectiveStopFunctions/StopMessage
=====================================  =====================================================

(* our namespace: the Robotics model has no torque or current variable.) ProtectiveStop is
TRUE when any protective-stop function is active. Program states map onto the TaskControl
state machine: ``#P_FREE`` (no program selected) → Idle, ``#P_RESET``, ``#P_STOP`` and
``#P_END`` → Ready (a program is loaded and can be started), ``#P_ACTIVE`` → Executing.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence, Set
from typing import Any

from pyopenshowvar import KrlEnum, Struct

__all__ = [
    "IDENTITY_VARIABLES",
    "POLL_VARIABLES",
    "SLOW_EVERY",
    "SLOW_VARIABLES",
    "identity_values",
    "operational_mode",
    "poll_values",
    "task_state",
    "text_of",
]

#: Read once per connection.
IDENTITY_VARIABLES = ("$MODEL_NAME[]", "$KR_SERIALNO", "$ROBNAME[]", "$RCV_INFO[]")
#: Read every poll, in one pipelined batch.
POLL_VARIABLES = (
    "$AXIS_ACT",
    "$VEL_AXIS_ACT[]",
    "$TORQUE_AXIS_ACT[]",
    "$CURR_ACT[]",
    "$MOT_TEMP[]",
    "$OV_PRO",
    "$DRIVES_ON",
    "$MODE_OP",
    "$ALARM_STOP",
    "$USER_SAF",
    "$STOPMESS",
    "$PRO_STATE1",
    "$PRO_NAME1[]",
    "$PRO_STATE0",
    "$PRO_NAME0[]",
)

#: Read only every SLOW_EVERY-th poll (2 Hz at the default 10 Hz): motor temperatures change
#: over minutes, and program names only when a program is selected (the interpreter states,
#: which tell that at once, stay in every poll). Saves a fifth of the KVP requests.
SLOW_VARIABLES = frozenset({"$MOT_TEMP[]", "$PRO_NAME1[]", "$PRO_NAME0[]", "$PRO_STATE0"})
SLOW_EVERY = 5

# OPC 40010-1 OperationalModeEnumeration
_MODES = {"T1": 1, "T2": 2, "AUT": 3, "EX": 4}
_AUTOMATIC = {"AUT", "EX"}
_AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
KELVIN = 273.15


def text_of(value: Any) -> str:
    """A CHAR array's text or an identity value as a plain string (no quotes, no ``#``)."""
    if value is None:
        return ""
    if isinstance(value, KrlEnum):
        return value.name
    return str(value).strip().strip('"').strip().lstrip("#")


def operational_mode(mode: Any) -> int:
    return _MODES.get(mode.name.upper(), 0) if isinstance(mode, KrlEnum) else 0


def task_state(state: Any) -> str:
    """The TaskControlStateMachine state of a KRL interpreter state (``#P_ACTIVE``...)."""
    name = state.name.upper() if isinstance(state, KrlEnum) else ""
    if name == "P_ACTIVE":
        return "Executing"
    if name in ("P_RESET", "P_STOP", "P_END"):
        return "Ready"
    return "Idle"


def identity_values(values: Mapping[str, Any]) -> dict[str, Any]:
    """The identity nodes' values from :data:`IDENTITY_VARIABLES` (absent ones are empty)."""
    model = text_of(values.get("$MODEL_NAME[]"))
    serial = values.get("$KR_SERIALNO")
    return {
        "model": model,
        "product_code": model,
        "serial": "" if serial is None else text_of(serial),
        "name": text_of(values.get("$ROBNAME[]")),
        "software_revision": text_of(values.get("$RCV_INFO[]")),
    }


def _floats(values: Any, count: int, scale: Sequence[float] | float = 1.0) -> list[float] | None:
    if not isinstance(values, list) or len(values) < count:
        return None
    try:
        raw = [float(v) for v in values[:count]]
    except (TypeError, ValueError):
        return None
    if isinstance(scale, int | float):
        return [v * scale for v in raw]
    return [v * s for v, s in zip(raw, scale, strict=True)]


_SAFETY = frozenset({"$MODE_OP", "$ALARM_STOP", "$USER_SAF", "$STOPMESS"})


def poll_values(
    values: Mapping[str, Any],
    max_speed: Sequence[float],
    changed: Set[str] | None = None,
) -> dict[str, Any]:
    """The per-poll node values from the typed values of :data:`POLL_VARIABLES`.

    Keys missing from ``values`` (unknown on this controller, or not read) give no entry, so
    their nodes keep their last value and status. With ``changed`` (the variables whose text
    changed this poll) only the entries that depend on them are computed: at 500 polls a
    second, recomputing and comparing unchanged values is most of the work.
    """

    def want(*names: str) -> bool:
        return changed is None or any(n in changed for n in names)

    out: dict[str, Any] = {}
    axes = values.get("$AXIS_ACT")
    # a Struct from parse_value, or the members' dict from the fast path (parse_number_struct)
    members: object = axes.members if isinstance(axes, Struct) else axes
    if want("$AXIS_ACT") and isinstance(members, Mapping):
        try:
            out["position"] = [float(members[a]) for a in _AXES]
        except (KeyError, TypeError, ValueError):
            pass
    percent_to_speed = [s / 100.0 for s in max_speed]
    for key, name, scale in (
        ("speed", "$VEL_AXIS_ACT[]", percent_to_speed),
        ("torque", "$TORQUE_AXIS_ACT[]", 1.0),
        ("current", "$CURR_ACT[]", 1.0),
    ):
        converted = _floats(values.get(name), 6, scale) if want(name) else None
        if converted is not None:
            out[key] = converted
    temps = _floats(values.get("$MOT_TEMP[]"), 6) if want("$MOT_TEMP[]") else None
    if temps is not None:
        # rounded: 300 K - 273.15 is 26.850000000000023 in binary floating point, and a
        # micro-kelvin is far below any motor sensor's resolution
        out["temperature"] = [round(t - KELVIN, 6) for t in temps]
    if want("$OV_PRO") and isinstance(values.get("$OV_PRO"), int | float):
        out["override"] = float(values["$OV_PRO"])
    if want("$DRIVES_ON") and isinstance(values.get("$DRIVES_ON"), bool):
        out["in_control"] = values["$DRIVES_ON"]
    for key, state_var, name_var in (
        ("robot", "$PRO_STATE1", "$PRO_NAME1[]"),
        ("submit", "$PRO_STATE0", "$PRO_NAME0[]"),
    ):
        if state_var in values and want(state_var):
            state = task_state(values[state_var])
            out[f"{key}_state"] = state
            out[f"{key}_loaded"] = state != "Idle"
        if name_var in values and want(name_var):
            out[f"{key}_program"] = text_of(values[name_var])
    if want(*_SAFETY):
        out.update(_safety(values))
    return out


def _safety(values: Mapping[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    mode = values.get("$MODE_OP")
    if mode is not None:
        out["mode"] = operational_mode(mode)
    alarm = values.get("$ALARM_STOP")
    if isinstance(alarm, bool):
        out["estop"] = out["estop_fn_active"] = not alarm
    # Operator safety (the guard) is monitored in the automatic modes only; in T1/T2 the
    # enabling switch guards the operator instead.
    automatic = isinstance(mode, KrlEnum) and mode.name.upper() in _AUTOMATIC
    user_saf = values.get("$USER_SAF")
    active: list[bool] = []
    if isinstance(user_saf, bool) and mode is not None:
        out["opsafe_fn_enabled"] = automatic
        out["opsafe_fn_active"] = automatic and not user_saf
        active.append(out["opsafe_fn_active"])
    stopmess = values.get("$STOPMESS")
    if isinstance(stopmess, bool):
        out["stopmess_fn_enabled"] = True
        out["stopmess_fn_active"] = stopmess
        active.append(stopmess)
    if active:
        out["pstop"] = any(active)
    return out
