"""The nodes a robot's poller sets once per connection: its identity and what its model fixes.

Identity (OPC 40010-1's MotionDevice, Controller, Motor and Software identification) comes from
the robot's own ``$MODEL_NAME[]``, ``$KR_SERIALNO``, ``$ROBNAME[]`` and ``$RCV_INFO[]``
(:func:`~.mapping.identity_values`); what KVP cannot tell (the controller's and motors'
product codes and serial numbers) is left empty rather than made up. The rest is fixed by the
Robotics model: an articulated robot with rotary axes, the units of each axis variable, the
names of the task controls and of the safety functions.
"""

from __future__ import annotations

from collections.abc import Mapping
from datetime import datetime
from typing import Any

from . import ua
from .cellnodes import UNITS, RobotNodes
from .livenodes import Sink

__all__ = ["publish_identity", "publish_static"]

_V = ua.VariantType


async def publish_identity(
    nodes: RobotNodes, sink: Sink, ident: Mapping[str, Any], name: str, stamp: datetime
) -> None:
    """The identification nodes from ``ident`` (:func:`~.mapping.identity_values`); ``name``
    (the cell file's) when the robot has no ``$ROBNAME[]``."""
    strings = {
        "product_code": ident["product_code"],
        "serial": ident["serial"],
        "software_revision": ident["software_revision"],
        "controller_product_code": "",
        "controller_serial": "",
        "motor_product_code": "",
        "motor_serial": "",
        "user_level": "",
    }
    texts = {
        "manufacturer": "KUKA",
        "model": ident["model"],
        "name": ident["name"] or name,
        "controller_manufacturer": "KUKA",
        "controller_model": "KUKA Robot Controller (KRC)",
        "motor_manufacturer": "KUKA",
        "motor_model": "",
        "software_manufacturer": "KUKA",
        "software_model": "KUKA System Software",
    }
    for key, value in strings.items():
        for node in nodes.identity.get(key, []):
            await sink.set(node, value, _V.String, stamp)
    for key, value in texts.items():
        for node in nodes.identity.get(key, []):
            await sink.set(node, ua.LocalizedText(value), _V.LocalizedText, stamp)


async def publish_static(nodes: RobotNodes, sink: Sink, stamp: datetime) -> None:
    """Values fixed by the model: category, motion profiles, units, task names."""
    n, s = nodes, sink
    for node in n.identity.get("category", []):
        await s.set(node, 1, _V.Int32, stamp)  # ARTICULATED_ROBOT
    for node in n.identity.get("motion_profile", []):
        await s.set(node, 1, _V.Int32, stamp)  # ROTARY
    tasks = nodes.tasks
    if n.identity.get("task_reference") and "robot" in tasks:
        robot_task = tasks["robot"].program_name
        tc = ua.node_id(
            ua.path_of(robot_task).rsplit(".ParameterSet.", 1)[0], robot_task.NamespaceIndex
        )
        await s.set(n.identity["task_reference"][0], tc, _V.NodeId, stamp)
    for key, label in (
        ("robot_task_name", "Robot interpreter ($PRO_STATE1)"),
        ("submit_task_name", "Submit interpreter ($PRO_STATE0)"),
    ):
        for node in n.identity.get(key, []):
            await s.set(node, ua.LocalizedText(label), _V.LocalizedText, stamp)
    for task in tasks.values():  # 0 = Unknown: KVP cannot tell who changed the state
        await s.set(task.last_transition_reason, 0, _V.Int16, stamp)
    for key, label in (
        ("estop_fn_name", "$ALARM_STOP"),
        ("opsafe_fn_name", "$USER_SAF"),
        ("stopmess_fn_name", "$STOPMESS"),
    ):
        for node in n.identity.get(key, []):
            await s.set(node, label, _V.String, stamp)
    for unit, axis_nodes in (
        ("deg", n.position),
        ("deg/s", n.speed),
        ("Nm", n.torque),
        ("%", n.current),
        ("degC", n.temperature),
    ):
        for node in axis_nodes:
            eu = ua.node_id(f"{ua.path_of(node)}.EngineeringUnits", node.NamespaceIndex)
            await s.set(eu, UNITS[unit], _V.ExtensionObject, stamp)
