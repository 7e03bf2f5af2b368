"""The cell's node tree in the OPC UA for Robotics model (OPC 40010-1, NodeSet 1.02).

::

    Objects/DeviceSet/<cell> : MotionDeviceSystemType
      MotionDevices/<robot> : MotionDeviceType      Manufacturer, Model, SerialNumber, ...
        Axes/A1..A6 : AxisType                       ParameterSet/ActualPosition, ActualSpeed
        PowerTrains/PowerTrain1..6 : PowerTrainType  Motor1 : MotorType (MotorTemperature,
                                                     + ActualTorque, ActualCurrent: ours)
        ParameterSet/SpeedOverride, InControl
      Controllers/<robot> : ControllerType           Software/KSS, CurrentUser,
        TaskControls/RobotInterpreter, SubmitInterpreter : TaskControlType (+ state machine)
        ParameterSet/<extra variables>, Connected (ours); WriteVariable method (ours)
      SafetyStates/<robot> : SafetyStateType          OperationalMode, EmergencyStop,
                                                     ProtectiveStop and their functions

The references the specification defines between them are added too: the controller
``Controls`` its motion device and ``HasSafetyStates`` its safety state; each power train
``Moves`` its axis and the axis ``Requires`` it (one motor per axis: a KUKA wrist's mechanical
coupling is not modelled). NodeIds of the specification's types are its normative numeric ids;
:func:`check_type_ids` verifies them against the loaded NodeSet at start-up.
"""

from __future__ import annotations

from typing import Any

from . import ua
from .cellnodes import AXES, CellNodes, RobotNodes, TaskNodes
from .clone import RobotTemplate
from .model import DI_URI, GATEWAY_URI, ROBOTICS_URI, Instantiator, NodeBatch
from .ua import Server

__all__ = ["RobotBuilder", "build_cell", "check_type_ids"]

# Normative NodeIds (OPC 40010-1 NodeSet 1.02, DI 1.05) with the browse name each must have.
ROBOTICS_IDS = {
    "MotionDeviceSystemType": 1002,
    "ControllerType": 1003,
    "MotionDeviceType": 1004,
    "TaskControlType": 1011,
    "SafetyStateType": 1013,
    "MotorType": 1019,
    "TaskControlStateMachineType": 1025,
    "AxisType": 16601,
    "PowerTrainType": 16794,
    "EmergencyStopFunctionType": 17230,
    "ProtectiveStopFunctionType": 17233,
    "UserType": 18175,
    "Controls": 4002,
    "Moves": 18178,
    "Requires": 18179,
    "HasSafetyStates": 18182,
}
DI_IDS = {"SoftwareType": 15106, "DeviceSet": 5001}

_ANALOG_UNIT = ua.node_id(ua.ObjectIds.AnalogUnitType)
_DATA_VARIABLE = ua.node_id(ua.ObjectIds.BaseDataVariableType)
_HAS_COMPONENT = ua.node_id(ua.ObjectIds.HasComponent)
_HAS_ADDIN = ua.node_id(ua.ObjectIds.HasAddIn)


def _rid(ns: dict[str, int], name: str) -> ua.NodeId:
    return ua.node_id(ROBOTICS_IDS[name], ns[ROBOTICS_URI])


async def check_type_ids(server: Server, ns: dict[str, int]) -> None:
    """Every hard-coded id names the node the specification says (a wrong NodeSet fails loud)."""
    pairs = [(ua.node_id(i, ns[ROBOTICS_URI]), n) for n, i in ROBOTICS_IDS.items()]
    pairs += [(ua.node_id(i, ns[DI_URI]), n) for n, i in DI_IDS.items()]
    for node_id, name in pairs:
        browse = await server.get_node(node_id).read_browse_name()
        if browse.Name != name:
            raise RuntimeError(
                f"NodeSet mismatch: {node_id.to_string()} is {browse.Name}, not {name}"
            )


async def _state_table(server: Server, ns: dict[str, int]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The states and transitions of TaskControlStateMachineType with their numbers."""
    machine = server.get_node(_rid(ns, "TaskControlStateMachineType"))
    states: dict[str, tuple[ua.NodeId, int]] = {}
    transitions: dict[str, tuple[ua.NodeId, int]] = {}
    for child in await machine.get_children(refs=ua.ObjectIds.HasComponent):
        tdef = await child.read_type_definition()
        if tdef not in (
            ua.node_id(ua.ObjectIds.StateType),
            ua.node_id(ua.ObjectIds.TransitionType),
        ):
            continue
        name = (await child.read_browse_name()).Name
        prop = "StateNumber" if tdef == ua.node_id(ua.ObjectIds.StateType) else "TransitionNumber"
        number = await (await child.get_child(prop)).read_value()
        (states if prop == "StateNumber" else transitions)[name] = (child.nodeid, int(number))
    return states, transitions


async def build_cell(
    server: Server, inst: Instantiator, ns: dict[str, int], cell_name: str
) -> CellNodes:
    """The MotionDeviceSystem in DI's DeviceSet, with its three folders."""
    await check_type_ids(server, ns)
    batch = NodeBatch()
    ours = ns[GATEWAY_URI]
    device_set = ua.node_id(DI_IDS["DeviceSet"], ns[DI_URI])
    system = await inst.add(
        batch,
        device_set,
        cell_name,
        ua.QualifiedName(cell_name, ours),
        _rid(ns, "MotionDeviceSystemType"),
    )
    await _commit(server, batch)
    states, transitions = await _state_table(server, ns)
    return CellNodes(
        system,
        ua.node_id(f"{cell_name}.MotionDevices", ours),
        ua.node_id(f"{cell_name}.Controllers", ours),
        ua.node_id(f"{cell_name}.SafetyStates", ours),
        ns,
        states,
        transitions,
    )


async def _commit(server: Server, batch: NodeBatch) -> None:
    session = server.iserver.isession
    results = await session.add_nodes(batch.items)
    for item, res in zip(batch.items, results, strict=True):
        if not res.StatusCode.is_good():
            raise RuntimeError(
                f"cannot add {item.RequestedNewNodeId.to_string()}: {res.StatusCode}"
            )
    if batch.references:
        for ref, code in zip(
            batch.references, await session.add_references(batch.references), strict=True
        ):
            if not code.is_good():
                raise RuntimeError(
                    f"cannot add reference from {ref.SourceNodeId.to_string()}: {code}"
                )


class RobotBuilder:
    """Adds one robot's MotionDevice, Controller and SafetyState.

    The first robot is instantiated from the types (one AddNodes call); the others are copies
    of it (:mod:`.clone`, a twentieth of the time) unless ``clone`` is False. Each robot's
    extra variables are added afterwards, as they differ between robots.
    """

    def __init__(
        self, server: Server, inst: Instantiator, cell: CellNodes, *, clone: bool = True
    ) -> None:
        self.server, self.inst, self.cell = server, inst, cell
        self.ns = cell.ns
        self.ours = cell.ns[GATEWAY_URI]
        self.r = cell.ns[ROBOTICS_URI]
        self.di = cell.ns[DI_URI]
        self.clone = clone
        self.template: RobotTemplate | None = None

    async def _add(
        self,
        batch: NodeBatch,
        parent: ua.NodeId,
        node_id: str,
        browse_name: ua.QualifiedName,
        type_definition: ua.NodeId,
        **kw: Any,
    ) -> ua.NodeId:
        """:meth:`Instantiator.add`, or only the NodeId for a dry batch."""
        if batch.dry:
            return self._id(node_id)
        return await self.inst.add(batch, parent, node_id, browse_name, type_definition, **kw)

    def _q(self, name: str, ns: int | None = None) -> ua.QualifiedName:
        return ua.QualifiedName(name, self.ours if ns is None else ns)

    def _id(self, path: str) -> ua.NodeId:
        return ua.node_id(path, self.ours)

    async def build(self, name: str, extras: tuple[str, ...]) -> RobotNodes:
        batch = NodeBatch(dry=self.template is not None)
        cell = self.cell
        md_path = f"{ua.path_of(cell.motion_devices)}.{name}"
        ctrl_path = f"{ua.path_of(cell.controllers)}.{name}"
        safe_path = f"{ua.path_of(cell.safety_states)}.{name}"
        md = await self._add(
            batch,
            cell.motion_devices,
            md_path,
            self._q(name),
            _rid(self.ns, "MotionDeviceType"),
            optional=frozenset({"ComponentName", "TaskControlReference", "ParameterSet/InControl"}),
        )
        ctrl = await self._add(
            batch,
            cell.controllers,
            ctrl_path,
            self._q(name),
            _rid(self.ns, "ControllerType"),
            optional=frozenset({"ComponentName", "ParameterSet"}),
        )
        safe = await self._add(
            batch,
            cell.safety_states,
            safe_path,
            self._q(name),
            _rid(self.ns, "SafetyStateType"),
            optional=frozenset({"EmergencyStopFunctions", "ProtectiveStopFunctions"}),
        )
        nodes = RobotNodes(name, md, ctrl, safe)
        await self._motion_device(batch, nodes, md_path)
        await self._controller(batch, nodes, ctrl_path)
        await self._safety(batch, nodes, safe_path)
        batch.reference(ctrl, _rid(self.ns, "Controls"), md)
        batch.reference(ctrl, _rid(self.ns, "HasSafetyStates"), safe)
        if self.template is not None:
            self.template.stamp(self.server, [md, ctrl, safe], name)
        else:
            await _commit(self.server, batch)
            if self.clone:
                self.template = RobotTemplate.capture(self.server, [md, ctrl, safe], name)
        own = NodeBatch()
        params = self._id(f"{ctrl_path}.ParameterSet")
        for extra in extras:
            nodes.extras[extra] = await self._variable(
                own, params, f"{ctrl_path}.ParameterSet.{extra}", extra, ua.ObjectIds.BaseDataType
            )
        await _commit(self.server, own)
        return nodes

    async def _motion_device(self, batch: NodeBatch, nodes: RobotNodes, path: str) -> None:
        for key, prop in (
            ("manufacturer", "Manufacturer"),
            ("model", "Model"),
            ("product_code", "ProductCode"),
            ("serial", "SerialNumber"),
            ("name", "ComponentName"),
        ):
            nodes.identity.setdefault(key, []).append(self._id(f"{path}.{prop}"))
        nodes.identity["category"] = [self._id(f"{path}.MotionDeviceCategory")]
        nodes.scalars["override"] = self._id(f"{path}.ParameterSet.SpeedOverride")
        nodes.scalars["in_control"] = self._id(f"{path}.ParameterSet.InControl")
        nodes.identity["task_reference"] = [self._id(f"{path}.TaskControlReference")]
        for i, axis in enumerate(AXES, 1):
            axis_id = await self._add(
                batch,
                self._id(f"{path}.Axes"),
                f"{path}.Axes.{axis}",
                self._q(axis),
                _rid(self.ns, "AxisType"),
                optional=frozenset(
                    {"ParameterSet/ActualSpeed", "ParameterSet/ActualPosition/EURange"}
                ),
            )
            nodes.identity.setdefault("motion_profile", []).append(
                self._id(f"{path}.Axes.{axis}.MotionProfile")
            )
            nodes.position.append(self._id(f"{path}.Axes.{axis}.ParameterSet.ActualPosition"))
            nodes.position_range.append(
                self._id(f"{path}.Axes.{axis}.ParameterSet.ActualPosition.EURange")
            )
            nodes.speed.append(self._id(f"{path}.Axes.{axis}.ParameterSet.ActualSpeed"))
            pt_path = f"{path}.PowerTrains.PowerTrain{i}"
            pt = await self._add(
                batch,
                self._id(f"{path}.PowerTrains"),
                pt_path,
                self._q(f"PowerTrain{i}"),
                _rid(self.ns, "PowerTrainType"),
            )
            motor_path = f"{pt_path}.Motor{i}"
            await self._add(batch, pt, motor_path, self._q(f"Motor{i}"), _rid(self.ns, "MotorType"))
            for key, prop in (
                ("motor_manufacturer", "Manufacturer"),
                ("motor_model", "Model"),
                ("motor_product_code", "ProductCode"),
                ("motor_serial", "SerialNumber"),
            ):
                nodes.identity.setdefault(key, []).append(self._id(f"{motor_path}.{prop}"))
            params = self._id(f"{motor_path}.ParameterSet")
            nodes.temperature.append(self._id(f"{motor_path}.ParameterSet.MotorTemperature"))
            nodes.torque.append(
                await self._analog(
                    batch, params, f"{motor_path}.ParameterSet.ActualTorque", "ActualTorque"
                )
            )
            nodes.current.append(
                await self._analog(
                    batch, params, f"{motor_path}.ParameterSet.ActualCurrent", "ActualCurrent"
                )
            )
            batch.reference(pt, _rid(self.ns, "Moves"), axis_id)
            batch.reference(axis_id, _rid(self.ns, "Requires"), pt)

    async def _analog(
        self, batch: NodeBatch, parent: ua.NodeId, node_id: str, name: str
    ) -> ua.NodeId:
        double = {"DataType": ua.node_id(ua.ObjectIds.Double)}
        return await self._add(
            batch, parent, node_id, self._q(name), _ANALOG_UNIT, attributes=double
        )

    async def _controller(self, batch: NodeBatch, nodes: RobotNodes, path: str) -> None:
        for key, prop in (
            ("controller_manufacturer", "Manufacturer"),
            ("controller_model", "Model"),
            ("controller_product_code", "ProductCode"),
            ("controller_serial", "SerialNumber"),
            ("name", "ComponentName"),
        ):
            nodes.identity.setdefault(key, []).append(self._id(f"{path}.{prop}"))
        nodes.identity["user_level"] = [self._id(f"{path}.CurrentUser.Level")]
        sw_path = f"{path}.Software.KSS"
        await self._add(
            batch,
            self._id(f"{path}.Software"),
            sw_path,
            self._q("KSS"),
            ua.node_id(DI_IDS["SoftwareType"], self.di),
            optional=frozenset({"SoftwareRevision"}),
        )
        for key, prop in (
            ("software_manufacturer", "Manufacturer"),
            ("software_model", "Model"),
            ("software_revision", "SoftwareRevision"),
        ):
            nodes.identity.setdefault(key, []).append(self._id(f"{sw_path}.{prop}"))
        for key, label in (("robot", "RobotInterpreter"), ("submit", "SubmitInterpreter")):
            tc_path = f"{path}.TaskControls.{label}"
            await self._add(
                batch,
                self._id(f"{path}.TaskControls"),
                tc_path,
                self._q(label),
                _rid(self.ns, "TaskControlType"),
                optional=frozenset({"TaskControlOperation"}),
            )
            nodes.identity.setdefault(f"{key}_task_name", []).append(
                self._id(f"{tc_path}.ComponentName")
            )
            sm = f"{tc_path}.TaskControlOperation.TaskControlStateMachine"
            nodes.tasks[key] = TaskNodes(
                self._id(f"{tc_path}.ParameterSet.TaskProgramName"),
                self._id(f"{tc_path}.ParameterSet.TaskProgramLoaded"),
                self._id(f"{sm}.CurrentState"),
                self._id(f"{sm}.CurrentState.Id"),
                self._id(f"{sm}.LastTransition"),
                self._id(f"{sm}.LastTransition.Id"),
                self._id(f"{sm}.LastTransitionReason"),
            )
        params = self._id(f"{path}.ParameterSet")
        nodes.connected = await self._variable(
            batch, params, f"{path}.ParameterSet.Connected", "Connected", ua.ObjectIds.Boolean
        )

    async def _variable(
        self, batch: NodeBatch, parent: ua.NodeId, node_id: str, name: str, data_type: int
    ) -> ua.NodeId:
        return await self._add(
            batch,
            parent,
            node_id,
            self._q(name),
            _DATA_VARIABLE,
            attributes={"DataType": ua.node_id(data_type)},
        )

    async def _safety(self, batch: NodeBatch, nodes: RobotNodes, path: str) -> None:
        p = f"{path}.ParameterSet"
        nodes.scalars["mode"] = self._id(f"{p}.OperationalMode")
        nodes.scalars["estop"] = self._id(f"{p}.EmergencyStop")
        nodes.scalars["pstop"] = self._id(f"{p}.ProtectiveStop")
        functions = (
            ("EmergencyStopFunctions", "EmergencyStop", "EmergencyStopFunctionType", "estop_fn"),
            (
                "ProtectiveStopFunctions",
                "OperatorSafety",
                "ProtectiveStopFunctionType",
                "opsafe_fn",
            ),
            ("ProtectiveStopFunctions", "StopMessage", "ProtectiveStopFunctionType", "stopmess_fn"),
        )
        for folder, fname, tname, key in functions:
            f_path = f"{path}.{folder}.{fname}"
            await self._add(
                batch, self._id(f"{path}.{folder}"), f_path, self._q(fname), _rid(self.ns, tname)
            )
            nodes.identity.setdefault(f"{key}_name", []).append(self._id(f"{f_path}.Name"))
            nodes.scalars[f"{key}_active"] = self._id(f"{f_path}.Active")
            if tname == "ProtectiveStopFunctionType":
                nodes.scalars[f"{key}_enabled"] = self._id(f"{f_path}.Enabled")
