"""The second and later robots of a cell: copies of the first robot's nodes under a new name.

Instantiating a robot from the Robotics types (:class:`~.model.Instantiator`, then asyncua's
AddNodes service) makes about 200 nodes of two dozen attributes each and checks every one of
them on the way: some 50-70 ms of CPU per robot, seconds for a 50-robot cell. Every robot of
a cell gets the same nodes apart from its name (its extra variables and its WriteVariable
method are added afterwards, the normal way), so only the first robot is instantiated. Right
after its nodes are committed, :meth:`RobotTemplate.capture` takes a copy of them (attributes
and references), and :meth:`RobotTemplate.stamp` puts that copy into the address space for
each further robot, with every NodeId inside the robot and the three roots' names changed.
The result is node for node what instantiating would give (tests/test_gateway_clone.py
compares the two).

Attribute values are shared between the copies, as instantiation shares the type's values
with every instance: asyncua replaces a value on a write and never changes one in place.
References are copied, because asyncua does change those in place (a renamed node's
reference descriptions).
"""

from __future__ import annotations

from dataclasses import dataclass

from asyncua.server.address_space import AddressSpace, AttributeValue, NodeData

from . import ua
from .ua import Server

__all__ = ["RobotTemplate"]

_NAMES = (ua.AttributeIds.BrowseName, ua.AttributeIds.DisplayName)


@dataclass(frozen=True)
class _Node:
    root: int  # index into the template's roots
    suffix: str  # the identifier after the root's ("" for the root itself)
    attributes: tuple[tuple[ua.AttributeIds, ua.DataValue | None], ...]
    references: tuple[ua.ReferenceDescription, ...]


class RobotTemplate:
    """One robot's nodes, frozen right after they were built (see the module doc)."""

    def __init__(self, ns: int, roots: list[str], name: str, nodes: list[_Node]) -> None:
        self.ns, self.roots, self.name, self.nodes = ns, roots, name, nodes
        self._inside = {roots[n.root] + n.suffix: n for n in nodes}

    @classmethod
    def capture(cls, server: Server, roots: list[ua.NodeId], name: str) -> RobotTemplate:
        """Copy every node under ``roots`` (string NodeIds of one namespace, named ``name``)."""
        aspace = server.iserver.aspace
        prefixes = [str(r.Identifier) for r in roots]
        ns = roots[0].NamespaceIndex
        nodes: list[_Node] = []
        for node_id in list(aspace.keys()):
            ident = node_id.Identifier
            if node_id.NamespaceIndex != ns or not isinstance(ident, str):
                continue
            for index, prefix in enumerate(prefixes):
                if ident == prefix or ident.startswith(prefix + "."):
                    data = aspace[node_id]
                    attrs = tuple((a, v.value) for a, v in data.attributes.items())
                    refs = tuple(_copy_ref(r) for r in data.references)
                    nodes.append(_Node(index, ident[len(prefix) :], attrs, refs))
                    break
        return cls(ns, prefixes, name, nodes)

    def stamp(self, server: Server, roots: list[ua.NodeId], name: str) -> None:
        """Add a copy of the template under ``roots`` (same order as captured), named ``name``.

        The roots' parents (the cell's three folders) get their forward references to the new
        roots, as AddNodes would have added them.
        """
        aspace = server.iserver.aspace
        prefixes = [str(r.Identifier) for r in roots]
        if len(prefixes) != len(self.roots):
            raise ValueError("a robot template is stamped with as many roots as it has")
        for prefix in prefixes:
            if ua.node_id(prefix, self.ns) in aspace:
                raise ValueError(f"{prefix} already exists")
        for node in self.nodes:
            new_id = ua.node_id(prefixes[node.root] + node.suffix, self.ns)
            data = NodeData(new_id)
            for attr, dv in node.attributes:
                if attr == ua.AttributeIds.NodeId:
                    dv = ua.DataValue(ua.Variant(new_id, ua.VariantType.NodeId))
                elif node.suffix == "" and attr in _NAMES:
                    dv = self._renamed_value(dv, name)
                # asyncua's AttributeValue holds a DataValue | None; its __init__ says DataValue
                data.attributes[attr] = AttributeValue(dv)  # type: ignore[arg-type]
            data.references = [self._moved(r, prefixes, name) for r in node.references]
            aspace[new_id] = data
        for index, root in enumerate(roots):
            self._link_parent(aspace, index, root, name)

    # ------------------------------------------------------------------ renaming

    def _target(self, node_id: ua.NodeId) -> _Node | None:
        if node_id.NamespaceIndex != self.ns or not isinstance(node_id.Identifier, str):
            return None
        return self._inside.get(node_id.Identifier)

    def _moved(
        self, ref: ua.ReferenceDescription, prefixes: list[str], name: str
    ) -> ua.ReferenceDescription:
        new = _copy_ref(ref)
        target = self._target(ref.NodeId)
        if target is not None:
            new.NodeId = ua.node_id(prefixes[target.root] + target.suffix, self.ns)
            if target.suffix == "":
                self._rename_ref(new, name)
        return new

    def _rename_ref(self, ref: ua.ReferenceDescription, name: str) -> None:
        if ref.BrowseName is not None and ref.BrowseName.Name == self.name:
            ref.BrowseName = ua.QualifiedName(name, ref.BrowseName.NamespaceIndex)
        if ref.DisplayName is not None and ref.DisplayName.Text == self.name:
            ref.DisplayName = ua.LocalizedText(name, ref.DisplayName.Locale)

    def _renamed_value(self, dv: ua.DataValue | None, name: str) -> ua.DataValue | None:
        value = dv.Value.Value if dv is not None and dv.Value is not None else None
        if isinstance(value, ua.QualifiedName) and value.Name == self.name:
            renamed = ua.QualifiedName(name, value.NamespaceIndex)
            return ua.DataValue(ua.Variant(renamed, ua.VariantType.QualifiedName))
        if isinstance(value, ua.LocalizedText) and value.Text == self.name:
            text = ua.LocalizedText(name, value.Locale)
            return ua.DataValue(ua.Variant(text, ua.VariantType.LocalizedText))
        return dv

    def _link_parent(self, aspace: AddressSpace, index: int, root: ua.NodeId, name: str) -> None:
        """The parent's forward reference to a new root: a copy of the one to the template's."""
        template_root = ua.node_id(self.roots[index], self.ns)
        for ref in self._inside[self.roots[index]].references:
            if ref.IsForward or self._target(ref.NodeId) is not None:
                continue  # the root's inverse reference from outside names its parent
            parent = aspace[ref.NodeId]
            for down in list(parent.references):
                if down.IsForward and down.NodeId == template_root:
                    new = _copy_ref(down)
                    new.NodeId = root
                    self._rename_ref(new, name)
                    parent.references.append(new)


def _copy_ref(ref: ua.ReferenceDescription) -> ua.ReferenceDescription:
    # every field given: the defaults would build five throw-away objects per reference
    return ua.ReferenceDescription(
        ReferenceTypeId=ref.ReferenceTypeId,
        IsForward=ref.IsForward,
        NodeId=ref.NodeId,
        BrowseName=ref.BrowseName,
        DisplayName=ref.DisplayName,
        NodeClass=ref.NodeClass,
        TypeDefinition=ref.TypeDefinition,
    )
