"""The carried statements of a lazy SPS pass (:mod:`.lazy_pass`): the ones the next pass reads.

:class:`Carried` runs one now, as the interpreter would (a compiled plan, or an ``IF`` on a
compared path with a compiled condition instead of the tree walk). :class:`Counter` goes one
step further for the statements that only count: an ``IF P < L THEN P = P + 1 ELSE P = 1``
(any comparison and literals, or a bare ``P = P + 1``) on one INT or REAL path ``P``. Its
step is computed in Python with the interpreter's own rules (:meth:`Evaluator._arith`,
:func:`convert`, the store's :func:`check`) and the value is written when the pass's
deferred copies are made: nobody can read ``P`` before that (it belongs to the pass's stale
variables). A step that would fail (an INT overflow) is not computed here: the pass then
runs its carried statements now, which raises the KRL error when it happens.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pyopenshowvar.krl import Kind, KrlValue, Struct

from ..slot import Slot
from ..values import Refused, check
from . import ast
from .runtime import _INT_MAX, _INT_MIN, KrlRuntimeError, _compare, convert

if TYPE_CHECKING:
    from .interp import Interpreter
    from .plan import AssignPlan

__all__ = ["Carried", "Counter", "peek", "pick"]


def peek(slot: Slot) -> KrlValue | None:
    """The value at ``slot`` as the store holds it now, without filling a stale value."""
    value: KrlValue | None = slot.var.elems[slot.index]
    for member in slot.members:
        value = value._members.get(member) if isinstance(value, Struct) else None
    return value


def pick(whole: object, slot: Slot) -> KrlValue | None:
    """The part ``slot`` of a whole variable's value (a list for an array)."""
    value = whole[slot.index] if isinstance(whole, list) and slot.var.is_array else whole
    for member in slot.members:
        value = value._members.get(member) if isinstance(value, Struct) else None
    return value  # type: ignore[return-value]


class Carried:
    """A carried statement run now: a plan, or an ``IF <path> <op> <number>`` of plans."""

    __slots__ = ("_plans", "cond", "els", "interp", "limit", "op", "stmt", "then")

    def __init__(
        self,
        interp: Interpreter,
        stmt: ast.Stmt,
        plans: dict[int, AssignPlan],
        conds: dict[int, Slot],
    ) -> None:
        self.interp, self.stmt = interp, stmt
        self.cond: Slot | None = None
        self.op, self.limit = "", 0.0
        self.then: tuple[ast.Assign, ...] = ()
        self.els: tuple[ast.Assign, ...] = ()
        if isinstance(stmt, ast.If):
            cond = stmt.cond
            assert isinstance(cond, ast.Binary) and isinstance(cond.right, ast.IntLit | ast.RealLit)
            self.cond = conds[id(stmt)]  # the compared path (see LazyPass._unit)
            self.op, self.limit = cond.op, cond.right.value
            self.then, self.els = stmt.then_body, stmt.else_body  # type: ignore[assignment]
        self._plans = plans

    def run(self) -> int:
        """Run it as the interpreter would; the statements it counts."""
        stmt = self.stmt
        if isinstance(stmt, ast.Assign):
            self._assign(stmt)
            return 1
        assert isinstance(stmt, ast.If) and self.cond is not None
        value = self.cond.get()
        if isinstance(value, int | float) and not isinstance(value, bool):
            taken = _compare(self.op, value, self.limit)
        else:  # not a number or not initialised: the general way words the error
            cond = self.interp.ev.eval(stmt.cond)
            if not isinstance(cond, bool):
                raise KrlRuntimeError("condition is not BOOL", stmt.cond)
            taken = cond
        body = self.then if taken else self.els
        for assign in body:
            self._assign(assign)
        return 1 + len(body)

    def _assign(self, stmt: ast.Assign) -> None:
        # the paths are current and not shadowed (LazyPass.run and compile checked)
        if not self._plans[id(stmt)].run(checked=True):  # else the general way (its error)
            ev = self.interp.ev
            ev.assign(stmt.target, ev.eval(stmt.value), stmt)


class Counter:
    """A carried statement that only counts on one numeric path (see the module)."""

    __slots__ = ("cond", "els", "ev", "limit", "op", "slot", "stmt", "then")

    def __init__(self, carried: Carried, slot: Slot, then: AssignPlan | None,
                 els: AssignPlan | None) -> None:  # fmt: skip
        self.stmt, self.cond, self.op, self.limit = (
            carried.stmt,
            carried.cond,
            carried.op,
            carried.limit,
        )
        self.ev, self.slot, self.then, self.els = carried.interp.ev, slot, then, els

    @classmethod
    def compile(cls, carried: Carried, plans: dict[int, AssignPlan]) -> Counter | None:
        """The counter form of ``carried``, or None when it is not one."""
        stmt = carried.stmt
        if isinstance(stmt, ast.Assign):
            assign = plans[id(stmt)]
            return cls._of(carried, assign.target, assign, None) if cls._counts(assign) else None
        assert isinstance(stmt, ast.If) and carried.cond is not None
        slot = carried.cond
        branches: list[AssignPlan | None] = []
        for body in (carried.then, carried.els):
            if len(body) > 1:
                return None
            plan = plans[id(body[0])] if body else None
            if plan is not None and (plan.target.name != slot.name or not cls._counts(plan)):
                return None
            branches.append(plan)
        return cls._of(carried, slot, *branches)

    @staticmethod
    def _counts(plan: AssignPlan) -> bool:
        """``P = literal`` or ``P = P ± literal``."""
        source = plan.source
        return source is None or (source.name == plan.target.name and source.var is plan.target.var)

    @classmethod
    def _of(cls, carried: Carried, slot: Slot, then: AssignPlan | None,
            els: AssignPlan | None) -> Counter | None:  # fmt: skip
        kind = slot.chain[-1][0].kind
        if kind is not Kind.INT and kind is not Kind.REAL:
            return None
        for plan in (then, els):
            if plan is not None and plan.target.var is not slot.var:
                return None
        return cls(carried, slot, then, els)

    def step(self, value: KrlValue) -> tuple[KrlValue, int] | None:
        """The value after one pass and the statements it counts; None when the step
        cannot be computed here (the pass then runs as before)."""
        if not isinstance(value, int | float) or isinstance(value, bool):
            return None
        if self.cond is None:
            plan, count = self.then, 1
        else:
            taken = _compare(self.op, value, self.limit)
            plan = self.then if taken else self.els
            count = 1 + (plan is not None)
        if plan is None:
            return value, count
        constant = plan.constant
        if type(value) is int and type(constant) is int and plan.target.type_name == "INT":
            # INT counting, the common case, inline: what _arith, convert and check do for
            # an INT result within 32 bits (beyond: the general way below raises)
            op = plan.op
            new_int = constant if op is None and plan.source is None else (
                value + constant if op == "+" else value - constant if op == "-" else None
            )  # fmt: skip
            if new_int is not None and _INT_MIN <= new_int <= _INT_MAX:
                return new_int, count
        try:
            new: KrlValue = value if plan.source is not None else plan.constant  # type: ignore[assignment]
            if plan.op is not None:
                new = self.ev._arith(plan.op, value, plan.constant, plan.stmt.value)  # type: ignore[arg-type]
            target = plan.target
            spec, type_name = target.chain[-1]
            new = convert(new, spec, type_name, target.store.registry, plan.stmt)
            check(new, spec, type_name, target.store.registry)
        except (KrlRuntimeError, Refused):
            return None  # it fails: let the pass run now and raise it then
        return new, count
