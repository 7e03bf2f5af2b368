"""The KRL executor: runs a parsed :class:`~.ast.Module` one interpolation cycle at a time.

Statements are Python generators; a statement that must wait (a motion the advance run may
not plan yet, ``WAIT``, an advance-run stop, the statement budget) *yields*, and
:meth:`Interpreter.step` resumes it in the next IPO cycle. Nothing ever blocks the event loop.

**Advance run** (reference §5). The interpreter *is* the advance run: it executes statements as
soon as it reaches them and hands motions to the :class:`~..motion.kernel.MotionKernel`, which
runs them in the main run. A motion statement waits until ``kernel.can_plan($ADVANCE)`` and
reads its target only then, so the target is captured when the motion is planned. ``WAIT FOR``,
``WAIT SEC``, ``HALT``, the program's ``END`` and every statement that reads ``$AXIS_ACT`` /
``$POS_ACT`` (directly or in a DEFFCT it calls) first wait until the kernel has neither a
queued nor an active motion: the advance-run stop. Approximation therefore only happens when
the next motion was planned in time, which the kernel decides.

**Budget.** At most :attr:`Interpreter.budget` statements, and at most ``TIME_BUDGET`` (2 ms)
of wall time, run per cycle, so a ``LOOP`` of assignments only burns a bounded slice of each
cycle and the server keeps answering promptly. The time budget is also never more than a
quarter (``TIME_SHARE``) of the wall time since the previous cycle ended (and never less than
0.5 ms), so cycles that come back to back (the IPO clock catching up on a loaded machine, a
high ``--speed``) shrink it instead of starving the server. Planning a ``LIN`` (in slices,
bounded work) keeps the full 2 ms per cycle, as the robot's timing depends on it. Statements inside user functions
count too: a ``DEFFCT`` called from an expression runs as a generator (:mod:`.interp_expr`)
and is suspended mid-way like any statement, so a slow or endless function costs each cycle
its slice and nothing more. Local variables of the live calls hold at most ``LOCAL_ELEMENTS``
elements together (one array at most ``datfile.MAX_ELEMENTS``). A motion that completes at
once (the robot already stands on its target) may run once per cycle
before the loop yields, so ``LOOP PTP MYAXIS C_PTP ENDLOOP`` does not spin at rest.

The **submit interpreter** (``submit=True``) has no kernel: motions are errors, WAIT does not
stop any advance run, and each ``LOOP`` iteration ends the cycle (the SPS body runs once per
cycle).
"""

from __future__ import annotations

import time
from collections.abc import Generator, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from pyopenshowvar.krl import KrlValue

from . import ast
from .interp_expr import ExprMixin
from .interp_motion import BUDGET, WAIT, MotionMixin
from .interp_skip import PASS, SkipMixin
from .plan import AssignPlan
from .runtime import (
    ACTUAL_POSITION,
    HEAVY_ELEMENTS,
    Evaluator,
    Frame,
    KrlRuntimeError,
    convert,
    is_number,
)

if TYPE_CHECKING:
    from ..motion.kernel import MotionKernel
    from ..store import VariableStore

__all__ = ["DEFAULT_BUDGET", "Interpreter"]

#: Statements per interpolation cycle before the interpreter yields to the event loop.
DEFAULT_BUDGET = 2000
#: Wall seconds of statements per cycle, whichever of the two limits comes first: a runaway loop
#: then costs the server at most this much latency per cycle, however slow the statements are.
TIME_BUDGET = 0.002
#: ... and at most this share of the wall time since the previous cycle ended, but at least
#: TIME_FLOOR seconds.
TIME_SHARE = 0.25
TIME_FLOOR = 0.0005
#: Statements between two looks at the clock (fewer after a statement on a large array).
CHECK_EVERY = 64
#: Elements of all local variables of the routines on the call stack together (8 MB of
#: references): a deep recursion with a big local array is an error, not a memory hog.
LOCAL_ELEMENTS = 1 << 20
#: Routine calls nested deeper than this are an error (endless recursion).
MAX_CALL_DEPTH = 64

Gen = Generator[str, None, "Signal"]


@dataclass(frozen=True, slots=True)
class _Exit:
    pass


@dataclass(frozen=True, slots=True)
class _Return:
    value: KrlValue | None


Signal = _Exit | _Return | None
_EXIT = _Exit()


class Halted(Exception):
    """``HALT`` reached (the main run got there): the program stops, no error message."""


class Interpreter(SkipMixin, ExprMixin, MotionMixin):
    """Executes one module's main routine, stepped once per IPO cycle."""

    def __init__(
        self,
        module: ast.Module,
        store: VariableStore,
        kernel: MotionKernel | None = None,
        *,
        submit: bool = False,
        budget: int = DEFAULT_BUDGET,
    ) -> None:
        self.module = module
        self.store = store
        self.kernel = kernel
        self.submit = submit
        self.budget = budget
        self.frames: list[Frame] = []
        self.ev = Evaluator(store, self.frames, self._call_function)
        self.count = 0  # statements this cycle
        self._until = 0.0  # perf_counter() at which this cycle's time budget ends
        #: ... and the motion planning's (a LIN planned in slices): the full TIME_BUDGET, so
        #: a high --speed does not stretch a LIN's planning over more simulated time.
        self._plan_until = 0.0
        self._check_at = CHECK_EVERY  # statement count at which the clock is read next
        self._ended = 0.0  # perf_counter() when the last cycle's statements ended
        self.at_once = 0  # motions that completed at once this cycle
        self.total = 0  # statements since start (diagnostics, tests)
        self.finished = False
        self.halted = False
        #: Simulated seconds of the submit interpreter (the robot program uses the kernel's).
        self.sim_time = 0.0
        self._gen: Gen | None = None
        self._reads: dict[int, bool] = {}
        self._init_skip()
        self._user_calls: dict[int, bool] = {}
        #: Compiled assignments per statement node (None: not one of the simple forms).
        self._plans: dict[int, AssignPlan | None] = {}
        self._local_sizes: dict[int, int] = {}
        #: Elements of the locals of the routines on the call stack now.
        self.local_elements = 0

    # --- driving -------------------------------------------------------------------------------
    def start(self) -> None:
        """(Re)start the main routine from its first statement."""
        if self._gen is not None:
            # Unwound now, while its frames are the ones on the stack: left to the garbage
            # collector, its ``finally`` clauses popped frames of the new run (or an empty stack)
            self._gen.close()
            self._gen = None
        self.frames.clear()
        self.local_elements = 0
        self.finished = self.halted = False
        self._reset_skip()
        self._gen = self._main()

    def step(self) -> None:
        """Run one cycle's worth of statements; raises :class:`KrlRuntimeError`."""
        if self._gen is None or self.finished or self.halted:
            return
        self._cycle()

    def _run(self) -> str | None:
        self.count = self.at_once = 0
        self._check_at = CHECK_EVERY
        now = time.perf_counter()
        # Never more than TIME_SHARE of the wall time since the last cycle ended: when cycles
        # come back to back (the IPO clock catching up on a starved machine), a runaway program
        # must not take the loop over, which a fixed 2 ms per cycle would.
        share = max(TIME_FLOOR, TIME_SHARE * (now - self._ended))
        self._until = now + min(TIME_BUDGET, share)
        self._plan_until = now + TIME_BUDGET
        assert self._gen is not None
        try:
            return next(self._gen)
        except StopIteration:
            self.finished = True
            self._gen = None
        except Halted:
            self.halted = True
            self._gen = None
        except KrlRuntimeError:
            self._gen = None
            raise
        except RecursionError:
            self._gen = None
            raise KrlRuntimeError("call stack overflow (endless recursion?)") from None
        finally:
            self._ended = time.perf_counter()
        return None

    def _main(self) -> Gen:
        yield from self._invoke(self.module.main, (), self.module.main)
        yield from self._advance_stop()  # END: the program ends when the robot has arrived
        return None

    # --- helpers -------------------------------------------------------------------------------
    def _tick(self) -> Generator[str, None, None]:
        """Count one statement; yield when this cycle's budget is used up."""
        self.count += 1
        self.total += 1
        if self.count > self.budget:
            yield BUDGET
        elif self.count >= self._check_at or self.ev.heavy:
            # The clock is read every CHECK_EVERY statements, and after each statement that
            # touched a large array (a call with big locals, a whole-array read), so the wall
            # time stays bounded while short cycles run an exact number of statements.
            self.ev.heavy = False
            self._check_at = self.count + CHECK_EVERY
            if time.perf_counter() > self._until:
                yield BUDGET

    def _advance_stop(self) -> Generator[str, None, None]:
        """Wait until the main run has caught up (no queued or active motion)."""
        if self.kernel is None:
            return
        while self.kernel.moving:
            yield WAIT

    def _stop_if_reads(self, *exprs: ast.Expr | None) -> Generator[str, None, None]:
        if self.kernel is not None and any(e is not None and self._reads_actual(e) for e in exprs):
            yield from self._advance_stop()

    def _reads_actual(self, expr: ast.Expr) -> bool:
        key = id(expr)
        cached = self._reads.get(key)
        if cached is None:
            self._reads[key] = False  # recursion guard
            cached = any(self._node_reads(e) for e in _walk(expr))
            self._reads[key] = cached
        return cached

    def _node_reads(self, e: ast.Expr) -> bool:
        if isinstance(e, ast.Name):
            return e.name in ACTUAL_POSITION
        if isinstance(e, ast.Call):
            routine = self.module.routine(e.name)
            return routine is not None and self._body_reads(routine.body)
        return False

    def _body_reads(self, body: Iterable[ast.Stmt]) -> bool:
        for stmt in body:
            for expr in _stmt_exprs(stmt):
                if self._reads_actual(expr):
                    return True
            if any(self._body_reads(b) for b in _stmt_bodies(stmt)):
                return True
        return False

    # --- routines ------------------------------------------------------------------------------
    def _invoke(self, routine: ast.Routine, args: tuple[ast.Expr, ...], node: ast.Node) -> Gen:
        """Call ``routine`` with ``args``; returns its _Return (the DEFFCT value)."""
        if len(args) > len(routine.params):
            raise KrlRuntimeError(f"{routine.name} takes {len(routine.params)} argument(s)", node)
        lowered: list[ast.Expr] = []  # user calls in the arguments run once, here
        for arg in args:
            lowered.append((yield from self._lower(arg)))
        values = [self.ev.eval(a) for a in lowered]
        refs = [self.ev.ref(a) if p.direction == "OUT" and _lvalue(a) else None
                for p, a in zip(routine.params, lowered, strict=False)]  # fmt: skip
        if len(self.frames) >= MAX_CALL_DEPTH:
            raise KrlRuntimeError("call stack overflow (endless recursion?)", node)
        size = self._local_size(routine)
        if self.local_elements + size > LOCAL_ELEMENTS:
            raise KrlRuntimeError(
                f"calling {routine.name}: local variables of the call stack would exceed"
                f" {LOCAL_ELEMENTS} elements (endless recursion or a huge local array?)",
                node,
            )
        frame = Frame(routine, self.store)
        self.ev.heavy = self.ev.heavy or size >= HEAVY_ELEMENTS
        for param, value in zip(routine.params, values, strict=False):
            if param.name not in frame.names:
                raise KrlRuntimeError(f"parameter {param.name} has no DECL", routine)
            self.ev.frames.append(frame)
            try:
                self.ev.put(frame.store, param.name, param.name, value, node)
            finally:
                self.ev.frames.pop()
        self.frames.append(frame)
        self.local_elements += size
        try:
            signal = yield from self._block(routine.body)
        finally:
            self.frames.pop()
            self.local_elements -= size
        for param, ref in zip(routine.params, refs, strict=False):
            if ref is not None:  # OUT parameter: copy back (KRL passes it by reference)
                try:
                    value = frame.store.get(param.name)
                except LookupError:
                    continue
                self.ev.put(ref[0], ref[1], ref[2].name, value, node)
        if routine.is_function:
            if not isinstance(signal, _Return) or signal.value is None:
                raise KrlRuntimeError(f"function {routine.name} ended without RETURN", routine)
            assert routine.return_type is not None
            spec = self.store.registry.resolve(routine.return_type)
            value = convert(signal.value, spec, routine.return_type, self.store.registry, node)
            return _Return(value)
        return None

    def _local_size(self, routine: ast.Routine) -> int:
        """Elements the locals of ``routine`` occupy (a CHAR array is one text)."""
        size = self._local_sizes.get(id(routine))
        if size is None:
            size = 0
            for decl in routine.decls:
                if isinstance(decl, ast.Decl):
                    for d in decl.declarations:
                        n = 1
                        for dim in d.dims:
                            n *= dim
                        size += 1 if d.type_name == "CHAR" else n
            self._local_sizes[id(routine)] = size
        return size

    def _call_fn(self, call: ast.Call) -> Generator[str, None, KrlValue]:
        """Run a user DEFFCT called from an expression; its statements count and may yield."""
        routine = self.module.routine(call.name)
        if routine is None:
            raise KrlRuntimeError(f"unknown function {call.name}", call)
        if not routine.is_function:
            raise KrlRuntimeError(f"{call.name} is a DEF, not a DEFFCT", call)
        result = yield from self._invoke(routine, call.args, call)
        assert isinstance(result, _Return) and result.value is not None
        return result.value

    def _call_function(self, call: ast.Call) -> KrlValue:
        """The Evaluator's hook for a user call it meets itself. The executor hands it only
        expressions without user calls (see :mod:`.interp_expr`); should one slip through, the
        call runs within this cycle's budget or fails, it never runs unbounded."""
        gen = self._call_fn(call)
        try:
            reason = next(gen)
        except StopIteration as stop:
            return stop.value  # type: ignore[no-any-return]
        finally:
            gen.close()
        raise KrlRuntimeError(
            f"{call.name}: the function must wait ({reason}) where the emulator cannot suspend it",
            call,
        )

    # --- statements ----------------------------------------------------------------------------
    def _block(self, body: tuple[ast.Stmt, ...]) -> Gen:
        for stmt in body:
            if type(stmt) is ast.Assign and self._planned(stmt):
                continue
            signal = yield from self._stmt(stmt)
            if signal is not None:
                return signal
        return None

    def _planned(self, stmt: ast.Assign) -> bool:
        """Run ``stmt`` by its compiled plan (:mod:`.plan`): True when it did.

        False — run it the general way — when it has none, when this statement is where the
        cycle's budget must be looked at (the general way yields there), or when the plan
        does not apply now. Counted like any statement.
        """
        key = id(stmt)
        if key in self._plans:
            plan = self._plans[key]
        else:
            plain = self.kernel is None or not (
                self._reads_actual(stmt.target) or self._reads_actual(stmt.value)
            )  # a read of $AXIS_ACT & co. in the robot program stops the advance run first
            plan = self._plans[key] = AssignPlan.compile(self.ev, stmt) if plain else None
        if plan is None:
            return False
        count = self.count + 1
        if count > self.budget or count >= self._check_at or self.ev.heavy:
            return False
        if not plan.run():
            if plan.stale():
                del self._plans[key]  # a variable was declared anew: compile it again
            return False
        self.count = count
        self.total += 1
        return True

    def _stmt(self, stmt: ast.Stmt) -> Gen:
        yield from self._tick()
        if isinstance(stmt, ast.Assign):
            yield from self._stop_if_reads(stmt.target, stmt.value)
            value = yield from self._eval(stmt.value)
            self.ev.assign((yield from self._lower(stmt.target)), value, stmt)
        elif isinstance(stmt, ast.Motion | ast.InlineMotion):
            yield from self._motion(stmt)
        elif isinstance(stmt, ast.If):
            yield from self._stop_if_reads(stmt.cond)
            body = stmt.then_body if (yield from self._cond(stmt.cond)) else stmt.else_body
            return (yield from self._block(body))
        elif isinstance(stmt, ast.Loop):
            return (yield from self._loop(stmt))
        elif isinstance(stmt, ast.For):
            return (yield from self._for(stmt))
        elif isinstance(stmt, ast.While):
            while True:
                yield from self._stop_if_reads(stmt.cond)
                if not (yield from self._cond(stmt.cond)):
                    return None
                signal = yield from self._block(stmt.body)
                if signal is not None:
                    return None if signal is _EXIT else signal
                yield from self._tick()
        elif isinstance(stmt, ast.Repeat):
            while True:
                signal = yield from self._block(stmt.body)
                if signal is not None:
                    return None if signal is _EXIT else signal
                yield from self._stop_if_reads(stmt.cond)
                if (yield from self._cond(stmt.cond)):
                    return None
                yield from self._tick()
        elif isinstance(stmt, ast.Switch):
            return (yield from self._switch(stmt))
        elif isinstance(stmt, ast.WaitFor):
            yield from self._advance_stop()
            while not (yield from self._cond(stmt.cond)):
                yield WAIT
        elif isinstance(stmt, ast.WaitSec):
            yield from self._wait_sec(stmt)
        elif isinstance(stmt, ast.CallStmt):
            yield from self._call_stmt(stmt)
        elif isinstance(stmt, ast.Return):
            if stmt.value is None:
                return _Return(None)
            yield from self._stop_if_reads(stmt.value)
            return _Return((yield from self._eval(stmt.value)))
        elif isinstance(stmt, ast.Exit):
            return _EXIT
        elif isinstance(stmt, ast.Halt):
            yield from self._advance_stop()
            raise Halted
        # Decl/StrucDef/EnumDef ran at the call; Ini and Continue are no-ops here.
        return None

    def _loop(self, stmt: ast.Loop) -> Gen:
        while True:
            signal = yield from self._block(stmt.body)
            if signal is not None:
                return None if signal is _EXIT else signal
            if self.submit:
                self._pass_loop = id(stmt)
                yield PASS  # the SPS runs its LOOP body once per cycle
            yield from self._tick()

    def _for(self, stmt: ast.For) -> Gen:
        yield from self._stop_if_reads(stmt.start, stmt.stop, stmt.step)
        var = ast.Name(stmt.var, line=stmt.line, column=stmt.column)
        first = yield from self._eval(stmt.start)
        last = yield from self._eval(stmt.stop)
        step = (yield from self._eval(stmt.step)) if stmt.step is not None else 1
        for v in (first, last, step):
            if not is_number(v):
                raise KrlRuntimeError("FOR needs INT bounds and STEP", stmt)
        if step == 0:
            raise KrlRuntimeError("FOR with STEP 0", stmt)
        self.ev.assign(var, first, stmt)
        while True:
            i = self.ev.eval(var)
            assert isinstance(i, int | float)
            if (step > 0 and i > last) or (step < 0 and i < last):  # type: ignore[operator]
                return None
            signal = yield from self._block(stmt.body)
            if signal is not None:
                return None if signal is _EXIT else signal
            i = self.ev.eval(var)
            self.ev.assign(var, i + step, stmt)  # type: ignore[operator]
            yield from self._tick()

    def _switch(self, stmt: ast.Switch) -> Gen:
        yield from self._stop_if_reads(stmt.selector)
        selector = yield from self._eval(stmt.selector)
        for case in stmt.cases:
            for v in case.values:
                if (yield from self._eval(v)) == selector:
                    return (yield from self._block(case.body))
        if stmt.default is not None:
            return (yield from self._block(stmt.default))
        return None

    def _wait_sec(self, stmt: ast.WaitSec) -> Gen:
        yield from self._advance_stop()
        seconds = yield from self._eval(stmt.seconds)
        if not is_number(seconds):
            raise KrlRuntimeError("WAIT SEC needs a number", stmt)
        end = self.now() + float(seconds)  # type: ignore[arg-type]
        while self.now() < end - 1e-9:
            yield WAIT
        return None

    def now(self) -> float:
        """Simulated seconds (the kernel's clock; the SPS counts its own cycles)."""
        return self.kernel.time if self.kernel is not None else self.sim_time

    def _call_stmt(self, stmt: ast.CallStmt) -> Gen:
        if stmt.name == "BAS" or stmt.name.startswith("BAS_"):
            return None  # the KUKA system library inside INI folds: no-op
        routine = self.module.routine(stmt.name)
        if routine is None:
            raise KrlRuntimeError(f"unknown routine {stmt.name}", stmt)
        yield from self._stop_if_reads(*stmt.args)
        yield from self._invoke(routine, stmt.args, stmt)
        return None


def _lvalue(expr: ast.Expr) -> bool:
    if isinstance(expr, ast.Name):
        return True
    if isinstance(expr, ast.Member | ast.Index):
        return _lvalue(expr.base)
    return False


def _walk(expr: ast.Expr) -> Iterable[ast.Expr]:
    yield expr
    children: tuple[ast.Expr, ...] = ()
    if isinstance(expr, ast.Index):
        children = (expr.base, *expr.indices)
    elif isinstance(expr, ast.Member):
        children = (expr.base,)
    elif isinstance(expr, ast.Unary):
        children = (expr.operand,)
    elif isinstance(expr, ast.Binary):
        children = (expr.left, expr.right)
    elif isinstance(expr, ast.Call):
        children = expr.args
    elif isinstance(expr, ast.Aggregate):
        children = tuple(item.value for item in expr.items)
    for child in children:
        yield from _walk(child)


def _stmt_exprs(stmt: ast.Stmt) -> tuple[ast.Expr, ...]:
    """The expressions a statement evaluates itself (not those of its nested bodies)."""
    if isinstance(stmt, ast.Assign):
        return (stmt.target, stmt.value)
    if isinstance(stmt, ast.If | ast.While | ast.Repeat | ast.WaitFor):
        return (stmt.cond,)
    if isinstance(stmt, ast.For):
        return tuple(e for e in (stmt.start, stmt.stop, stmt.step) if e is not None)
    if isinstance(stmt, ast.Switch):
        return (stmt.selector,)
    if isinstance(stmt, ast.Motion | ast.InlineMotion):
        return (stmt.target,)
    if isinstance(stmt, ast.CallStmt):
        return stmt.args
    if isinstance(stmt, ast.Return) and stmt.value is not None:
        return (stmt.value,)
    return ()


def _stmt_bodies(stmt: ast.Stmt) -> tuple[tuple[ast.Stmt, ...], ...]:
    if isinstance(stmt, ast.If):
        return (stmt.then_body, stmt.else_body)
    if isinstance(stmt, ast.Loop | ast.For | ast.While | ast.Repeat):
        return (stmt.body,)
    if isinstance(stmt, ast.Switch):
        return (*(c.body for c in stmt.cases), stmt.default or ())
    return ()
