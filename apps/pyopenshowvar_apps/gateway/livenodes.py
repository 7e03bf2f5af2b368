"""The values the pollers feed into the address space, published lazily.

The hot path of the gateway: a moving robot changes two dozen node values per poll, 500 polls a
second in a 50-robot cell. Writing each through asyncua's ``write_attribute_value`` builds a
Variant and a DataValue and runs its checks for every value, although almost all of them are
never looked at before the next poll replaces them. So each fed node is a :class:`LiveNode`:

* the value, its Variant type, status and timestamp are plain attributes, set by the poller;
* the node's Value attribute gets a *value callback* (asyncua's
  ``Server.set_attribute_value_callback``): a Read builds the DataValue from them when a client
  asks, once per change (it is cached until the value changes again);
* a node some client subscribed to (asyncua registers a *datachange callback* on its Value
  attribute for every monitored item) gets its DataValue built at once and handed to those
  callbacks, exactly as ``write_attribute_value`` would hand it.

A value equal to the last one (and the same status) is dropped before anything is built. The
nodes' DataType, AccessLevel and everything else stay as the model built them; only the Value
attribute is served this way, and nothing else in the gateway writes those nodes' values.
"""

from __future__ import annotations

import logging
from datetime import datetime
from typing import Any

from . import ua
from .ua import Server

__all__ = ["LiveNode", "Sink"]

log = logging.getLogger(__name__)

_VALUE = ua.AttributeIds.Value
_GOOD = ua.status_code(ua.StatusCodes.Good)
_NULL = ua.VariantType.Null
_MISSING = object()


class _SharedDataValue(ua.DataValue):
    """A DataValue nobody changes after it was built: deep copies of it are itself.

    asyncua deep-copies every value it hands to a monitored item (to compare the next one
    with), about as costly as building the value; a LiveNode's DataValues are never changed
    in place (a change builds a new one), so the copy would only burn CPU.
    """

    __slots__ = ()

    def __deepcopy__(self, memo: dict[int, Any]) -> _SharedDataValue:
        return self


class LiveNode:
    """One Value attribute fed by a poller (see the module doc)."""

    __slots__ = ("_callbacks", "_dv", "node_id", "stamp", "status", "value", "vtype")

    def __init__(self, node_id: ua.NodeId, callbacks: dict[int, Any]) -> None:
        self.node_id = node_id
        #: asyncua's datachange callbacks of this attribute: one per monitored item (the
        #: dict asyncua itself adds to and removes from, so a new subscription is seen at once)
        self._callbacks = callbacks
        self.value: Any = _MISSING
        self.vtype = _NULL
        self.status = _GOOD
        self.stamp: datetime | None = None
        self._dv: ua.DataValue | None = None

    def datavalue(self, *_: Any) -> ua.DataValue:
        """The current DataValue (asyncua's value callback: called for every Read)."""
        dv = self._dv
        if dv is None:
            if self.status is _GOOD and self.value is not _MISSING:
                variant = ua.Variant(self.value, self.vtype, is_array=False)
            else:
                # OPC 10000-4 §7.7.1: a Bad value is null (asyncua's write does the same)
                variant = ua.Variant(None, _NULL)
            stamp = ua.timestamp(self.stamp)
            dv = self._dv = _SharedDataValue(
                variant, self.status, SourceTimestamp=stamp, ServerTimestamp=stamp
            )
        return dv

    @property
    def subscribed(self) -> bool:
        """Some client monitors this node: a change must be handed on at once."""
        return bool(self._callbacks)

    def update(self, value: Any, vtype: ua.VariantType, stamp: datetime) -> bool:
        """Store a Good value; False (and nothing stored) when it did not change."""
        if value == self.value and self.status is _GOOD:
            return False
        self.value, self.vtype, self.stamp, self.status = value, vtype, stamp, _GOOD
        self._dv = None
        return True

    def update_bad(self, code: int, stamp: datetime) -> bool:
        """Store a Bad status (the value becomes null); False when it was already that."""
        if self.status is not _GOOD and self.status.value == code:
            return False
        self.value, self.stamp, self.status = _MISSING, stamp, ua.status_code(code)
        self._dv = None
        return True

    async def notify(self) -> None:
        """Hand the new DataValue to every monitored item of this node."""
        dv = self.datavalue()
        # a copy: a subscription deleted by a callback must not break the iteration
        for handle, callback in list(self._callbacks.items()):
            try:
                await callback(handle, dv)
            except Exception:  # one broken subscription must not stop the poller
                log.exception("datachange callback of %s failed", self.node_id.to_string())


class Sink:
    """The :class:`LiveNode` of every fed node, created on first use; counts what changed."""

    def __init__(self, server: Server) -> None:
        self.server = server
        self._aspace = server.iserver.aspace
        self._live: dict[Any, LiveNode] = {}
        self._typed: set[Any] = set()
        self._pending: list[LiveNode] = []
        #: changed values stored (a monitoring figure for tests and benchmarks)
        self.writes = 0

    def live(self, node: ua.NodeId) -> LiveNode:
        """The node's LiveNode; the first call installs the value callback."""
        # keyed by the string identifier, whose hash Python caches (a NodeId hashes a tuple)
        found = self._live.get(node.Identifier)
        if found is not None:
            return found
        data = self._aspace.get(node)
        if data is None or _VALUE not in data.attributes:
            raise KeyError(f"no variable {node.to_string()} in the address space")
        live = LiveNode(node, data.attributes[_VALUE].datachange_callbacks)
        self.server.set_attribute_value_callback(node, live.datavalue)
        self._live[node.Identifier] = live
        return live

    def put(self, live: LiveNode, value: Any, vtype: ua.VariantType, ts: datetime) -> None:
        """The hot path (``live`` resolved once by the caller): store, and remember the node
        for :meth:`flush` when a client subscribed to it."""
        if live.update(value, vtype, ts):
            self.writes += 1
            if live.subscribed:
                self._pending.append(live)

    async def flush(self) -> None:
        """Tell the subscribers of every node :meth:`put` changed since the last flush."""
        pending, self._pending = self._pending, []
        for live in pending:
            await live.notify()

    async def set(self, node: ua.NodeId, value: Any, vtype: ua.VariantType, ts: datetime) -> None:
        """:meth:`put` and :meth:`flush` for one node (the paths that are not hot)."""
        self.put(self.live(node), value, vtype, ts)
        await self.flush()

    async def set_typed(
        self, node: ua.NodeId, value: Any, vtype: ua.VariantType, ts: datetime
    ) -> None:
        """For a BaseDataType node: fix its DataType to ``vtype`` the first time, then set."""
        if node.Identifier not in self._typed:
            self._typed.add(node.Identifier)
            dt = ua.DataValue(ua.Variant(ua.node_id(vtype.value), ua.VariantType.NodeId))
            await self._aspace.write_attribute_value(node, ua.AttributeIds.DataType, dt)
        await self.set(node, value, vtype, ts)

    async def bad(self, node: ua.NodeId, code: int, ts: datetime) -> None:
        live = self.live(node)
        if live.update_bad(code, ts) and live.subscribed:
            self._pending.append(live)
        await self.flush()
