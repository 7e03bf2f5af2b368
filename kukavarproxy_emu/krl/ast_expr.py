"""Expression nodes of the KRL AST (and the :class:`Node` base); see :mod:`.ast`.

Kept apart only to keep each module short: import everything from
:mod:`kukavarproxy_emu.krl.ast`, which re-exports these names.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeAlias

from pyopenshowvar.krl import KrlValue

__all__ = [
    "Aggregate", "AggregateItem", "Binary", "BoolLit", "Call", "EnumLit", "Expr", "Index",
    "IntLit", "Member", "Name", "Node", "RealLit", "StrLit", "Unary", "Value",
]  # fmt: skip


@dataclass(frozen=True, slots=True, kw_only=True)
class Node:
    """Base of every node: where it starts in the source (1-based line and column)."""

    line: int
    column: int


# --------------------------------------------------------------------------- expressions


@dataclass(frozen=True, slots=True)
class IntLit(Node):
    """An INT literal: decimal ``42`` or bit literal ``'B1010'`` / ``'H1F'``."""

    value: int


@dataclass(frozen=True, slots=True)
class RealLit(Node):
    """A REAL literal (``1.5``, ``.5``, ``1E-3``)."""

    value: float


@dataclass(frozen=True, slots=True)
class BoolLit(Node):
    """``TRUE`` or ``FALSE``."""

    value: bool


@dataclass(frozen=True, slots=True)
class StrLit(Node):
    """A CHAR string literal ``"..."`` (without the quotes; KRL has no escapes)."""

    value: str


@dataclass(frozen=True, slots=True)
class EnumLit(Node):
    """An ENUM literal ``#NAME``; ``name`` is upper-case without the ``#``."""

    name: str


@dataclass(frozen=True, slots=True)
class AggregateItem(Node):
    """One ``NAME value`` member of an aggregate."""

    name: str
    value: Expr


@dataclass(frozen=True, slots=True)
class Aggregate(Node):
    """A structure literal ``{A1 0.0, A2 -90.0}`` or ``{E6AXIS: A1 0.0, ...}``.

    ``type_name`` is the explicit type before ``:`` (or ``None``). Member values are constants
    (literals, unary minus, nested aggregates), as in real KRL. ``text`` is the exact source
    text so the executor may hand it to :func:`pyopenshowvar.krl.parse_value` instead.
    """

    type_name: str | None
    items: tuple[AggregateItem, ...]
    text: str


@dataclass(frozen=True, slots=True)
class Name(Node):
    """A variable reference (``COUNT``, ``$OV_PRO``, ``HOME``)."""

    name: str


@dataclass(frozen=True, slots=True)
class Index(Node):
    """An array element ``base[i]`` or ``base[i, j]`` (KRL arrays are 1-based).

    Empty ``indices`` is ``NAME[]``, the whole array (``NAME[] = "text"`` for CHAR arrays).
    ``line``/``column`` are those of the ``[``.
    """

    base: Expr
    indices: tuple[Expr, ...]


@dataclass(frozen=True, slots=True)
class Member(Node):
    """A structure member ``base.NAME`` (``LOCAL.A1``, ``$AXIS_ACT.A1``); ``line``/``column``
    are those of the member name."""

    base: Expr
    member: str


@dataclass(frozen=True, slots=True)
class Unary(Node):
    """``NOT x``, ``-x``, ``+x``, ``B_NOT x``."""

    op: str
    operand: Expr


@dataclass(frozen=True, slots=True)
class Binary(Node):
    """A binary operation; ``line``/``column`` are those of the operator."""

    op: str
    left: Expr
    right: Expr


@dataclass(frozen=True, slots=True)
class Call(Node):
    """A function call in an expression: a built-in (``SIN``, ``ATAN2``...) or a DEFFCT."""

    name: str
    args: tuple[Expr, ...]


@dataclass(frozen=True, slots=True)
class Value(Node):
    """A value the executor has computed already. Never produced by the parser: the executor
    puts it in place of a user function call (or of an operand evaluated before one) so that
    the rest of the expression can be evaluated without running the call again."""

    value: KrlValue


Expr: TypeAlias = (
    IntLit
    | RealLit
    | BoolLit
    | StrLit
    | EnumLit
    | Aggregate
    | Name
    | Index
    | Member
    | Unary
    | Binary
    | Call
    | Value
)


def is_lvalue(expr: Expr) -> bool:
    """Whether ``expr`` names storage: a variable, or a member or element of one."""
    if isinstance(expr, Name):
        return True
    if isinstance(expr, Member | Index):
        return is_lvalue(expr.base)
    return False
