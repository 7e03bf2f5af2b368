"""A cloned robot (gateway/clone.py) is node for node what instantiating it from the types gives.

One asyncua server with the DI/IA/Robotics NodeSets (no sockets): robot ``a1`` instantiated
(the template), ``a2`` cloned from it, ``b1`` instantiated by a builder that never clones.
``a2`` and ``b1`` must have the same nodes, attributes (timestamps aside) and references, and
their parents the same references to them, once their names are set aside.
"""

from __future__ import annotations

from typing import Any

import pytest

asyncua = pytest.importorskip("asyncua")
from asyncua import Server, ua  # noqa: E402
from pyopenshowvar_apps.gateway.model import GATEWAY_URI, Instantiator, load_nodesets  # noqa: E402
from pyopenshowvar_apps.gateway.robotics import RobotBuilder, build_cell  # noqa: E402

pytestmark = [pytest.mark.asyncio, pytest.mark.timeout(120)]

EXTRAS = ("$OV_JOG", "MYAXIS")
ROOTS = ("cell.MotionDevices", "cell.Controllers", "cell.SafetyStates")


def _norm(value: Any, name: str, ns: int) -> Any:
    """A value with the robot's name set aside (NodeIds, browse and display names)."""
    if isinstance(value, ua.NodeId) and value.NamespaceIndex == ns:
        ident = value.Identifier
        if isinstance(ident, str):
            for root in ROOTS:
                if ident == f"{root}.{name}" or ident.startswith(f"{root}.{name}."):
                    return ("robot", root, ident[len(root) + len(name) + 1 :])
        return value
    if isinstance(value, ua.QualifiedName) and value.Name == name:
        return ("name", value.NamespaceIndex)
    if isinstance(value, ua.LocalizedText) and value.Text == name:
        return ("text", value.Locale)
    return value


def _dump(server: Server, name: str, ns: int) -> dict[Any, Any]:
    aspace = server.iserver.aspace
    out: dict[Any, Any] = {}
    for node_id in list(aspace.keys()):
        key = _norm(node_id, name, ns)
        data = aspace[node_id]
        refs = sorted(
            repr(
                (
                    r.ReferenceTypeId,
                    r.IsForward,
                    _norm(r.NodeId, name, ns),
                    _norm(r.BrowseName, name, ns),
                    _norm(r.DisplayName, name, ns),
                    r.NodeClass,
                    r.TypeDefinition,
                )
            )
            for r in data.references
            if _norm(r.NodeId, name, ns) != r.NodeId or key != node_id
        )
        if key == node_id:  # a node outside the robot: only its references to the robot
            if refs:
                out[("refs", node_id)] = refs
            continue
        attrs = {}
        for attr, av in data.attributes.items():
            dv = av.value
            variant = dv.Value if dv is not None else None
            value = _norm(variant.Value, name, ns) if variant is not None else None
            vtype = variant.VariantType if variant is not None else None
            attrs[attr] = (repr(value), vtype, dv.StatusCode if dv is not None else None)
        out[key] = (attrs, refs)
    return out


async def test_a_cloned_robot_equals_an_instantiated_one() -> None:
    server = Server()
    await server.init()
    try:
        ns = await load_nodesets(server)
        inst = Instantiator(server, ns[GATEWAY_URI])
        cell = await build_cell(server, inst, ns, "cell")
        cloning = RobotBuilder(server, inst, cell)
        await cloning.build("a1", EXTRAS)
        assert cloning.template is not None
        a2 = await cloning.build("a2", EXTRAS)
        b1 = await RobotBuilder(server, inst, cell, clone=False).build("b1", EXTRAS)
        ours = ns[GATEWAY_URI]
        cloned, instantiated = _dump(server, "a2", ours), _dump(server, "b1", ours)
        assert len(cloned) >= 200  # the whole robot, and its parents' references to it
        assert cloned == instantiated
        # the NodeIds the poller feeds are the same, name aside
        assert [_norm(n, "a2", ours) for n in a2.position] == [
            _norm(n, "b1", ours) for n in b1.position
        ]
        assert _norm(a2.extras["MYAXIS"], "a2", ours) == _norm(b1.extras["MYAXIS"], "b1", ours)
    finally:
        await server.stop()
