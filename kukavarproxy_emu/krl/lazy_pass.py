"""Lazy SPS passes: copies are made when someone reads them, not every 12 ms.

An SPS snapshot (docs/snapshots.md) copies the robot's readings into a structure every pass,
``CELL = CELL_W`` last, and counts its passes. At rest nobody may read ``CELL`` for seconds,
yet each pass copied, and the copies forced the plant to compute readings (noise, forward
kinematics) for them. A :class:`LazyPass` runs such a pass in two parts:

* the **carried** statements, those the next pass reads (the counter), run now, as they would;
* the **dead-if-followed** statements (the copies and ``CELL = CELL_W``: :mod:`.pass_flow`)
  do not run. The pass captures what they would read from outside the pass (a reading of
  the plant: the frozen inputs it would be computed from, see
  :meth:`~..store.VariableStore.capture`; any other variable: its value) and marks the
  variables the pass writes stale (:meth:`~..store.VariableStore.defer`). The first read or
  write of any of them, by anyone (a KVP, C3 or kvp9 request, the robot program, the
  SPS itself, an app), runs the deferred statements with the captured values first: the
  reader sees exactly the pass the eager run would have left. When the next pass comes first,
  the deferred statements are dropped unrun (dead: the next pass overwrites all they
  wrote before anything reads it).

A pass is run this way only when nothing can differ from running it statement by statement:
the submit interpreter stands at the end of its ``LOOP`` body (not in a call, not a repeat
it would skip), every statement is a compiled assignment (:class:`~.plan.AssignPlan`) or an
``IF`` of them on a compared path, the carried statements come first and write nothing the
deferred ones write, each deferred statement copies a path of its own type or a literal into
a target without limits (so it cannot fail later), what it reads is initialised, a stale
reading it reads can be captured, and the pass is short enough never to be cut by the
interpreter's budget. Otherwise the pass runs as before.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import TYPE_CHECKING

from pyopenshowvar.krl import KrlValue

from ..slot import Slot
from ..values import Refused
from . import ast
from .lazy_carried import Carried, Counter, peek, pick
from .pass_flow import Path, Unit, dead_units, overlaps, slot_path
from .plan import AssignPlan
from .runtime import KrlRuntimeError, convert, literal_path, render

if TYPE_CHECKING:
    from ..names import Var
    from ..store_lazy import Maker, Stale
    from .interp import Interpreter

__all__ = ["LazyPass"]

log = logging.getLogger(__name__)

_COMPARE = ("==", "<>", "<", "<=", ">", ">=")
#: Statements of a pass the interpreter never cuts (it looks at its time budget from this
#: count on: :data:`.interp.CHECK_EVERY`).
_UNCUT = 64


class LazyPass:
    """The lazy form of one SPS ``LOOP`` body (see the module); :meth:`run` or None."""

    def __init__(self, interp: Interpreter, loop: ast.Loop) -> None:
        self.interp, self.loop_id = interp, id(loop)
        self.store = interp.store
        self.plans: dict[int, AssignPlan] = {}
        self.conds: dict[int, Slot] = {}
        self.carried: list[Carried] = []
        #: The deferred copies: (plan, source kind: "const" / "self" / "ext").
        self.deferred: list[tuple[AssignPlan, str]] = []
        self.targets: frozenset[str] = frozenset()
        #: The deferred copies' entry in the store while they wait (None: none waits).
        self.pending: Stale | None = None
        self._ready = False  # every source of a deferred copy was initialised once
        #: The carried statements as counters (empty: they run now; see lazy_carried).
        self.counters: tuple[Counter, ...] = ()
        #: The waiting pass: the counters' values (None: in the store) and its captures.
        self._counted: list[KrlValue] | None = None
        self._captured: list[object] = []
        #: Every variable the plans touch, to see that none was declared anew.
        self._vars: tuple[tuple[str, Var], ...] = ()
        #: Per variable from outside the pass: the parts the deferred copies read ...
        self._outside: tuple[tuple[str, tuple[Slot, ...]], ...] = ()
        #: ... and the positions of those copies in :attr:`deferred`.
        self._positions: dict[str, list[int]] = {}
        #: The version of each of those variables when its values were last captured.
        self._seen: list[int] = []
        self._seeing: list[int] = []
        self._fresh = False  # the last capture took a stale reading
        self._declarations = -1  # store.declarations when the plans were last seen current

    @classmethod
    def compile(cls, interp: Interpreter, loop_id: int) -> LazyPass | None:
        """The lazy form of the main routine's ``LOOP`` ``loop_id``, or None."""
        main = interp.module.main
        loop = next((s for s in main.body if id(s) == loop_id), None)
        if not isinstance(loop, ast.Loop) or main.params or not loop.body:
            return None
        self = cls(interp, loop)
        units = [self._unit(stmt) for stmt in loop.body]
        if any(u is None for u in units):
            return None
        dead = dead_units(units)  # type: ignore[arg-type]
        live = [i for i, d in enumerate(dead) if not d]
        if not any(dead) or (live and max(live) > dead.index(True)):
            return None  # nothing to defer, or a carried statement after a deferred one
        self.targets = frozenset(str(p[0]) for u in units if u is not None for p in u.writes)
        if any(interp.store.is_system(t) for t in self.targets):
            return None  # the controller's own variables (the kernel reads them) stay eager
        locals_ = {d.name for decl in main.decls if isinstance(decl, ast.Decl)
                   for d in decl.declarations}  # fmt: skip
        if self.targets & locals_ or any(
            p.source is not None and p.source.var.name in locals_ for p in self.plans.values()
        ):
            return None  # a local shadows a global: the plans would not apply
        carried_writes: list[Path] = [p for i in live for p in units[i].writes]  # type: ignore[union-attr]
        worst = 1
        for i, stmt in enumerate(loop.body):
            unit = units[i]
            assert unit is not None
            worst += 1 + (max(len(stmt.then_body), len(stmt.else_body))
                          if isinstance(stmt, ast.If) else 0)  # fmt: skip
            if not dead[i]:
                self.carried.append(Carried(interp, stmt, self.plans, self.conds))
                continue
            kind = self._deferrable(stmt, carried_writes)
            if kind is None:
                return None
            self.deferred.append((self.plans[id(stmt)], kind))
        if worst >= min(_UNCUT, interp.budget):
            return None  # a long pass may be cut by the budget: it runs as before
        counters = [Counter.compile(c, self.plans) for c in self.carried]
        paths = [c.slot.name for c in counters if c is not None]
        if all(c is not None for c in counters) and len(set(paths)) == len(paths):
            self.counters = tuple(c for c in counters if c is not None)
        slots = [p.target for p in self.plans.values()]
        slots += [p.source for p in self.plans.values() if p.source is not None]
        slots += list(self.conds.values())
        self._vars = tuple({s.var.name: s.var for s in slots}.items())
        for i, (plan, kind) in enumerate(self.deferred):
            if kind == "ext":
                assert plan.source is not None
                base = plan.source.var.name
                self._positions.setdefault(base, []).append(i)
        self._outside = tuple(
            (base, tuple(self.deferred[i][0].source for i in at))  # type: ignore[misc]
            for base, at in self._positions.items()
        )
        self._seen = [-1] * len(self._outside)
        return self

    def _unit(self, stmt: ast.Stmt) -> Unit | None:
        """The reads and writes of one statement of a supported form, None otherwise."""
        if isinstance(stmt, ast.Assign):
            plan = AssignPlan.compile(self.interp.ev, stmt)
            if plan is None:
                return None
            self.plans[id(stmt)] = plan
            target = slot_path(plan.target)
            source = (slot_path(plan.source),) if plan.source is not None else ()
            return Unit(source, (target,), (target,))
        if not isinstance(stmt, ast.If):
            return None
        cond = stmt.cond
        if not (
            isinstance(cond, ast.Binary)
            and cond.op in _COMPARE
            and isinstance(cond.right, ast.IntLit | ast.RealLit)
        ):
            return None
        slot = Slot.compile(self.store, render(cond.left)) if literal_path(cond.left) else None
        if slot is None:
            return None
        self.conds[id(stmt)] = slot
        reads: list[Path] = [slot_path(slot)]
        branches: list[list[Path]] = []
        for body in (stmt.then_body, stmt.else_body):
            writes: list[Path] = []
            for inner in body:
                unit = self._unit(inner) if isinstance(inner, ast.Assign) else None
                if unit is None:
                    return None
                reads += unit.reads
                writes += unit.writes
            branches.append(writes)
        kills = tuple(p for p in branches[0] if p in branches[1])
        return Unit(tuple(reads), (*branches[0], *branches[1]), kills)

    def _deferrable(self, stmt: ast.Stmt, carried_writes: list[Path]) -> str | None:
        """How a dead statement's source is read later ("const", "self", "ext"), or None
        when it must run now: it could fail (a conversion, a limit) or it writes what a
        carried statement writes."""
        if not isinstance(stmt, ast.Assign):
            return None
        plan = self.plans[id(stmt)]
        target, source = plan.target, plan.source
        if plan.op is not None or target.var.ranges is not None:
            return None
        if any(overlaps(slot_path(target), w) for w in carried_writes):
            return None
        if source is None:
            try:
                convert(plan.constant, target.chain[-1][0], target.type_name,  # type: ignore[arg-type]
                        self.store.registry, stmt)  # fmt: skip
            except KrlRuntimeError:
                return None
            return "const"
        if source.type_name != target.type_name:
            return None  # a conversion that may fail later (REAL to INT, narrowing)
        return "self" if source.var.name in self.targets else "ext"

    # --- one pass ------------------------------------------------------------------------------
    def run(self) -> bool:
        """Run one pass lazily; False (nothing done) when it must run as before."""
        interp, store = self.interp, self.store
        if (
            interp._quiet is not None  # a repeat the interpreter skips: cheaper still
            or interp._at_pass != self.loop_id
            or len(interp.frames) != 1
            or interp.ev.heavy
        ):
            return False
        if store.declarations != self._declarations:  # something was declared since
            declared = store.declared
            for name, var in self._vars:
                if declared.get(name) is not var:
                    return False  # declared anew: the plans are stale
            self._declarations = store.declarations
        if not self._ready:
            for plan, kind in self.deferred:
                if kind == "self" and peek(plan.source) is None:  # type: ignore[arg-type]
                    return False  # not initialised (yet): the eager pass words the error
        captured = self._capture()
        if captured is None or not (self.carried or self._fresh):
            # nothing changes every pass (no counter, no fresh reading): the interpreter
            # skips the pass once it repeats, which is cheaper still
            return False
        self._ready = True
        count = self._count(captured) if self.counters else None
        if count is None:
            count = self._carry(captured)
        interp.count = count
        interp.total += count
        interp.whole_pass = True
        return True

    def _capture(self) -> list[object] | None:
        """What the deferred copies read from outside the pass, as it is now: a stale
        reading's maker (one per group), or the values; None when a value is missing or a
        stale reading cannot wait."""
        store = self.store
        captured: list[object] = []
        stale, versions = store._stale, store._versions
        seen, before = list(self._seen), self._captured
        makers: dict[int, Maker] = {}
        for k, (base, slots) in enumerate(self._outside):
            entry = stale.get(base) if stale else None
            if entry is None:
                version = versions.get(base, 0)
                if seen[k] == version:  # not changed since the last pass: the same values
                    captured.append(before[k])
                    continue
                values = [peek(slot) for slot in slots]
                if None in values:
                    return None  # not initialised: the eager pass words the error
                seen[k] = version
                captured.append(values)
                continue
            if entry.capture is None:
                return None  # a lazy value that cannot wait: copy it now
            # one maker per capture (groups captured together share theirs)
            maker = makers.get(id(entry.capture))
            if maker is None:
                maker = makers[id(entry.capture)] = entry.capture()
            captured.append(maker)
        self._seeing = seen  # kept with the captures when the pass runs lazily
        self._fresh = bool(makers)  # a stale reading was captured
        return captured

    def _count(self, captured: list[object]) -> int | None:
        """The pass with counters only: their next values are kept here, written with the
        deferred copies. None when a step cannot be computed here."""
        store, pending = self.store, self.pending
        values: list[KrlValue | None] | None = None
        if pending is not None:
            values = self._counted  # type: ignore[assignment]
        if values is None:  # the store holds the current values (nothing waits)
            values = [peek(c.slot) for c in self.counters]
        count = 1 + len(self.deferred)  # counted as the interpreter counts them
        stepped: list[KrlValue] = []
        for counter, value in zip(self.counters, values, strict=True):
            step = counter.step(value) if value is not None else None
            if step is None:
                if pending is not None:
                    store.fill_stale(next(iter(self.targets)))  # the passes so far, then
                return None  # this one as before
            stepped.append(step[0])
            count += step[1]
        self._counted, self._captured, self._seen = stepped, captured, self._seeing
        if pending is None or not store.renew(pending):
            self.pending = store.defer(self.targets, self._materialize)
        return count

    def _carry(self, captured: list[object]) -> int:
        """The pass with its carried statements run now."""
        store, pending = self.store, self.pending
        # the previous pass's deferred copies are dead now: the carried statements below do
        # not read them, and this pass's deferred copies overwrite them before anyone can
        waited = pending is not None and store.forget(pending)
        try:
            # the LOOP's own statement count and the deferred copies, as the interpreter
            # counts them
            count = 1 + len(self.deferred)
            for unit in self.carried:
                count += unit.run()
        except BaseException:
            if waited:  # the SPS stops here: the previous pass stays as it would have
                self.pending = store.defer(self.targets, self._materialize)
            raise
        self._captured, self._seen, self._counted = captured, self._seeing, None
        self.pending = store.defer(self.targets, self._materialize)
        return count

    def _materialize(self) -> None:
        """Make the deferred pass: the counters' values, then the copies with what the
        pass captured (the store calls it at the first read or write of a target)."""
        self.pending = None
        counted, self._counted = self._counted, None
        if counted is not None:
            for counter, count in zip(self.counters, counted, strict=True):
                if peek(counter.slot) != count:
                    counter.slot.set(count)
        captured = self._captured
        outside: dict[int, KrlValue | None] = {}  # deferred copy -> its value from outside
        made: dict[int, Mapping[str, object]] = {}
        for (base, slots), got in zip(self._outside, captured, strict=True):
            positions = self._positions[base]
            if isinstance(got, list):
                outside.update(zip(positions, got, strict=True))
                continue
            whole = made.get(id(got))
            if whole is None:
                whole = made[id(got)] = got()  # type: ignore[operator]
            for i, slot in zip(positions, slots, strict=True):
                outside[i] = pick(whole[base], slot)
        for i, (plan, kind) in enumerate(self.deferred):
            value: KrlValue | None
            if kind == "const":
                value = plan.constant
            elif kind == "self":
                assert plan.source is not None
                value = plan.source.get()
            else:
                value = outside[i]
            if value is None:  # cannot happen: checked when the pass ran
                log.error("lazy SPS pass: %s has no value", plan.stmt.value)
                continue
            try:
                plan.put(value, copied=kind != "const")
            except (KrlRuntimeError, Refused):  # cannot happen: the types were checked
                log.exception("lazy SPS pass: a deferred copy failed")
