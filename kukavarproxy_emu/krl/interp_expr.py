"""Expressions inside the KRL executor: user functions run as generators, like statements.

:class:`~.runtime.Evaluator` evaluates an expression in one go. That is right for the common
case, but a user ``DEFFCT`` called from an expression runs statements, and those must count
against the cycle's statement and wall-time budget and be able to wait for the next cycle like
any other statement; otherwise one ``LOOP R = SLOW() ENDLOOP`` or a function that never
returns holds the event loop (and every client of the emulator) for as long as it runs.

So an expression that contains a user call is evaluated here, operand by operand in the
Evaluator's order (left to right, ``AND``/``OR`` short-circuit): each call runs as a generator
through the interpreter's ``_call_fn``, and each operand already computed is replaced by an
:class:`~.ast.Value` node, so the Evaluator then finishes the expression without running any
call twice. Expressions without user calls (almost all of them) go straight to the Evaluator.
"""

from __future__ import annotations

from collections.abc import Generator
from dataclasses import replace

from pyopenshowvar.krl import KrlValue

from . import ast
from .runtime import BUILTINS, Evaluator, KrlRuntimeError

__all__ = ["ExprMixin", "is_user_call"]

Eval = Generator[str, None, KrlValue]


def is_user_call(expr: ast.Expr) -> bool:
    """A call of a routine of the program (not a built-in such as SIN or ATAN2)."""
    return isinstance(expr, ast.Call) and expr.name not in BUILTINS and expr.name != "ATAN2"


def _children(expr: ast.Expr) -> tuple[ast.Expr, ...]:
    if isinstance(expr, ast.Index):
        return (expr.base, *expr.indices)
    if isinstance(expr, ast.Member):
        return (expr.base,)
    if isinstance(expr, ast.Unary):
        return (expr.operand,)
    if isinstance(expr, ast.Binary):
        return (expr.left, expr.right)
    if isinstance(expr, ast.Call):
        return expr.args
    return ()  # aggregates hold constants only


class ExprMixin:
    """The expression part of :class:`~.interp.Interpreter` (needs ``ev`` and ``_call_fn``)."""

    ev: Evaluator
    _user_calls: dict[int, bool]

    def _call_fn(self, call: ast.Call) -> Eval:
        raise NotImplementedError  # provided by Interpreter

    def _has_call(self, expr: ast.Expr) -> bool:
        """Whether ``expr`` contains a user function call (cached per node of the program)."""
        if isinstance(expr, ast.Value):
            return False  # made during evaluation: not cached (its id may be reused)
        key = id(expr)
        cached = self._user_calls.get(key)
        if cached is None:
            cached = is_user_call(expr) or any(self._has_call(c) for c in _children(expr))
            self._user_calls[key] = cached
        return cached

    def _eval(self, expr: ast.Expr) -> Eval:
        """The value of ``expr``; user calls in it run as generators (they may yield)."""
        if not self._has_call(expr):
            return self.ev.eval(expr)
        if isinstance(expr, ast.Call):
            if is_user_call(expr):
                return (yield from self._call_fn(expr))
            args = []
            for arg in expr.args:
                args.append(self._value(arg, (yield from self._eval(arg))))
            return self.ev.eval(replace(expr, args=tuple(args)))
        if isinstance(expr, ast.Binary):
            left = yield from self._eval(expr.left)
            if (expr.op == "AND" and left is False) or (expr.op == "OR" and left is True):
                return left  # short-circuit, as the Evaluator does
            right = yield from self._eval(expr.right)
            node = replace(expr, left=self._value(expr.left, left))
            return self.ev.eval(replace(node, right=self._value(expr.right, right)))
        if isinstance(expr, ast.Unary):
            operand = yield from self._eval(expr.operand)
            return self.ev.eval(replace(expr, operand=self._value(expr.operand, operand)))
        return self.ev.eval((yield from self._lower(expr)))

    def _lower(self, expr: ast.Expr) -> Generator[str, None, ast.Expr]:
        """``expr`` with every user call in it computed: an lvalue stays an lvalue (its
        indices become values), anything else becomes a :class:`~.ast.Value`."""
        if not self._has_call(expr):
            return expr
        if isinstance(expr, ast.Index | ast.Member):
            if ast.is_lvalue(expr.base):
                base = yield from self._lower(expr.base)
            else:
                base = self._value(expr.base, (yield from self._eval(expr.base)))
            if isinstance(expr, ast.Member):
                return replace(expr, base=base)
            indices = []
            for index in expr.indices:
                indices.append(self._value(index, (yield from self._eval(index))))
            return replace(expr, base=base, indices=tuple(indices))
        return self._value(expr, (yield from self._eval(expr)))

    def _cond(self, expr: ast.Expr) -> Generator[str, None, bool]:
        value = yield from self._eval(expr)
        if not isinstance(value, bool):
            raise KrlRuntimeError("condition is not BOOL", expr)
        return value

    @staticmethod
    def _value(node: ast.Expr, value: KrlValue) -> ast.Value:
        return ast.Value(value, line=node.line, column=node.column)
