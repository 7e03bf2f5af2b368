"""The KRL abstract syntax tree produced by :mod:`kukavarproxy_emu.krl.parser`.

Every node is a frozen, slotted dataclass carrying the 1-based ``line`` and ``column`` of the
token that starts it, so the executor can report runtime errors exactly like syntax errors.
``line`` and ``column`` are keyword-only and come after the node's own fields in the
constructor (``Name("X", line=3, column=5)``).

Conventions the executor can rely on:

* names (variables, routines, members, types, enum values) are upper-case, because KRL names
  are case-insensitive; system variables keep their ``$`` (``$OUT``, ``$AXIS_ACT``);
* operators are normalised strings: ``"NOT" "-" "+" "B_NOT"`` (unary) and
  ``"*" "/" "+" "-" ":" "==" "<>" "<" "<=" ">" ">=" "AND" "OR" "EXOR" "B_AND" "B_OR"
  "B_EXOR"`` (binary);
* bit literals (``'B1010'``, ``'H1F'``) are plain :class:`IntLit`;
* declarations are the :mod:`pyopenshowvar.krl.datfile` records (one declaration parser for
  ``$CONFIG.DAT``, module ``.dat`` files and ``DECL`` lines inside a ``DEF``): initial values
  stay KRL literal text for :func:`pyopenshowvar.krl.parse_value`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeAlias

from pyopenshowvar.krl.datfile import DatFile, Declaration, EnumDecl, StrucDecl

from .ast_expr import (
    Aggregate,
    AggregateItem,
    Binary,
    BoolLit,
    Call,
    EnumLit,
    Expr,
    Index,
    IntLit,
    Member,
    Name,
    Node,
    RealLit,
    StrLit,
    Unary,
    Value,
    is_lvalue,
)

__all__ = [
    "Aggregate",
    "AggregateItem",
    "Assign",
    "Binary",
    "BoolLit",
    "Call",
    "CallStmt",
    "Case",
    "Continue",
    "Decl",
    "EnumDef",
    "EnumLit",
    "Exit",
    "Expr",
    "For",
    "Halt",
    "If",
    "Index",
    "Ini",
    "InlineMotion",
    "IntLit",
    "Loop",
    "Member",
    "Module",
    "Motion",
    "Name",
    "Node",
    "Param",
    "RealLit",
    "Repeat",
    "Return",
    "Routine",
    "Stmt",
    "StrLit",
    "StrucDef",
    "Switch",
    "Unary",
    "Value",
    "WaitFor",
    "WaitSec",
    "While",
    "is_lvalue",
]


# ---------------------------------------------------------------------------- statements


@dataclass(frozen=True, slots=True)
class Decl(Node):
    """A ``DECL`` line inside a routine (may declare several variables)."""

    declarations: tuple[Declaration, ...]


@dataclass(frozen=True, slots=True)
class StrucDef(Node):
    """A ``STRUC`` type definition line inside a routine."""

    struc: StrucDecl


@dataclass(frozen=True, slots=True)
class EnumDef(Node):
    """An ``ENUM`` type definition line inside a routine."""

    enum: EnumDecl


@dataclass(frozen=True, slots=True)
class Assign(Node):
    """``target = value``; ``target`` is a :class:`Name`, :class:`Index` or :class:`Member`."""

    target: Expr
    value: Expr


@dataclass(frozen=True, slots=True)
class CallStmt(Node):
    """A call of another DEF as a statement (``MOVE_TO(3)``).

    ``BAS(#INITMOV, 0)`` and the other KUKA system library calls inside ``INI`` folds also
    parse to this node; the executor treats ``BAS`` as a no-op.
    """

    name: str
    args: tuple[Expr, ...]


@dataclass(frozen=True, slots=True)
class If(Node):
    """``IF cond THEN ... [ELSE ...] ENDIF``; ``else_body`` is empty without ``ELSE``."""

    cond: Expr
    then_body: tuple[Stmt, ...]
    else_body: tuple[Stmt, ...]


@dataclass(frozen=True, slots=True)
class Loop(Node):
    """``LOOP ... ENDLOOP`` (left only by ``EXIT``)."""

    body: tuple[Stmt, ...]


@dataclass(frozen=True, slots=True)
class Exit(Node):
    """``EXIT``: leave the innermost LOOP/FOR/WHILE/REPEAT."""


@dataclass(frozen=True, slots=True)
class For(Node):
    """``FOR var = start TO stop [STEP step] ... ENDFOR`` (``step`` ``None`` means 1)."""

    var: str
    start: Expr
    stop: Expr
    step: Expr | None
    body: tuple[Stmt, ...]


@dataclass(frozen=True, slots=True)
class While(Node):
    """``WHILE cond ... ENDWHILE``."""

    cond: Expr
    body: tuple[Stmt, ...]


@dataclass(frozen=True, slots=True)
class Repeat(Node):
    """``REPEAT ... UNTIL cond`` (the body runs at least once)."""

    body: tuple[Stmt, ...]
    cond: Expr


@dataclass(frozen=True, slots=True)
class Case(Node):
    """One ``CASE v1, v2`` branch of a SWITCH."""

    values: tuple[Expr, ...]
    body: tuple[Stmt, ...]


@dataclass(frozen=True, slots=True)
class Switch(Node):
    """``SWITCH expr CASE ... [DEFAULT ...] ENDSWITCH``; ``default`` ``None``: no DEFAULT."""

    selector: Expr
    cases: tuple[Case, ...]
    default: tuple[Stmt, ...] | None


@dataclass(frozen=True, slots=True)
class WaitFor(Node):
    """``WAIT FOR cond`` (stops the advance run)."""

    cond: Expr


@dataclass(frozen=True, slots=True)
class WaitSec(Node):
    """``WAIT SEC expr`` (stops the advance run)."""

    seconds: Expr


@dataclass(frozen=True, slots=True)
class Halt(Node):
    """``HALT``: stop the program as if the operator released the start key."""


@dataclass(frozen=True, slots=True)
class Continue(Node):
    """``CONTINUE`` (prevents an advance-run stop on a real KRC; a no-op here)."""


@dataclass(frozen=True, slots=True)
class Ini(Node):
    """A bare ``INI`` line as the thesis writes it (stands for the INI fold; a no-op)."""


@dataclass(frozen=True, slots=True)
class Return(Node):
    """``RETURN [expr]``: ``value`` is required in a DEFFCT, absent in a DEF."""

    value: Expr | None


@dataclass(frozen=True, slots=True)
class Motion(Node):
    """A motion statement: ``PTP``, ``PTP_REL``, ``LIN``, ``LIN_REL``, ``CIRC``, ``CIRC_REL``.

    ``aux`` is the CIRC auxiliary point (``None`` otherwise). ``approx`` is ``"C_PTP"``,
    ``"C_DIS"``, ``"C_VEL"``, ``"C_ORI"`` or ``None``; ``frame`` is ``"TOOL"``/``"BASE"`` for
    ``PTP_REL ... #TOOL`` or ``None``.
    """

    kind: str
    target: Expr
    aux: Expr | None
    approx: str | None
    frame: str | None


@dataclass(frozen=True, slots=True)
class InlineMotion(Node):
    """An inline-form motion ``PTP HOME Vel = 100 % DEFAULT`` (KUKA's ILF, as the thesis).

    ``kind`` is ``"PTP"``/``"LIN"``/``"CIRC"``; ``cont`` is the ``CONT`` flag (approximate);
    ``velocity`` with ``unit`` ``"%"`` (PTP, of the axis maximum) or ``"M/S"`` (LIN/CIRC);
    ``dataset`` is the motion data set name (``DEFAULT``, ``PDAT1``); ``tool``/``base`` are
    the optional ``Tool[n]`` / ``Base[n]`` numbers.
    """

    kind: str
    target: Expr
    cont: bool
    velocity: Expr
    unit: str
    dataset: str | None
    tool: int | None
    base: int | None


Stmt: TypeAlias = (
    Decl
    | StrucDef
    | EnumDef
    | Assign
    | CallStmt
    | If
    | Loop
    | Exit
    | For
    | While
    | Repeat
    | Switch
    | WaitFor
    | WaitSec
    | Halt
    | Continue
    | Ini
    | Return
    | Motion
    | InlineMotion
)

# ------------------------------------------------------------------------------- modules


@dataclass(frozen=True, slots=True)
class Param(Node):
    """A routine parameter; ``direction`` is ``"IN"`` (by value) or ``"OUT"`` (by reference,
    KRL's default when no direction is written). Its type comes from a DECL in the body."""

    name: str
    direction: str


@dataclass(frozen=True, slots=True)
class Routine(Node):
    """A ``DEF`` (``return_type`` ``None``) or ``DEFFCT`` (``return_type`` the KRL type).

    ``decls`` are the routine's DECL/STRUC/ENUM lines (also found in ``body`` in source order,
    for executors that want to run them in place).
    """

    name: str
    params: tuple[Param, ...]
    return_type: str | None
    is_global: bool
    decls: tuple[Decl | StrucDef | EnumDef, ...]
    body: tuple[Stmt, ...]

    @property
    def is_function(self) -> bool:
        """True for a DEFFCT."""
        return self.return_type is not None


@dataclass(frozen=True, slots=True)
class Module(Node):
    """One parsed ``.src``/``.sub`` file (and optionally its ``.dat``).

    The first routine is the module's main program (its name is the file's program name);
    the rest are local subroutines and functions. ``dat`` holds the module's data list.
    """

    filename: str
    routines: tuple[Routine, ...]
    dat: DatFile | None

    @property
    def name(self) -> str:
        """The main routine's name (``""`` for a module without routines)."""
        return self.routines[0].name if self.routines else ""

    @property
    def main(self) -> Routine:
        """The main routine (the first DEF in the file)."""
        return self.routines[0]

    def routine(self, name: str) -> Routine | None:
        """The routine called ``name`` (case-insensitive), or ``None``."""
        wanted = name.upper()
        for routine in self.routines:
            if routine.name == wanted:
                return routine
        return None
