"""KRL runtime: errors, variable scopes, typed assignment and expression evaluation.

The executor (:mod:`.interp`) walks statements; everything that computes a value or stores one
lives here so it can be tested on its own:

* :class:`KrlRuntimeError` — an error at a node (file:line:column); it stops the program;
* :class:`Frame` — the locals of one routine call, held in a private
  :class:`~kukavarproxy_emu.store.VariableStore` so locals get exactly the type rules
  (struct merging, CHAR lengths, ranges) of globals;
* :class:`Evaluator` — expressions and assignments over the frame stack and the global store.

KRL typing implemented here: INT op INT is INT (``/`` truncates towards zero), mixed
arithmetic is REAL, assigning a REAL to an INT rounds half away from zero, an INT to a REAL
widens, a struct assigned to a compatible struct type keeps the common members (E6POS → POS →
FRAME, E6AXIS → AXIS); every other mismatch is a runtime error, as on a KRC.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from pyopenshowvar.kinematics import matrix_to_frame, pose_to_matrix
from pyopenshowvar.krl import Kind, KrlEnum, KrlValue, Struct, TypeRegistry, TypeSpec

from ..names import Var
from ..store import UnknownVariable, VariableStore, WriteRefused
from . import ast

if TYPE_CHECKING:
    from pyopenshowvar.krl.datfile import Declaration

__all__ = [
    "ACTUAL_POSITION",
    "BUILTINS",
    "HEAVY_ELEMENTS",
    "Evaluator",
    "Frame",
    "KrlRuntimeError",
    "convert",
    "literal_path",
    "render",
]

#: Reading one of these in the robot program stops the advance run (reference §5).
ACTUAL_POSITION = frozenset({"$AXIS_ACT", "$POS_ACT", "$AXIS_ACT_MEAS", "$POS_ACT_MES"})
#: System variables the store marks read-only for KUKAVARPROXY but a KRL program may write.
KRL_WRITABLE = frozenset({"$OUT", "$TIMER", "$TIMER_STOP"})
_INT_MIN, _INT_MAX = -(2**31), 2**31 - 1
#: A value with this many elements makes the executor look at its wall-time budget at once.
HEAVY_ELEMENTS = 4096


class KrlRuntimeError(Exception):
    """A runtime error at a node; :meth:`located` adds the file (the executor knows it)."""

    def __init__(self, message: str, node: ast.Node | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.line = node.line if node is not None else 0
        self.column = node.column if node is not None else 0

    def located(self, filename: str) -> str:
        """``FILE:LINE:COL: message`` (``FILE: message`` without a position)."""
        if self.line:
            return f"{filename}:{self.line}:{self.column}: {self.message}"
        return f"{filename}: {self.message}"


def _deg(f: Callable[[float], float]) -> Callable[[float], float]:
    return lambda x: f(math.radians(x))


def _sqrt(x: float) -> float:
    if x < 0:
        raise ValueError(f"SQRT of a negative number ({x:g})")
    return math.sqrt(x)


def _arc(f: Callable[[float], float], name: str) -> Callable[[float], float]:
    def g(x: float) -> float:
        if not -1.0 <= x <= 1.0:
            raise ValueError(f"{name} argument {x:g} outside -1..1")
        return math.degrees(f(x))

    return g


#: One-argument built-in functions (angles in degrees, as KRL).
BUILTINS: dict[str, Callable[[float], float]] = {
    "SIN": _deg(math.sin),
    "COS": _deg(math.cos),
    "TAN": _deg(math.tan),
    "SQRT": _sqrt,
    "ABS": abs,
    "ASIN": _arc(math.asin, "ASIN"),
    "ACOS": _arc(math.acos, "ACOS"),
    "ATAN": lambda x: math.degrees(math.atan(x)),
}


def render(expr: ast.Expr, index: Callable[[ast.Expr], str] | None = None) -> str:
    """Source-like text of an lvalue expression (``MYE6ARRAY[ROW]``); ``index`` renders the
    indices (the executor passes evaluated values so messages name the element)."""
    if isinstance(expr, ast.Name):
        return expr.name
    if isinstance(expr, ast.Member):
        return f"{render(expr.base, index)}.{expr.member}"
    if isinstance(expr, ast.Index):
        parts = [index(i) if index else render(i) for i in expr.indices]
        return f"{render(expr.base, index)}[{','.join(parts)}]"
    if isinstance(expr, ast.Call):
        return f"{expr.name}()"
    if isinstance(expr, ast.Aggregate):
        return expr.text
    if isinstance(expr, ast.IntLit | ast.RealLit | ast.Value):
        return str(expr.value)
    return type(expr).__name__


def _var(store: VariableStore, base: str) -> Var | None:
    """The declared variable ``base`` of ``store`` (type, dimensions), None if undeclared."""
    return store.declaration(base)


def is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def round_int(x: float) -> int:
    """KRL's REAL -> INT conversion: round half away from zero."""
    return int(math.copysign(math.floor(abs(x) + 0.5), x))


class Frame:
    """The locals of one routine call (a private store sharing the global type registry)."""

    def __init__(self, routine: ast.Routine, globals_: VariableStore) -> None:
        self.routine = routine
        self.store = VariableStore(globals_.registry, system=False, default_config=False)
        self.names: set[str] = set()
        #: (parameter name, caller's variable text, caller's store) copied back on return.
        self.out: list[tuple[str, str, VariableStore]] = []
        for decl in routine.decls:
            if isinstance(decl, ast.StrucDef):
                self.store.registry.add_struct(decl.struc.name, decl.struc.members)
            elif isinstance(decl, ast.EnumDef):
                self.store.registry.add_enum(decl.enum.name, decl.enum.values)
            else:
                for d in decl.declarations:
                    self._declare(d, decl)

    def _declare(self, d: Declaration, node: ast.Node) -> None:
        try:
            self.store.declare(d.name, d.type_name, d.dims, d.init, d.is_const)
        except ValueError as exc:
            raise KrlRuntimeError(f"declaration of {d.name}: {exc}", node) from None
        self.names.add(d.name)


class Evaluator:
    """Evaluates expressions and performs assignments for one interpreter.

    ``frames`` is the interpreter's call stack (the last frame's locals shadow the globals);
    ``call`` runs a user DEFFCT synchronously and returns its value.
    """

    def __init__(
        self,
        store: VariableStore,
        frames: list[Frame],
        call: Callable[[ast.Call], KrlValue],
    ) -> None:
        self.store = store
        self.frames = frames
        self.call = call
        self._globals = set(store.names())
        #: Set when an evaluation copied a large array (the executor checks its clock).
        self.heavy = False
        #: While not None, every variable read is recorded here as (store, base name).
        self.reads: set[tuple[VariableStore, str]] | None = None
        #: :meth:`ref` of lvalues whose indices are literals (``CELL_W.TORQUE_1``,
        #: ``$TORQUE_AXIS_ACT[3]``), per node: (declaration, store, text, base). An SPS copies
        #: the same variables every cycle; this spares building and bounds-checking their text.
        self._refs: dict[int, tuple[Var, VariableStore, str, ast.Name]] = {}
        #: The value the last variable read returned, and its store (see :meth:`put`).
        self._read: object = None
        self._read_store: VariableStore | None = None

    # --- references ----------------------------------------------------------------------------
    def scope(self, name: str, node: ast.Node) -> VariableStore:
        """The store holding ``name``: the current routine's locals, else the globals."""
        if self.frames and name in self.frames[-1].names:
            return self.frames[-1].store
        if name not in self._globals:
            self._globals = set(self.store.names())  # a data list may have been loaded since
            if name not in self._globals:
                raise KrlRuntimeError(f"variable {name} is not declared", node)
        return self.store

    def has(self, name: str) -> bool:
        """Whether ``name`` is a declared local or global variable."""
        if self.frames and name in self.frames[-1].names:
            return True
        return name in self._globals or name in self.store.names()

    def ref(self, expr: ast.Expr) -> tuple[VariableStore, str, ast.Name]:
        """(store, full variable text such as ``A[3].X``, base name node) of an lvalue."""
        if isinstance(expr, ast.Name):
            return self.scope(expr.name, expr), expr.name, expr
        cached = self._refs.get(id(expr))
        if cached is not None:
            var, store, text, base = cached
            # the same scope and declaration as when it was cached: same text, same bounds
            if self.scope(base.name, base) is store and store.declaration(base.name) is var:
                return store, text, base
        store, text, base = self._ref(expr)
        declared = store.declaration(base.name)
        if declared is not None and literal_path(expr):
            self._refs[id(expr)] = (declared, store, text, base)
        return store, text, base

    def _ref(self, expr: ast.Expr) -> tuple[VariableStore, str, ast.Name]:
        if isinstance(expr, ast.Name):
            return self.scope(expr.name, expr), expr.name, expr
        if isinstance(expr, ast.Member):
            store, text, base = self._ref(expr.base)
            return store, f"{text}.{expr.member}", base
        if isinstance(expr, ast.Index):
            store, text, base = self._ref(expr.base)
            if not expr.indices:  # NAME[]: a whole CHAR array (the store refuses others)
                return store, f"{text}[]", base
            idx = [self._index(i) for i in expr.indices]
            self._check_bounds(store, base, idx, expr)
            return store, f"{text}[{','.join(map(str, idx))}]", base
        raise KrlRuntimeError("not a variable", expr)

    def _index(self, expr: ast.Expr) -> int:
        value = self.eval(expr)
        if isinstance(value, bool) or not isinstance(value, int):
            raise KrlRuntimeError(f"array index must be INT, not {_type_of(value)}", expr)
        return value

    def _check_bounds(
        self, store: VariableStore, base: ast.Name, idx: list[int], node: ast.Node
    ) -> None:
        var = _var(store, base.name)
        if var is None:
            return
        dims = (var.text_len,) if var.text_len else var.dims
        if not dims:
            raise KrlRuntimeError(f"{base.name} is not an array", node)
        if len(idx) != len(dims):
            raise KrlRuntimeError(f"{base.name} needs {len(dims)} indices", node)
        for i, size in zip(idx, dims, strict=True):
            if not 1 <= i <= size:
                raise KrlRuntimeError(f"index {i} out of range 1..{size} of {base.name}", node)

    # --- expressions ---------------------------------------------------------------------------
    def eval(self, expr: ast.Expr) -> KrlValue:
        """The value of ``expr``; raises :class:`KrlRuntimeError`."""
        if isinstance(expr, ast.IntLit | ast.RealLit | ast.BoolLit | ast.StrLit | ast.Value):
            return expr.value
        if isinstance(expr, ast.Name | ast.Index | ast.Member):
            if isinstance(expr, ast.Member) and not ast.is_lvalue(expr.base):
                base = self.eval(expr.base)
                if not isinstance(base, Struct) or expr.member not in base:
                    raise KrlRuntimeError(f"no member {expr.member}", expr)
                return base[expr.member]
            store, text, name = self.ref(expr)
            if self.reads is not None:
                self.reads.add((store, name.name))
            try:
                value = store.get(text)
            except UnknownVariable:
                raise KrlRuntimeError(f"{text} is not initialised", expr) from None
            if isinstance(value, list) and len(value) >= HEAVY_ELEMENTS:
                self.heavy = True
            self._read, self._read_store = value, store
            return value
        if isinstance(expr, ast.EnumLit):
            return KrlEnum._from_parsed(expr.name)
        if isinstance(expr, ast.Binary):
            return self._binary(expr)
        if isinstance(expr, ast.Unary):
            return self._unary(expr)
        if isinstance(expr, ast.Call):
            return self._call(expr)
        if isinstance(expr, ast.Aggregate):
            members = {item.name: self.eval(item.value) for item in expr.items}
            return Struct(expr.type_name, members)
        raise KrlRuntimeError(f"cannot evaluate {type(expr).__name__}", expr)

    def _call(self, expr: ast.Call) -> KrlValue:
        fn = BUILTINS.get(expr.name)
        if fn is None and expr.name != "ATAN2":
            return self.call(expr)
        args = [self.eval(a) for a in expr.args]
        want = 2 if fn is None else 1
        if len(args) != want:
            raise KrlRuntimeError(f"{expr.name} takes {want} argument(s)", expr)
        if not all(is_number(a) for a in args):
            raise KrlRuntimeError(f"{expr.name} needs numbers", expr)
        x = [float(a) for a in args]  # type: ignore[arg-type]
        try:
            if fn is None:  # ATAN2(Y, X), degrees; KRL defines ATAN2(0, 0) = 0
                return math.degrees(math.atan2(x[0], x[1]))
            return float(fn(x[0]))
        except (ValueError, OverflowError) as exc:
            raise KrlRuntimeError(str(exc), expr) from None

    def _unary(self, expr: ast.Unary) -> KrlValue:
        v = self.eval(expr.operand)
        if expr.op == "NOT" and isinstance(v, bool):
            return not v
        if expr.op in "+-" and is_number(v):
            return -v if expr.op == "-" else v  # type: ignore[operator]
        if expr.op == "B_NOT" and isinstance(v, int) and not isinstance(v, bool):
            return ~v
        raise KrlRuntimeError(f"type mismatch: {expr.op} {_type_of(v)}", expr)

    def _binary(self, expr: ast.Binary) -> KrlValue:
        op = expr.op
        a = self.eval(expr.left)
        if op == "AND" and a is False:
            return False  # KRL evaluates AND/OR short-circuit
        if op == "OR" and a is True:
            return True
        b = self.eval(expr.right)
        if op in ("AND", "OR", "EXOR"):
            if isinstance(a, bool) and isinstance(b, bool):
                return (a and b) if op == "AND" else (a or b) if op == "OR" else a != b
        elif op in ("==", "<>"):
            if (is_number(a) and is_number(b)) or type(a) is type(b):
                return (a == b) == (op == "==")
        elif op in ("<", "<=", ">", ">="):
            if (is_number(a) and is_number(b)) or (isinstance(a, str) and isinstance(b, str)):
                return _compare(op, a, b)  # type: ignore[arg-type]
        elif op in ("+", "-", "*", "/"):
            if is_number(a) and is_number(b):
                return self._arith(op, a, b, expr)  # type: ignore[arg-type]
        elif op in ("B_AND", "B_OR", "B_EXOR"):
            if isinstance(a, int) and isinstance(b, int):
                if not isinstance(a, bool) and not isinstance(b, bool):
                    return a & b if op == "B_AND" else a | b if op == "B_OR" else a ^ b
        elif op == ":":
            return _geo(a, b, expr)
        raise KrlRuntimeError(f"type mismatch: {_type_of(a)} {op} {_type_of(b)}", expr)

    @staticmethod
    def _arith(op: str, a: int | float, b: int | float, node: ast.Node) -> int | float:
        if op == "/" and b == 0:
            raise KrlRuntimeError("division by zero", node)
        both_int = isinstance(a, int) and isinstance(b, int)
        if op == "+":
            r = a + b
        elif op == "-":
            r = a - b
        elif op == "*":
            r = a * b
        elif both_int:
            r = abs(a) // abs(b) * (1 if (a >= 0) == (b >= 0) else -1)  # truncates to 0
        else:
            r = a / b
        if both_int and not _INT_MIN <= r <= _INT_MAX:
            raise KrlRuntimeError("INT overflow", node)
        if isinstance(r, float) and not math.isfinite(r):
            raise KrlRuntimeError("REAL overflow", node)
        return r

    # --- assignment ----------------------------------------------------------------------------
    def assign(self, target: ast.Expr, value: KrlValue, node: ast.Node) -> None:
        """``target = value`` with KRL conversions; raises :class:`KrlRuntimeError`."""
        store, text, base = self.ref(target)
        self.put(store, text, base.name, value, node)

    def put(
        self, store: VariableStore, text: str, base: str, value: KrlValue, node: ast.Node
    ) -> None:
        """Store ``value`` into the variable ``text`` of ``store`` (KRL conversions)."""
        if store is self.store and base not in KRL_WRITABLE and store.is_read_only(base):
            raise KrlRuntimeError(f"{base} is write-protected", node)
        var = _var(store, base)
        valid = False
        if var is not None:
            value, type_name = self._convert(value, var, store, text, node)
            # A structure just read from a variable of the very type of the target (an SPS
            # copying $AXIS_ACT into an E6AXIS member, a snapshot copied whole) is a valid
            # value of that type already: the store need not convert and check it again.
            # (The same store: a routine's locals may declare a STRUC of their own.)
            valid = isinstance(value, Struct) and value is self._read
            valid = valid and store is self._read_store and value.type_name == type_name  # type: ignore[union-attr]
        if self.reads is not None:
            self.reads.add((store, base))
        try:
            if store.get(text) == value:
                return  # nothing observable changes: keep the store's read cache warm
        except (UnknownVariable, WriteRefused):
            pass
        try:
            if valid:
                store.put_valid(text, value)
            else:
                store.set_system(text, value)
        except (UnknownVariable, WriteRefused) as exc:
            reason = exc.reason if isinstance(exc, WriteRefused) else "no such variable"
            raise KrlRuntimeError(f"{text} = {_short(value)}: {reason}", node) from None

    @staticmethod
    def _convert(
        value: KrlValue, var: Var, store: VariableStore, text: str, node: ast.Node
    ) -> tuple[KrlValue, str | None]:
        """``value`` converted to the declared type at ``text``, and that type's name (None
        when the store is left to judge: a CHAR of a text, an unknown member)."""
        members = tuple(m for m in text.partition(".")[2].split(".") if m)
        if var.text_len and "[" in text and not members:
            return value, None  # one character of a CHAR array: the store checks it
        try:
            spec, type_name = var.chain(store.registry, members)[-1]
        except Exception:  # an unknown member: let the store word the refusal
            return value, None
        return convert(value, spec, type_name, store.registry, node), type_name


def convert(
    value: KrlValue, spec: TypeSpec, type_name: str, registry: TypeRegistry, node: ast.Node
) -> KrlValue:
    """``value`` as the KRL type ``spec`` (REAL -> INT rounds, compatible structs narrow)."""
    kind = spec.kind
    if kind is Kind.INT:
        if isinstance(value, float):
            if not math.isfinite(value) or not _INT_MIN <= value <= _INT_MAX:
                raise KrlRuntimeError(f"{value:g} does not fit an INT", node)
            return round_int(value)
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif kind is Kind.REAL:
        if is_number(value):
            return float(value)  # type: ignore[arg-type]
    elif kind is Kind.BOOL:
        if isinstance(value, bool):
            return value
    elif kind is Kind.STR:
        if isinstance(value, str):
            return value
    elif kind is Kind.ENUM:
        if isinstance(value, KrlEnum):
            return value
    elif kind is Kind.STRUCT and spec.struct is not None:
        if isinstance(value, Struct):
            sdef = spec.struct
            if value.type_name == sdef.name:
                # a value of this very type (read from a variable, or parsed typed): KRL
                # converts nothing, and the store checks it anyway. Copying a structure (an
                # SPS snapshot) stays cheap and keeps its type, so an unchanged copy is seen
                # as unchanged.
                return value
            members: dict[str, KrlValue] = {}
            for name, member in value.items():
                mtype = sdef.member_type(name)
                if mtype is None:
                    if value.type_name is None:  # an aggregate literal names a wrong member
                        raise KrlRuntimeError(f"{sdef.name} has no member {name}", node)
                    continue  # E6POS -> POS etc.: KRL keeps the common members
                mspec = registry.resolve(mtype)
                members[name] = convert(member, mspec, mtype, registry, node)
            return Struct(None, members)
    raise KrlRuntimeError(f"type mismatch: cannot assign {_type_of(value)} to {type_name}", node)


def literal_path(expr: ast.Expr) -> bool:
    """An lvalue whose text never changes: names, members, literal indices (``NAME[]`` too)."""
    if isinstance(expr, ast.Name):
        return True
    if isinstance(expr, ast.Member):
        return literal_path(expr.base)
    if isinstance(expr, ast.Index):
        return all(isinstance(i, ast.IntLit) for i in expr.indices) and literal_path(expr.base)
    return False


def _compare(op: str, a: float | str, b: float | str) -> bool:
    if op == "<":
        return a < b  # type: ignore[operator]
    if op == "<=":
        return a <= b  # type: ignore[operator]
    if op == ">":
        return a > b  # type: ignore[operator]
    return a >= b  # type: ignore[operator]


def _geo(a: KrlValue, b: KrlValue, node: ast.Node) -> KrlValue:
    """The geometric operator ``A : B`` (frame composition), result a FRAME-like struct."""

    def pose(v: KrlValue) -> list[float]:
        if not isinstance(v, Struct):
            raise KrlRuntimeError(f"type mismatch: {_type_of(v)} : (needs FRAME/POS)", node)
        try:
            return [float(v[k]) for k in "XYZABC"]  # type: ignore[arg-type]
        except KeyError:
            raise KrlRuntimeError("a FRAME/POS operand needs X, Y, Z, A, B, C", node) from None

    m = pose_to_matrix(np.array(pose(a))) @ pose_to_matrix(np.array(pose(b)))
    xyzabc = [float(x) for x in matrix_to_frame(m)]
    members: dict[str, KrlValue] = dict(zip("XYZABC", xyzabc, strict=True))
    if isinstance(b, Struct):
        for k in ("S", "T"):
            if k in b:
                members[k] = b[k]
    return Struct(None, members)


def _type_of(value: object) -> str:
    if isinstance(value, bool):
        return "BOOL"
    if isinstance(value, int):
        return "INT"
    if isinstance(value, float):
        return "REAL"
    if isinstance(value, str):
        return "CHAR"
    if isinstance(value, KrlEnum):
        return "ENUM"
    if isinstance(value, Struct):
        return value.type_name or "STRUC"
    if isinstance(value, Sequence):
        return "array"
    return type(value).__name__


def _short(value: KrlValue) -> str:
    # A CHAR value may have come from a client: escaped, it cannot break the log line.
    text = str(value) if not isinstance(value, Struct) else "{...}"
    text = text.encode("unicode_escape").decode("ascii")
    return text if len(text) < 30 else text[:27] + "..."
