"""The OPC UA information model: the standard NodeSets, and instances built from their types.

:func:`load_nodesets` imports the shipped DI, IA and Robotics NodeSet2 files (OPC Foundation,
see ``nodesets/LICENSE.txt``) with asyncua's XML importer, so every type, browse name and
namespace URI is the specification's own. Nodes marked ``DesignToolOnly`` are left out, as the
NodeSet schema asks of servers (DI 1.05 has nine, which asyncua cannot place).

:class:`Instantiator` creates instances the way OPC 10000-3 §6.4 describes: an instance gets
every child of its TypeDefinition (and the supertypes) whose ModellingRule is Mandatory, the
Optional children the caller names by relative path, and no placeholder (the caller adds the
robots, axes, ... that fill a placeholder, each with the placeholder's TypeDefinition). The
children of an instance declaration are its own plus those of its TypeDefinition. Plans are
cached per type, and one robot's nodes are added in one AddNodes call, so 50 robots take well
under a second. Node ids are strings: the dotted browse path from the MotionDeviceSystem, e.g.
``cell.MotionDevices.r1.Axes.A1.ParameterSet.ActualPosition`` — stable for SCADA tag lists.
"""

from __future__ import annotations

import logging
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from importlib import resources
from typing import Any

from . import ua
from .ua import Server

__all__ = [
    "DI_URI",
    "GATEWAY_URI",
    "IA_URI",
    "NODESET_FILES",
    "ROBOTICS_URI",
    "Decl",
    "Instantiator",
    "NodeBatch",
    "load_nodesets",
]

log = logging.getLogger(__name__)

DI_URI = "http://opcfoundation.org/UA/DI/"
IA_URI = "http://opcfoundation.org/UA/IA/"
ROBOTICS_URI = "http://opcfoundation.org/UA/Robotics/"
#: Our own namespace: the instances and the parameters the Robotics model leaves to vendors.
GATEWAY_URI = "urn:pyopenshowvar:kvp-gateway"
NODESET_FILES = ("Opc.Ua.Di.NodeSet2.xml", "Opc.Ua.IA.NodeSet2.xml", "Opc.Ua.Robotics.NodeSet2.xml")

_MANDATORY = ua.node_id(ua.ObjectIds.ModellingRule_Mandatory)
_OPTIONAL = ua.node_id(ua.ObjectIds.ModellingRule_Optional)
_PLACEHOLDERS = {
    ua.node_id(ua.ObjectIds.ModellingRule_MandatoryPlaceholder),
    ua.node_id(ua.ObjectIds.ModellingRule_OptionalPlaceholder),
}
_HAS_COMPONENT = ua.node_id(ua.ObjectIds.HasComponent)


def _nodeset_text(name: str) -> str:
    text = (
        resources.files(__package__).joinpath("nodesets").joinpath(name).read_text(encoding="utf-8")
    )
    root = ET.fromstring(text)
    design_only = [n for n in root if n.get("DesignToolOnly") == "true"]
    if not design_only:
        return text
    for node in design_only:
        root.remove(node)
    ET.register_namespace("", root.tag[1:].split("}")[0])
    return ET.tostring(root, encoding="unicode")


async def load_nodesets(server: Server) -> dict[str, int]:
    """Import DI, IA and Robotics; returns the namespace index of each URI (and ours)."""
    started = time.perf_counter()
    importer_log = logging.getLogger("asyncua.common.xmlimporter")
    # asyncua warns about every forward reference it re-parents; the NodeSets are the OPC
    # Foundation's and import completely, so those warnings would only be noise at start-up.
    level = importer_log.level
    importer_log.setLevel(logging.ERROR)
    try:
        for name in NODESET_FILES:
            await server.import_xml(xmlstring=_nodeset_text(name))
    finally:
        importer_log.setLevel(level)
    ours = await server.register_namespace(GATEWAY_URI)
    array = await server.get_namespace_array()
    log.info("loaded the DI, IA and Robotics NodeSets in %.2f s", time.perf_counter() - started)
    indexes = {uri: array.index(uri) for uri in (DI_URI, IA_URI, ROBOTICS_URI)}
    indexes[GATEWAY_URI] = ours
    return indexes


@dataclass(frozen=True)
class Decl:
    """One child an instance may get: the declaration node and how it hangs off its parent."""

    source: ua.NodeId
    browse_name: ua.QualifiedName
    node_class: ua.NodeClass
    reference: ua.NodeId
    type_definition: ua.NodeId
    rule: ua.NodeId | None


class NodeBatch:
    """AddNodes items collected for one call (parents always before their children).

    A ``dry`` batch collects nothing: the builder walks the model only for the NodeIds (the
    nodes themselves come from a :class:`~.clone.RobotTemplate`).
    """

    def __init__(self, *, dry: bool = False) -> None:
        self.dry = dry
        self.items: list[ua.AddNodesItem] = []
        self.references: list[ua.AddReferencesItem] = []

    def reference(self, source: ua.NodeId, ref: ua.NodeId, target: ua.NodeId) -> None:
        if self.dry:
            return
        item = ua.AddReferencesItem()
        item.SourceNodeId, item.ReferenceTypeId, item.TargetNodeId = source, ref, target
        item.IsForward = True
        self.references.append(item)


class Instantiator:
    """Builds instances of the loaded types into a :class:`NodeBatch` (see the module doc)."""

    def __init__(self, server: Server, ns: int) -> None:
        self.server = server
        self.session = server.iserver.isession
        self.ns = ns
        self._plans: dict[tuple[ua.NodeId, bool], list[Decl]] = {}
        self._attrs: dict[ua.NodeId, tuple[ua.NodeClass, dict[str, Any]]] = {}

    async def children(self, node: ua.NodeId, *, is_type: bool) -> list[Decl]:
        """The declarations an instance of ``node`` (a type or a declaration) may have."""
        key = (node, is_type)
        plan = self._plans.get(key)
        if plan is not None:
            return plan
        own: list[Decl] = []
        if is_type:
            for t in await self._supertypes(node):
                own += [
                    d for d in await self._declared(t) if _key(d.browse_name) not in _names(own)
                ]
        else:
            own = await self._declared(node)
            tdef = await self._type_of(node)
            if tdef is not None:
                inherited = await self.children(tdef, is_type=True)
                own += [d for d in inherited if _key(d.browse_name) not in _names(own)]
        self._plans[key] = own
        return own

    async def add(
        self,
        batch: NodeBatch,
        parent: ua.NodeId,
        node_id: str,
        browse_name: ua.QualifiedName,
        type_definition: ua.NodeId,
        *,
        reference: ua.NodeId = _HAS_COMPONENT,
        optional: frozenset[str] = frozenset(),
        source: ua.NodeId | None = None,
        attributes: dict[str, Any] | None = None,
    ) -> ua.NodeId:
        """Add an instance of ``type_definition`` (attributes from ``source``, default the type).

        ``optional`` names the Optional children to create, as relative browse paths
        ("ParameterSet/ActualSpeed"); Mandatory children are always created. ``attributes``
        overrides attributes of the new node (e.g. a concrete DataType for an AnalogUnitType).
        """
        new_id = ua.node_id(node_id, self.ns)
        template = source if source is not None else type_definition
        item = await self._item(template, type_definition, parent, reference, new_id, browse_name)
        # an instance is named after itself, not after its type or the placeholder it fills
        # (a client's tree shows the DisplayName: "r1", never "MotionDeviceType")
        set_attributes(item.NodeAttributes, {"DisplayName": ua.LocalizedText(browse_name.Name)})
        if attributes:
            set_attributes(item.NodeAttributes, attributes)
        batch.items.append(item)
        decls = await self.children(template, is_type=source is None)
        await self._add_children(batch, new_id, node_id, decls, optional, "")
        return new_id

    async def _add_children(
        self,
        batch: NodeBatch,
        parent: ua.NodeId,
        parent_path: str,
        decls: list[Decl],
        optional: frozenset[str],
        rel: str,
    ) -> None:
        for d in decls:
            path = f"{rel}/{d.browse_name.Name}" if rel else d.browse_name.Name
            if d.rule in _PLACEHOLDERS or d.rule is None:
                continue
            if d.rule == _OPTIONAL and path not in optional:
                continue
            if d.node_class == ua.NodeClass.Method:
                # Instances share the type's method node (OPC 10000-3 §6.4.4.4).
                batch.reference(parent, d.reference, d.source)
                continue
            node_id = f"{parent_path}.{d.browse_name.Name}"
            new_id = ua.node_id(node_id, self.ns)
            item = await self._item(
                d.source, d.type_definition, parent, d.reference, new_id, d.browse_name
            )
            batch.items.append(item)
            sub = await self.children(d.source, is_type=False)
            await self._add_children(batch, new_id, node_id, sub, optional, path)

    async def _item(
        self,
        template: ua.NodeId,
        type_definition: ua.NodeId,
        parent: ua.NodeId,
        reference: ua.NodeId,
        new_id: ua.NodeId,
        browse_name: ua.QualifiedName,
    ) -> ua.AddNodesItem:
        node_class, attrs = await self._attributes(template)
        item = ua.AddNodesItem()
        item.RequestedNewNodeId = new_id
        item.BrowseName = browse_name
        item.ParentNodeId = parent
        item.ReferenceTypeId = reference
        item.TypeDefinition = type_definition
        item.NodeClass = (
            ua.NodeClass.Object
            if node_class in (ua.NodeClass.Object, ua.NodeClass.ObjectType)
            else ua.NodeClass.Variable
        )
        item.NodeAttributes = _copy(attrs, item.NodeClass, browse_name)
        return item

    async def _attributes(self, node: ua.NodeId) -> tuple[ua.NodeClass, dict[str, Any]]:
        cached = self._attrs.get(node)
        if cached is not None:
            return cached
        n = self.server.get_node(node)
        node_class = await n.read_node_class()
        names = ["DisplayName", "Description"]
        if node_class in (ua.NodeClass.Object, ua.NodeClass.ObjectType):
            names += ["EventNotifier"] if node_class == ua.NodeClass.Object else []
        else:
            names += ["DataType", "ValueRank", "ArrayDimensions", "AccessLevel", "Value"]
            names += ["MinimumSamplingInterval"] if node_class == ua.NodeClass.Variable else []
        ids = [getattr(ua.AttributeIds, a) for a in names]
        values = await n.read_attributes(ids)
        attrs = {
            name: (dv if name == "Value" else ua.variant_of(dv).Value)
            for name, dv in zip(names, values, strict=True)
            if dv.StatusCode is None or dv.StatusCode.is_good()
        }
        self._attrs[node] = (node_class, attrs)
        return node_class, attrs

    async def _supertypes(self, type_id: ua.NodeId) -> list[ua.NodeId]:
        chain = [type_id]
        node = self.server.get_node(type_id)
        while True:
            parents = await node.get_referenced_nodes(
                refs=ua.ObjectIds.HasSubtype, direction=ua.BrowseDirection.Inverse
            )
            if not parents:
                return chain
            node = parents[0]
            chain.append(node.nodeid)

    async def _type_of(self, node: ua.NodeId) -> ua.NodeId | None:
        refs = await self.server.get_node(node).get_references(
            refs=ua.ObjectIds.HasTypeDefinition, direction=ua.BrowseDirection.Forward
        )
        return refs[0].NodeId if refs else None

    async def _declared(self, node: ua.NodeId) -> list[Decl]:
        """The children ``node`` declares itself, with their modelling rules."""
        refs = await self.server.get_node(node).get_references(
            refs=ua.ObjectIds.HierarchicalReferences,
            direction=ua.BrowseDirection.Forward,
            includesubtypes=True,
        )
        out: list[Decl] = []
        seen: set[ua.NodeId] = set()
        for r in refs:
            # The importer can record a reference both from the parent and from the child.
            if r.NodeId in seen or r.ReferenceTypeId == ua.node_id(ua.ObjectIds.HasSubtype):
                continue
            seen.add(r.NodeId)
            if r.NodeClass not in (ua.NodeClass.Object, ua.NodeClass.Variable, ua.NodeClass.Method):
                continue
            rules = await self.server.get_node(r.NodeId).get_referenced_nodes(
                refs=ua.ObjectIds.HasModellingRule
            )
            rule = rules[0].nodeid if rules else None
            tdef = r.TypeDefinition if r.NodeClass != ua.NodeClass.Method else ua.node_id()
            out.append(Decl(r.NodeId, r.BrowseName, r.NodeClass, r.ReferenceTypeId, tdef, rule))
        return out


def _names(decls: list[Decl]) -> set[tuple[int, str]]:
    return {_key(d.browse_name) for d in decls}


def _key(name: ua.QualifiedName) -> tuple[int, str]:
    return (name.NamespaceIndex, name.Name)


def _copy(attrs: dict[str, Any], node_class: ua.NodeClass, name: ua.QualifiedName) -> Any:
    out: Any = (
        ua.ObjectAttributes() if node_class == ua.NodeClass.Object else ua.VariableAttributes()
    )
    given: dict[str, Any] = {"DisplayName": attrs.get("DisplayName") or ua.LocalizedText(name.Name)}
    if attrs.get("Description") is not None:
        given["Description"] = attrs["Description"]
    if node_class == ua.NodeClass.Object:
        given["EventNotifier"] = attrs.get("EventNotifier", 0)
    else:
        given["DataType"] = attrs.get("DataType", ua.node_id(ua.ObjectIds.BaseDataType))
        given["ValueRank"] = attrs.get("ValueRank", -1)
        if attrs.get("ArrayDimensions"):
            given["ArrayDimensions"] = attrs["ArrayDimensions"]
        # Everything we serve is read-only: writes go through the WriteVariable method.
        given["AccessLevel"] = given["UserAccessLevel"] = ua.AccessLevel.CurrentRead.mask
        value = attrs.get("Value")
        if value is not None and value.Value is not None and value.Value.Value is not None:
            given["Value"] = value.Value
    set_attributes(out, given)
    return out


def set_attributes(out: Any, given: dict[str, Any]) -> None:
    """Set node attributes and flag them in SpecifiedAttributes (asyncua reads only those)."""
    for key, value in given.items():
        setattr(out, key, value)
        out.SpecifiedAttributes |= getattr(ua.NodeAttributesMask, key)
