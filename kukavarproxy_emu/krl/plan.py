"""Compiled plans of simple KRL assignments: ``TARGET = SOURCE`` without walking the tree.

Most of an SPS pass is assignments between fixed variable paths: an SPS snapshot copies the
robot's readings into a structure (``CELL_W.AXIS_ACT = $AXIS_ACT``,
``CELL_W.TORQUE_AXIS_ACT_3 = $TORQUE_AXIS_ACT[3]``), counts its passes
(``CELL_W.CYCLE = CELL_W.CYCLE + 1``) and publishes the structure (``CELL = CELL_W``), every
12 ms. Walked as a tree, each assignment builds the variables' texts, parses them again in the
store, and converts and checks the value (a whole structure: every member) before the store
copies it in. An :class:`AssignPlan` resolves both paths once (:class:`~..slot.Slot`) and then
does only what the assignment itself does, with the same KRL rules:

* the source is a fixed path, a literal, or a fixed path ``+``/``-`` a literal;
* the value is converted to the target's type exactly as the tree walk converts it
  (:func:`~.runtime.convert`: REAL to INT rounds, structures narrow);
* a target that already holds the value is not written (the store's read cache stays warm and
  the cycle may count as a repeat: :mod:`.interp_skip`);
* a structure read from a variable of the target's very type is not checked again.

A plan applies only while its paths keep their declarations and no local of the routine
running shadows them; otherwise, and for anything it does not cover (an uninitialised source, an
error to word), the statement runs the general way, which raises the KRL error.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pyopenshowvar.krl import KrlValue, Struct

from ..slot import Slot
from ..values import Refused
from . import ast
from .runtime import (
    KRL_WRITABLE,
    Evaluator,
    KrlRuntimeError,
    _short,
    convert,
    literal_path,
    render,
)

if TYPE_CHECKING:
    from ..store import VariableStore

__all__ = ["AssignPlan"]

_LITERALS = (ast.IntLit, ast.RealLit, ast.BoolLit, ast.StrLit)


class AssignPlan:
    """One compiled ``TARGET = SOURCE`` of the global store; :meth:`run` or fall back."""

    __slots__ = ("constant", "ev", "op", "source", "stmt", "store", "target")

    def __init__(
        self,
        ev: Evaluator,
        stmt: ast.Assign,
        target: Slot,
        source: Slot | None,
        op: str | None,
        constant: KrlValue | None,
    ) -> None:
        self.ev, self.stmt, self.store = ev, stmt, ev.store
        self.target, self.source, self.op, self.constant = target, source, op, constant

    @classmethod
    def compile(cls, ev: Evaluator, stmt: ast.Assign) -> AssignPlan | None:
        """The plan of ``stmt``, or None when it is not one of the simple forms."""
        store, value = ev.store, stmt.value
        if not literal_path(stmt.target):
            return None
        op: str | None = None
        constant: KrlValue | None = None
        if isinstance(value, ast.Binary) and value.op in ("+", "-"):
            if not isinstance(value.right, ast.IntLit | ast.RealLit):
                return None
            op, constant, value = value.op, value.right.value, value.left
        if isinstance(value, _LITERALS):
            if op is not None:
                return None
            source, constant = None, value.value
        elif literal_path(value):
            source = _slot(store, value)
            if source is None:
                return None
        else:
            return None
        target = _slot(store, stmt.target)
        if target is None:
            return None
        base = target.var.name
        if base not in KRL_WRITABLE and store.is_read_only(base):
            return None  # the general way words the error
        return cls(ev, stmt, target, source, op, constant)

    def stale(self) -> bool:
        """A path was declared anew since the plan was compiled."""
        target, source = self.target, self.source
        declared = target.declared  # one store: current() of both, without two calls
        return declared.get(target.var.name) is not target.var or (
            source is not None and declared.get(source.var.name) is not source.var
        )

    def run(self, *, checked: bool = False) -> bool:
        """Do the assignment; False when the plan does not apply now (nothing was done).
        ``checked``: the caller knows the paths are current and no local shadows them."""
        ev, target, source = self.ev, self.target, self.source
        if checked:
            pass
        elif self.stale():
            return False  # a variable was declared anew
        elif ev.frames:  # the routine running now may have a local of the same name
            local = ev.frames[-1].names
            if target.var.name in local or (source is not None and source.var.name in local):
                return False
        if source is None:
            value = self.constant
        else:
            value = source.get()
            if value is None:
                return False  # not initialised: the general way raises the KRL error
            if self.op is not None:
                if not isinstance(value, int | float) or isinstance(value, bool):
                    return False
                node = self.stmt.value
                value = ev._arith(self.op, value, self.constant, node)  # type: ignore[arg-type]
        assert value is not None
        reads = ev.reads
        if reads is not None:
            if source is not None:
                reads.add((self.store, source.var.name))
            reads.add((self.store, target.var.name))
        self.put(value, copied=source is not None and self.op is None)
        return True

    def put(self, value: KrlValue, *, copied: bool) -> None:
        """The assignment's second half: convert ``value`` to the target's type and store it
        (not written when the target holds it already); ``copied``: ``value`` was read as it
        is from the store (a structure of the target's very type is not checked again)."""
        target = self.target
        converted = convert(
            value, target.chain[-1][0], target.type_name, self.store.registry, self.stmt
        )
        if target.get() == converted:
            return  # nothing observable changes
        valid = (
            copied
            and converted is value
            and isinstance(converted, Struct)
            and converted.type_name == target.type_name
        )
        try:
            target.set(converted, valid=valid)
        except Refused as exc:
            text = render(self.stmt.target)
            raise KrlRuntimeError(f"{text} = {_short(converted)}: {exc}", self.stmt) from None


def _slot(store: VariableStore, expr: ast.Expr) -> Slot | None:
    return Slot.compile(store, render(expr))
