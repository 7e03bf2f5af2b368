"""The handles of a built cell's nodes: what the poller, the writes and the server hold on to.

:mod:`.robotics` builds the cell's tree in the OPC UA for Robotics model and returns, for each
robot, the NodeIds the poller writes every poll (:class:`RobotNodes`) and for the cell the
folders and the task state machine's states (:class:`CellNodes`). The engineering units of
the axis variables (:data:`UNITS`) are set once per connection (:mod:`.fixednodes`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from . import ua

__all__ = ["AXES", "UNITS", "CellNodes", "RobotNodes", "TaskNodes"]

AXES = ("A1", "A2", "A3", "A4", "A5", "A6")

_UNITS_URI = "http://www.opcfoundation.org/UA/units/un/cefact"


def _unit(code: str, symbol: str, text: str) -> ua.EUInformation:
    """A UNECE Rec 20 unit as OPC 10000-8 §5.6.3 encodes it (UnitId from the common code)."""
    unit_id = 0
    for ch in code:
        unit_id = (unit_id << 8) | ord(ch)
    return ua.EUInformation(
        NamespaceUri=_UNITS_URI,
        UnitId=unit_id,
        DisplayName=ua.LocalizedText(symbol),
        Description=ua.LocalizedText(text),
    )


UNITS = {
    "deg": _unit("DD", "°", "degree"),
    "deg/s": _unit("E96", "°/s", "degree per second"),
    "Nm": _unit("NU", "N·m", "newton metre"),
    "%": _unit("P1", "%", "percent"),
    "degC": _unit("CEL", "°C", "degree Celsius"),
}


@dataclass
class TaskNodes:
    """One KRL interpreter as a TaskControl: program name, loaded flag, state machine."""

    program_name: ua.NodeId
    program_loaded: ua.NodeId
    current_state: ua.NodeId
    current_state_id: ua.NodeId
    last_transition: ua.NodeId
    last_transition_id: ua.NodeId
    last_transition_reason: ua.NodeId


@dataclass
class RobotNodes:
    """The NodeIds the poller writes for one robot."""

    name: str
    motion_device: ua.NodeId
    controller: ua.NodeId
    safety: ua.NodeId
    #: identity key ("manufacturer", "model", ...) -> the nodes showing it
    identity: dict[str, list[ua.NodeId]] = field(default_factory=dict)
    position: list[ua.NodeId] = field(default_factory=list)
    #: EURange of each ActualPosition: the arm's axis range (deg)
    position_range: list[ua.NodeId] = field(default_factory=list)
    speed: list[ua.NodeId] = field(default_factory=list)
    torque: list[ua.NodeId] = field(default_factory=list)
    current: list[ua.NodeId] = field(default_factory=list)
    temperature: list[ua.NodeId] = field(default_factory=list)
    scalars: dict[str, ua.NodeId] = field(default_factory=dict)
    tasks: dict[str, TaskNodes] = field(default_factory=dict)
    extras: dict[str, ua.NodeId] = field(default_factory=dict)
    connected: ua.NodeId | None = None
    write_method: ua.NodeId | None = None


@dataclass
class CellNodes:
    system: ua.NodeId
    motion_devices: ua.NodeId
    controllers: ua.NodeId
    safety_states: ua.NodeId
    ns: dict[str, int]
    #: TaskControlStateMachineType's states and transitions: name -> (NodeId, number)
    states: dict[str, tuple[ua.NodeId, int]]
    transitions: dict[str, tuple[ua.NodeId, int]]
