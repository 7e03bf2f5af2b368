"""One task per robot: connect, read everything in one pipelined batch per poll, publish.

Each poll is ONE :meth:`Client.read_many` of :data:`~.mapping.POLL_VARIABLES` (the slow ones,
:data:`~.mapping.SLOW_VARIABLES`, every fifth poll), the cell file's extra variables and its
snapshot groups (a snapshot group is one read of a STRUC the controller fills, fanned out to
its member variables). Only texts that changed since the last
poll are parsed (the moving robot's fixed-format texts by the parser's fast paths), and only
node values that changed are stored (:mod:`.livenodes`: a DataValue is built only for a client
that reads or subscribes), so a robot at rest costs the event loop almost nothing beyond the KVP
round trip. Every value carries the time the reply arrived as its SourceTimestamp. No robot
can take the event loop from the others (:mod:`.budget`): a value longer than the robot's
``max_value_chars`` is not parsed, parsing hands the loop back every couple of milliseconds,
and a robot whose parsing takes more than its share of the loop is polled less often.

A robot that drops (connection lost, timeout, refused connection) turns all its live nodes
Bad (BadNoCommunication, the value null, as OPC 10000-4 §7.7.1 asks) and ``Connected`` FALSE;
the task retries with a capped backoff and the nodes turn Good with the first poll after it
reconnects. The poll schedule is absolute (missed periods are skipped, never bunched) and
shared: every robot polls on a grid of the event loop's clock (:mod:`.schedule`), in one of a
few slots per period (its ``phase``), so a cell's polls are spread evenly and a slot's robots
wake at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import re
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from typing import Any

from pyopenshowvar import Client, KvpError, Struct, UnknownVariableError

from ..armpick import DEFAULT_CHOICE, choose_arm, given_arm
from . import ua
from .budget import ValueTooLongError, WorkBudget
from .cell import RobotConfig, SnapshotGroup, canonical
from .cellnodes import CellNodes, RobotNodes
from .fixednodes import publish_identity, publish_static
from .livenodes import LiveNode, Sink
from .mapping import (
    IDENTITY_VARIABLES,
    POLL_VARIABLES,
    SLOW_EVERY,
    SLOW_VARIABLES,
    identity_values,
    poll_values,
    text_of,
)
from .schedule import next_slot, sleep_until
from .values import SCALAR_TYPES, parse_text, variant_of

__all__ = ["RobotPoller"]

log = logging.getLogger(__name__)

BACKOFF_MIN, BACKOFF_MAX = 0.25, 2.0
_V = ua.VariantType
_MISSING = object()


class RobotPoller:
    """Polls one robot over KVP and keeps its nodes current (see the module doc)."""

    def __init__(
        self,
        cfg: RobotConfig,
        nodes: RobotNodes,
        cell: CellNodes,
        sink: Sink,
        max_speed: Sequence[float] | None = None,
        phase: float = 0.0,
    ) -> None:
        self.cfg, self.nodes, self.cell, self.sink = cfg, nodes, cell, sink
        #: where in each poll period this robot's polls fall, 0 <= phase < 1 (see next_slot)
        self.phase = phase
        #: The arm drawn on the MotionDevice (its model, axis speeds and ranges): ``cfg.arm``,
        #: else the one $MODEL_NAME[] names, chosen at each connection (see _identity).
        self.given = given_arm(cfg.arm) if cfg.arm else None
        self.arm = self.given or DEFAULT_CHOICE
        self.fixed_speed = tuple(max_speed) if max_speed is not None else None
        self.max_speed = self.fixed_speed or tuple(float(s) for s in self.arm.model.max_speed)
        self.client: Client | None = None
        self.connected = False
        self.polls = 0
        self.last_error = ""
        self._texts: dict[str, str] = {}
        self._values: dict[str, Any] = {}
        self._states: dict[str, str] = {}
        self._snap_members = {canonical(m) for s in cfg.snapshots for m in s.members}
        # snapshot members are stored under the name the poll would have used
        self._alias = {canonical(n): n for n in (*POLL_VARIABLES, *cfg.exposed)}
        self._stop = asyncio.Event()
        # the nodes of the hot path, resolved once: per-axis arrays and the scalars
        live = sink.live
        self._arrays: list[tuple[str, list[LiveNode]]] = [
            (key, [live(node) for node in getattr(nodes, key)])
            for key in ("position", "speed", "torque", "current", "temperature")
        ]
        self._scalars = [
            (key, live(nodes.scalars[key]), vtype)
            for key, vtype in SCALAR_TYPES
            if key in nodes.scalars
        ]
        self._connected = None if nodes.connected is None else live(nodes.connected)
        self.budget = WorkBudget(cfg.name)

    # ------------------------------------------------------------------ lifecycle

    async def run(self) -> None:
        """Poll until :meth:`stop`; reconnects on its own after any connection problem."""
        backoff = BACKOFF_MIN
        await self._mark_bad(ua.StatusCodes.BadWaitingForInitialData)
        while not self._stop.is_set():
            try:
                await self._session()
                backoff = BACKOFF_MIN
            except (KvpError, OSError, TimeoutError) as exc:
                # jitter keeps 50 robots behind one switch from reconnecting in lockstep
                delay = backoff * (0.8 + 0.4 * random.random())
                if self.connected or _reason(exc) != self.last_error:  # news only
                    log.warning(
                        "robot %s (%s:%d): %s; reconnecting in %.1f s",
                        self.cfg.name, self.cfg.host, self.cfg.port, _reason(exc), delay,
                    )  # fmt: skip
                self.last_error = _reason(exc) or type(exc).__name__
            except Exception as exc:  # a bug must not leave a robot's nodes Good and frozen
                delay = backoff * (0.8 + 0.4 * random.random())
                log.exception("robot %s: poller failed; reconnecting", self.cfg.name)
                self.last_error = repr(exc)
            finally:
                await self._disconnect()
            if self._stop.is_set():
                break
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._stop.wait(), delay)
            backoff = min(backoff * 2, BACKOFF_MAX)

    def stop(self) -> None:
        """Ask :meth:`run` to end; the owner then cancels the task if it sleeps."""
        self._stop.set()

    async def _disconnect(self) -> None:
        was = self.connected
        self.connected = False
        client, self.client = self.client, None
        if client is not None:
            with contextlib.suppress(Exception):
                await client.close()
        if was or self.polls == 0:
            await self._mark_bad(ua.StatusCodes.BadNoCommunication)

    async def _session(self) -> None:
        cfg = self.cfg
        client = Client(
            cfg.host, cfg.port, timeout=cfg.timeout, connect_timeout=cfg.timeout, keepalive=None
        )
        self.client = client
        await client.connect()
        self.budget.reset_warning()
        names = await self._identity(client)
        self.connected = True
        self.last_error = ""
        log.info("robot %s connected (%s:%d)", cfg.name, cfg.host, cfg.port)
        period = 1.0 / cfg.poll_hz
        loop = asyncio.get_running_loop()
        # the first poll at once (values as soon as possible), then on this robot's slot
        due = loop.time()
        fast = [n for n in names if n not in SLOW_VARIABLES]
        count = 0
        while not self._stop.is_set():
            batch = names if count % SLOW_EVERY == 0 else fast
            count += 1
            started = loop.time()
            self.budget.begin()
            results = await client.read_many(batch, timeout=cfg.timeout)
            stamp = datetime.now(UTC)
            kept = await self._apply(results, names, stamp)
            if kept is not names:
                names, fast = kept, [n for n in kept if n not in SLOW_VARIABLES]
            self.polls += 1
            after = max(due, loop.time(), self.budget.earliest_next(started, period))
            due = next_slot(after, period, self.phase)
            # stop() cancels the task, so no per-poll waiter on the event
            await sleep_until(loop, due)

    # ------------------------------------------------------------------ reads

    def poll_names(self) -> list[str]:
        """What one poll asks for: snapshot STRUCs, then the variables they do not cover."""
        names = [s.variable for s in self.cfg.snapshots]
        for name in (*POLL_VARIABLES, *self.cfg.exposed):
            if canonical(name) not in self._snap_members and name not in names:
                names.append(name)
        return names

    async def _identity(self, client: Client) -> list[str]:
        results = await client.read_many(IDENTITY_VARIABLES, timeout=self.cfg.timeout)
        self.budget.begin()
        values = {
            n: await self._parse_reply(n, r.text)
            for n, r in results.items()
            if r.ok and r.text is not None
        }
        ident = identity_values(values)
        stamp = datetime.now(UTC)
        await self._arm(text_of(values.get("$MODEL_NAME[]")), stamp)
        await publish_identity(self.nodes, self.sink, ident, self.cfg.name, stamp)
        await publish_static(self.nodes, self.sink, stamp)
        return self.poll_names()

    async def _arm(self, model_name: str, stamp: datetime) -> None:
        """The robot's arm: axis speeds (for $VEL_AXIS_ACT's percent) and the axes' position
        ranges (EURange of ActualPosition), of a known arm only."""
        self.arm = choose_arm(model_name, self.given)
        if self.fixed_speed is None:
            self.max_speed = tuple(float(s) for s in self.arm.model.max_speed)
        log.info("robot %s: %s (%s)", self.cfg.name, self.arm.model.name, self.arm.source)
        if not self.arm.key:
            return
        model = self.arm.model
        for i, node in enumerate(self.nodes.position_range):
            value = ua.Range(Low=float(model.lower[i]), High=float(model.upper[i]))
            await self.sink.set(node, value, _V.ExtensionObject, stamp)

    async def _apply(
        self, results: Mapping[str, Any], names: list[str], stamp: datetime
    ) -> list[str]:
        changed: set[str] = set()
        keep = names
        for name, r in results.items():
            if r.error is not None:
                if isinstance(r.error, UnknownVariableError):
                    # not on this controller: stop asking until the next connection
                    keep = [n for n in keep if n != name]
                    log.info("robot %s: %s is unknown on the controller", self.cfg.name, name)
                    group = self._snapshot(name)
                    if group is not None:  # not installed: read its variables one by one
                        keep += [self._alias.get(canonical(m), m) for m in group.members]
                    await self._missing(name, stamp)
                    continue
                raise r.error
            text = r.text
            if self._texts.get(name) == text:
                continue  # the cheapest skip: same text, same value
            self._texts[name] = text
            value = await self._parse_reply(name, text)
            snapshot = self._snapshot(name)
            if snapshot is not None:
                changed |= self._fan_out(snapshot, value)
            else:
                self._values[name] = value
                changed.add(name)
        if changed:
            await self._publish(stamp, changed)
        if self._connected is not None:
            self.sink.put(self._connected, True, _V.Boolean, stamp)
        await self.sink.flush()
        return keep

    async def _parse_reply(self, name: str, text: str) -> Any:
        """One reply's value, within the robot's size cap and budget (:mod:`.budget`)."""
        if len(text) > self.cfg.max_value_chars:
            raise ValueTooLongError(
                f"{name} answered {len(text)} characters, over max_value_chars ="
                f" {self.cfg.max_value_chars}: not parsed (raise max_value_chars in the cell"
                " file for a long variable of your own)"
            )
        budget = self.budget
        t0 = budget.clock()
        value = parse_text(name, text)
        budget.charge(budget.clock() - t0)
        if budget.should_yield():
            await asyncio.sleep(0)  # the other robots and the OPC UA clients get their turn
        return value

    def _snapshot(self, name: str) -> SnapshotGroup | None:
        return next((s for s in self.cfg.snapshots if s.variable == name), None)

    def _fan_out(self, group: SnapshotGroup, value: Any) -> set[str]:
        """Store the members of a snapshot STRUC under their variables' names; which changed."""
        if not isinstance(value, Struct):
            log.warning("robot %s: snapshot %s is not a STRUC", self.cfg.name, group.variable)
            return set()
        members = {k.upper(): v for k, v in value.members.items()}
        changed: set[str] = set()
        for original, member in group.members.items():
            name = self._alias.get(canonical(original), original)
            if (
                member.upper() in members
                and self._values.get(name, _MISSING) != members[member.upper()]
            ):
                self._values[name] = members[member.upper()]
                changed.add(name)
        return changed

    async def _missing(self, name: str, stamp: datetime) -> None:
        node = self.nodes.extras.get(name)
        if node is not None:
            await self.sink.bad(node, ua.StatusCodes.BadNodeIdUnknown, stamp)

    # ------------------------------------------------------------------ writes to nodes

    async def _publish(self, stamp: datetime, changed: set[str] | None = None) -> None:
        values = poll_values(self._values, self.max_speed, changed)
        n, s = self.nodes, self.sink
        put = s.put
        for key, lives in self._arrays:
            array = values.get(key)
            if array is not None:
                for live, v in zip(lives, array, strict=False):
                    put(live, v, _V.Double, stamp)
        for key, live, vtype in self._scalars:
            if key in values:
                put(live, values[key], vtype, stamp)
        for key, task in n.tasks.items():
            if f"{key}_program" in values:
                await s.set(task.program_name, values[f"{key}_program"], _V.String, stamp)
            if f"{key}_loaded" in values:
                await s.set(task.program_loaded, values[f"{key}_loaded"], _V.Boolean, stamp)
            if f"{key}_state" in values:
                await self._task_state(key, values[f"{key}_state"], stamp)
        for name, node in n.extras.items():
            if name in self._values and (changed is None or name in changed):
                variant = variant_of(self._values[name], self._texts.get(name, ""))
                await s.set_typed(node, variant.Value, variant.VariantType, stamp)

    async def _task_state(self, key: str, state: str, stamp: datetime) -> None:
        task, s = self.nodes.tasks[key], self.sink
        before = self._states.get(key)
        self._states[key] = state
        state_id = self.cell.states.get(state)
        await s.set(task.current_state, ua.LocalizedText(state), _V.LocalizedText, stamp)
        if state_id is not None:
            await s.set(task.current_state_id, state_id[0], _V.NodeId, stamp)
        transition = self.cell.transitions.get(f"{before}To{state}") if before else None
        if transition is not None and before != state:
            await s.set(
                task.last_transition,
                ua.LocalizedText(f"{before}To{state}"),
                _V.LocalizedText,
                stamp,
            )
            await s.set(task.last_transition_id, transition[0], _V.NodeId, stamp)

    async def _mark_bad(self, code: int) -> None:
        stamp = datetime.now(UTC)
        n = self.nodes
        live: list[ua.NodeId] = [*n.position, *n.speed, *n.torque, *n.current, *n.temperature]
        live += [node for key, node in n.scalars.items()]
        for task in n.tasks.values():
            live += [task.program_name, task.program_loaded, task.current_state]
        live += list(n.extras.values())
        for node in live:
            await self.sink.bad(node, code, stamp)
        if n.connected is not None:
            await self.sink.set(n.connected, False, _V.Boolean, stamp)
        # parse everything again after a reconnect: the controller may have changed meanwhile
        self._texts.clear()
        self._values.clear()


# pyopenshowvar.core's advice to a client without auto_reconnect, in both of its forms
_NO_RECONNECT = re.compile(
    r" \(auto_reconnect is off(: call connect\(\) to open a new connection)?\)"
)


def _reason(exc: BaseException) -> str:
    """The client's error without its advice to reconnect by hand: the poller reconnects."""
    return _NO_RECONNECT.sub("", str(exc))
