"""Motion statements of the KRL executor, mapped onto the motion kernel's planning API.

``PTP``/``PTP_REL``/``LIN``/``LIN_REL`` with ``C_PTP``/``C_DIS``/``C_VEL``/``C_ORI`` become
:meth:`MotionKernel.ptp` & co. with ``approx=True`` (the kernel uses ``$APO.CPTP`` for PTP and
``$APO.CDIS`` for LIN, and blends only into an already planned motion). The inline form
``PTP HOME Vel = 100 % DEFAULT`` sets ``$VEL_AXIS[1..6]`` (PTP) or ``$VEL.CP`` (LIN) as KUKA's
inline forms do and moves to ``X<name>`` (the ILF convention, e.g. ``XHOME``), else ``<name>``,
else, for ``HOME``, the KR 6's home position A1..A6 = 0, -90, 90, 0, 0, 0.

A partial absolute target (``PTP {A1 10}``) keeps the other axes/coordinates of the planned
end point; a partial increment adds zero for the missing members, as KRL does.
"""

from __future__ import annotations

from collections.abc import Generator
from typing import TYPE_CHECKING, Any

import numpy as np

from pyopenshowvar.krl import KrlValue, Struct

from ..motion.kernel import MotionRefused
from . import ast
from .runtime import KrlRuntimeError, is_number, render

if TYPE_CHECKING:
    from ..motion.kernel import MotionKernel, PlanJob
    from ..store import VariableStore
    from .runtime import Evaluator

__all__ = ["AT_ONCE", "BUDGET", "HOME_AXES", "PASS", "WAIT", "MotionMixin"]

#: What a statement generator yields: the reason it waits for the next cycle.
BUDGET, WAIT = "budget", "wait"
#: The submit interpreter finished one pass of its LOOP.
PASS = "pass"
#: The robot program waits after motions that completed at once (the robot is on the target).
AT_ONCE = "at-once"
#: Home position of the KR 6 R900 sixx (used for ``PTP HOME`` without an XHOME variable).
HOME_AXES = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)
_AXES = tuple(f"A{i}" for i in range(1, 7))
_POSE = ("X", "Y", "Z", "A", "B", "C")


class MotionMixin:
    """The motion part of :class:`~.interp.Interpreter` (needs its attributes below)."""

    kernel: MotionKernel | None
    _pass_loop: int | None
    store: VariableStore
    ev: Evaluator
    at_once: int
    _plan_until: float

    def _stop_if_reads(self, *exprs: ast.Expr | None) -> Generator[str, None, None]:
        raise NotImplementedError  # provided by Interpreter

    def _eval(self, expr: ast.Expr) -> Generator[str, None, KrlValue]:
        raise NotImplementedError  # provided by ExprMixin

    def _lower(self, expr: ast.Expr) -> Generator[str, None, ast.Expr]:
        raise NotImplementedError  # provided by ExprMixin

    def advance(self) -> int:
        """``$ADVANCE`` (0..5)."""
        if self.ev.reads is not None:
            self.ev.reads.add((self.store, "$ADVANCE"))
        value = self.store.get("$ADVANCE")
        return value if isinstance(value, int) and not isinstance(value, bool) else 3

    def _motion(self, stmt: ast.Motion | ast.InlineMotion) -> Generator[str, None, None]:
        kernel = self.kernel
        if kernel is None:
            raise KrlRuntimeError(f"{stmt.kind}: no motions in the submit interpreter", stmt)
        if stmt.kind.startswith("CIRC"):
            raise KrlRuntimeError(f"{stmt.kind} is not supported by the emulator", stmt)
        yield from self._stop_if_reads(stmt.target)
        while not kernel.can_plan(self.advance()):
            yield WAIT
        # The advance run reads the target now: it is captured when the motion is planned.
        if isinstance(stmt, ast.InlineMotion):
            target, label = yield from self._inline(stmt)
            approx = stmt.cont
        else:
            expr = yield from self._lower(stmt.target)  # a user call in it runs once, here
            target = self.ev.eval(expr)
            label = f"{stmt.kind} {render(expr, self._index_text)}"
            approx = stmt.approx is not None
        try:
            tool = isinstance(stmt, ast.Motion) and stmt.frame == "TOOL"
            job = self._plan(kernel, stmt.kind, target, approx, label, stmt, tool=tool)
            # A LIN is planned in slices within this cycle's time budget; the advance run
            # stays on the statement until it is planned (or refused), as on a KRC.
            while job is not None and not job.step(self._plan_until):
                yield WAIT
        except MotionRefused as exc:
            raise KrlRuntimeError(str(exc), stmt) from None
        if not kernel.moving:  # completed at once: the robot stands on the target
            self.at_once += 1
            if self.at_once > 1:
                self._pass_loop = id(stmt)
                yield AT_ONCE  # a loop of such motions runs once per cycle, it does not spin

    def _index_text(self, expr: ast.Expr) -> str:
        try:
            return str(self.ev.eval(expr))
        except KrlRuntimeError:
            return render(expr)

    def _plan(
        self,
        kernel: MotionKernel,
        kind: str,
        target: KrlValue,
        approx: bool,
        label: str,
        node: ast.Node,
        *,
        tool: bool = False,
    ) -> PlanJob | None:
        """Plan the motion; a LIN comes back as a job still to be stepped."""
        if not isinstance(target, Struct):
            raise KrlRuntimeError(f"{kind} needs an AXIS/E6AXIS or POS/E6POS/FRAME target", node)
        relative = kind.endswith("_REL")
        if any(a in target for a in _AXES):
            if tool:
                raise KrlRuntimeError(f"{kind} #TOOL needs a POS/FRAME increment", node)
            if kind.startswith("LIN"):
                raise KrlRuntimeError(f"{kind} to an axis target is not supported", node)
            base = np.zeros(6) if relative else kernel.planned_q
            q = self._vector(target, _AXES, base, node)
            if relative:
                kernel.ptp_rel(q, approx=approx, label=label)
            else:
                kernel.ptp(q, approx=approx, label=label)
            return None
        if not any(k in target for k in _POSE):
            raise KrlRuntimeError(f"{kind} target has neither A1..A6 nor X..C", node)
        if relative:
            inc = self._vector(target, _POSE, np.zeros(6), node)
            if kind == "PTP_REL":
                kernel.ptp_rel_pose(inc, approx=approx, tool=tool, label=label)
                return None
            return kernel.plan_lin_rel(inc, approx=approx, tool=tool, label=label)
        pose = self._vector(target, _POSE, kernel.planned_pose(), node)
        if kind == "PTP":
            s, t = target.get("S"), target.get("T")
            kernel.ptp_pose(pose, s=_int_or_none(s), t=_int_or_none(t), approx=approx, label=label)
            return None
        return kernel.plan_lin(pose, approx=approx, label=label)

    @staticmethod
    def _vector(target: Struct, keys: tuple[str, ...], base: Any, node: ast.Node) -> Any:
        out = np.array(base, dtype=np.float64).copy()
        for i, key in enumerate(keys):
            if key in target:
                value = target[key]
                if not is_number(value):
                    raise KrlRuntimeError(f"member {key} is not a number", node)
                out[i] = float(value)  # type: ignore[arg-type]
        return out

    def _inline(self, stmt: ast.InlineMotion) -> Generator[str, None, tuple[KrlValue, str]]:
        """Target and label of ``PTP HOME Vel = 100 % DEFAULT``; sets the velocity."""
        velocity = yield from self._eval(stmt.velocity)
        if not is_number(velocity) or float(velocity) <= 0:  # type: ignore[arg-type]
            raise KrlRuntimeError("inline form: the velocity must be a positive number", stmt)
        vel = float(velocity)  # type: ignore[arg-type]
        if stmt.kind == "PTP":
            pct = max(1, min(100, round(vel)))
            for i in range(1, 7):
                self.store.set_system(f"$VEL_AXIS[{i}]", pct)
        else:
            self.store.set_system("$VEL.CP", min(vel, 2.0))
        target: KrlValue
        name = stmt.target.name if isinstance(stmt.target, ast.Name) else None
        if name is not None and self.ev.has("X" + name):
            target = self.ev.eval(ast.Name("X" + name, line=stmt.line, column=stmt.column))
        elif name == "HOME" and not self.ev.has("HOME"):
            target = Struct(None, dict(zip(_AXES, HOME_AXES, strict=True)))
        else:
            target = yield from self._eval(stmt.target)
        return target, f"{stmt.kind} {render(stmt.target)}"


def _int_or_none(value: KrlValue | None) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None
