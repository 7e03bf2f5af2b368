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
cycle and the server keeps answering promptly. A motion
that completes at once (the robot already stands on its target) may run once per cycle
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
from .interp_motion import BUDGET, WAIT, MotionMixin
from .runtime import ACTUAL_POSITION, Evaluator, Frame, KrlRuntimeError, convert, is_number

if TYPE_CHECKING:
    from ..motion.kernel import MotionKernel
    from ..store import VariableStore

__all__ = ["DEFAULT_BUDGET", "Interpreter"]

#: Statements per interpolation cycle before the interpreter yields to the event loop.
DEFAULT_BUDGET = 2000
#: Wall seconds of statements per cycle, whichever of the two limits comes first: a runaway loop
#: then costs the server at most this much latency per cycle, however slow the statements are.
TIME_BUDGET = 0.002
#: A DEFFCT called from an expression runs to completion; beyond this it is a runaway.
FUNCTION_LIMIT = 200_000

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


class Interpreter(MotionMixin):
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
        self.at_once = 0  # motions that completed at once this cycle
        self.total = 0  # statements since start (diagnostics, tests)
        self.finished = False
        self.halted = False
        #: Simulated seconds of the submit interpreter (the robot program uses the kernel's).
        self.sim_time = 0.0
        self._gen: Gen | None = None
        self._reads: dict[int, bool] = {}

    # --- driving -------------------------------------------------------------------------------
    def start(self) -> None:
        """(Re)start the main routine from its first statement."""
        self.frames.clear()
        self.finished = self.halted = False
        self._gen = self._main()

    def step(self) -> None:
        """Run one cycle's worth of statements; raises :class:`KrlRuntimeError`."""
        if self._gen is None or self.finished or self.halted:
            return
        self.count = self.at_once = 0
        self._until = time.perf_counter() + TIME_BUDGET
        try:
            next(self._gen)
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

    def _main(self) -> Gen:
        yield from self._invoke(self.module.main, (), self.module.main)
        yield from self._advance_stop()  # END: the program ends when the robot has arrived
        return None

    # --- helpers -------------------------------------------------------------------------------
    def _tick(self) -> Generator[str, None, None]:
        """Count one statement; yield when this cycle's budget is used up."""
        self.count += 1
        self.total += 1
        if self.count > self.budget or (not self.count & 63 and time.perf_counter() > self._until):
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

    def _bool(self, expr: ast.Expr) -> bool:
        value = self.ev.eval(expr)
        if not isinstance(value, bool):
            raise KrlRuntimeError("condition is not BOOL", expr)
        return value

    # --- routines ------------------------------------------------------------------------------
    def _invoke(self, routine: ast.Routine, args: tuple[ast.Expr, ...], node: ast.Node) -> Gen:
        """Call ``routine`` with ``args``; returns its _Return (the DEFFCT value)."""
        if len(args) > len(routine.params):
            raise KrlRuntimeError(f"{routine.name} takes {len(routine.params)} argument(s)", node)
        values = [self.ev.eval(a) for a in args]
        refs = [self.ev.ref(a) if p.direction == "OUT" and _lvalue(a) else None
                for p, a in zip(routine.params, args, strict=False)]  # fmt: skip
        frame = Frame(routine, self.store)
        for param, value in zip(routine.params, values, strict=False):
            if param.name not in frame.names:
                raise KrlRuntimeError(f"parameter {param.name} has no DECL", routine)
            self.ev.frames.append(frame)
            try:
                self.ev.put(frame.store, param.name, param.name, value, node)
            finally:
                self.ev.frames.pop()
        if len(self.frames) > 64:
            raise KrlRuntimeError("call stack overflow (endless recursion?)", node)
        self.frames.append(frame)
        try:
            signal = yield from self._block(routine.body)
        finally:
            self.frames.pop()
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

    def _call_function(self, call: ast.Call) -> KrlValue:
        """Run a user DEFFCT to completion (it is called from inside an expression)."""
        routine = self.module.routine(call.name)
        if routine is None:
            raise KrlRuntimeError(f"unknown function {call.name}", call)
        if not routine.is_function:
            raise KrlRuntimeError(f"{call.name} is a DEF, not a DEFFCT", call)
        gen = self._invoke(routine, call.args, call)
        saved, steps = self.count, 0
        try:
            while True:
                reason = next(gen)
                if reason != BUDGET:
                    raise KrlRuntimeError(
                        f"{call.name}: WAIT or motion inside a function used in an expression"
                        " is not supported by the emulator",
                        call,
                    )
                steps += self.count
                self.count = 0
                if steps > FUNCTION_LIMIT:
                    raise KrlRuntimeError(f"function {call.name} does not return", call)
        except StopIteration as stop:
            result = stop.value
        finally:
            gen.close()
            self.count = saved
        assert isinstance(result, _Return) and result.value is not None
        return result.value

    # --- statements ----------------------------------------------------------------------------
    def _block(self, body: tuple[ast.Stmt, ...]) -> Gen:
        for stmt in body:
            signal = yield from self._stmt(stmt)
            if signal is not None:
                return signal
        return None

    def _stmt(self, stmt: ast.Stmt) -> Gen:
        yield from self._tick()
        if isinstance(stmt, ast.Assign):
            yield from self._stop_if_reads(stmt.target, stmt.value)
            self.ev.assign(stmt.target, self.ev.eval(stmt.value), stmt)
        elif isinstance(stmt, ast.Motion | ast.InlineMotion):
            yield from self._motion(stmt)
        elif isinstance(stmt, ast.If):
            yield from self._stop_if_reads(stmt.cond)
            body = stmt.then_body if self._bool(stmt.cond) else stmt.else_body
            return (yield from self._block(body))
        elif isinstance(stmt, ast.Loop):
            return (yield from self._loop(stmt))
        elif isinstance(stmt, ast.For):
            return (yield from self._for(stmt))
        elif isinstance(stmt, ast.While):
            while True:
                yield from self._stop_if_reads(stmt.cond)
                if not self._bool(stmt.cond):
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
                if self._bool(stmt.cond):
                    return None
                yield from self._tick()
        elif isinstance(stmt, ast.Switch):
            return (yield from self._switch(stmt))
        elif isinstance(stmt, ast.WaitFor):
            yield from self._advance_stop()
            while not self._bool(stmt.cond):
                yield WAIT
        elif isinstance(stmt, ast.WaitSec):
            yield from self._wait_sec(stmt)
        elif isinstance(stmt, ast.CallStmt):
            yield from self._call_stmt(stmt)
        elif isinstance(stmt, ast.Return):
            if stmt.value is None:
                return _Return(None)
            yield from self._stop_if_reads(stmt.value)
            return _Return(self.ev.eval(stmt.value))
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
                yield WAIT  # the SPS runs its LOOP body once per cycle
            yield from self._tick()

    def _for(self, stmt: ast.For) -> Gen:
        yield from self._stop_if_reads(stmt.start, stmt.stop, stmt.step)
        var = ast.Name(stmt.var, line=stmt.line, column=stmt.column)
        first, last = self.ev.eval(stmt.start), self.ev.eval(stmt.stop)
        step = self.ev.eval(stmt.step) if stmt.step is not None else 1
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
        selector = self.ev.eval(stmt.selector)
        for case in stmt.cases:
            if any(self.ev.eval(v) == selector for v in case.values):
                return (yield from self._block(case.body))
        if stmt.default is not None:
            return (yield from self._block(stmt.default))
        return None

    def _wait_sec(self, stmt: ast.WaitSec) -> Gen:
        yield from self._advance_stop()
        seconds = self.ev.eval(stmt.seconds)
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
