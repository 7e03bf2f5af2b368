"""How a :class:`~pyopenshowvar.snapshot.Snapshot` is laid out within KRL's limits (no I/O).

* :func:`resolve_variable` — the type of a variable (system table, or given) and its slots: one
  member, or one per element of a whole array (no arrays inside a STRUC);
* :func:`layout` — the slots packed into parts (top-level globals, one read each): flat when
  the ``STRUC`` line fits ``struc_line``, else as nested group structures, and a new part when
  the worst-case reply text would pass ``max_text``; every generated name checked against
  KRL's 24 characters;
* the helpers that derive member names and estimate reply sizes.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

from .errors import KrlValueError
from .krl import Kind, TypeRegistry, TypeSpec
from .krl.systypes import system_type

__all__ = [
    "COUNTER",
    "KRL_KEYWORDS",
    "Part",
    "Slot",
    "SnapshotLimits",
    "StrucType",
    "Variable",
    "check_name",
    "layout",
    "resolve_variable",
    "struc_line",
    "unique_names",
]

#: The pass counter member of every snapshot structure (INT, counts 1, 2, ... 2**31-1, 1, ...).
COUNTER = "CYCLE"

#: Words a KRL member or variable name must not be (KSS 8 keywords and the names used here).
KRL_KEYWORDS = frozenset(
    """AND ANIN ANOUT B_AND B_EXOR B_NOT B_OR BOOL BRAKE C_DIS C_ORI C_PTP C_VEL CASE CHAR
    CIRC CIRC_REL CONST CONTINUE DECL DEF DEFAULT DEFDAT DEFFCT DELAY DISTANCE DO ELSE END ENDDAT
    ENDFCT ENDFOR ENDIF ENDLOOP ENDSWITCH ENDWHILE ENUM EXIT EXOR EXT EXTFCT FALSE FOR GLOBAL
    GOTO HALT IF IMPORT IN INT INTERRUPT IS LIN LIN_REL LOOP MAXIMUM MINIMUM NOT OFF ON OR OUT
    PATH PRIO PTP PTP_REL PUBLIC PULSE REAL REPEAT RESUME RETURN SEC SIGNAL STEP STRUC SWITCH
    THEN TO TRIGGER TRUE UNTIL WAIT WHEN WHILE""".split()
)

_IDENT = re.compile(r"[A-Z_][A-Z0-9_]*\Z", re.ASCII)
_VAR = re.compile(
    r"(\$?[A-Z_][A-Z0-9_$]*)(?:\[\s*([0-9,\s]*)\])?((?:\.[A-Z_$][A-Z0-9_$]*)*)\Z", re.ASCII
)
_TYPE = re.compile(r"([A-Z_$][A-Z0-9_$]*)(?:\[\s*([0-9]+)\s*\])?\Z", re.ASCII)
# worst-case text of one scalar on a KRC4: "-1.17549435E-38", "-2147483648", "FALSE"
_SCALAR_TEXT = {Kind.REAL: 15, Kind.INT: 11, Kind.BOOL: 5}
_ENUM_TEXT = 25  # "#" + a name of at most 24 characters


@dataclass(frozen=True, slots=True)
class SnapshotLimits:
    """The limits a snapshot layout respects.

    * ``name_length`` — KRL names have at most 24 characters (KSS 8.x KRL syntax quick guide,
      "Variables and declarations"); every generated name is checked against it.
    * ``struc_line`` — the longest ``STRUC`` declaration line we generate. KUKA documents no
      maximum; a declaration must stay on one line (data lists have no continuation), so we
      keep lines short enough for the smartPAD editor and nest group structures beyond it.
    * ``max_text`` — worst-case characters of reply text per read. KVP's 16-bit length field
      caps a reply at 65 529; a KRC4 also takes longer to format a longer value (about 1 µs
      per character, docs/snapshots.md), so more text than this starts another structure.
    * ``max_elements`` — a whole array ``X[]`` becomes one member per element, at most this many.
    """

    name_length: int = 24
    struc_line: int = 480
    max_text: int = 4096
    max_elements: int = 64

    def __post_init__(self) -> None:
        if self.name_length < 8 or self.struc_line < 80 or self.max_text < 64:
            raise ValueError(f"snapshot limits too small: {self}")
        if not 1 <= self.max_elements:
            raise ValueError("max_elements must be >= 1")


@dataclass(frozen=True, slots=True)
class Slot:
    """One member of a snapshot structure: what it copies and how it is declared."""

    source: str  # the KRL expression the SPS copies, e.g. "$TORQUE_AXIS_ACT[3]"
    member: str  # member name in its STRUC
    type_name: str  # a scalar, ENUM or STRUC type (never an array)
    text_max: int  # worst-case reply text of "MEMBER value, "


@dataclass(frozen=True, slots=True)
class Variable:
    """One variable of a snapshot as the user named it, and the slots that hold it."""

    name: str
    type_name: str  # type of the value the user gets ("REAL[12]" for a whole array)
    slots: tuple[Slot, ...]
    whole_array: bool


@dataclass(frozen=True, slots=True)
class StrucType:
    """A generated ``STRUC``: name and ``(member, type)`` pairs in declaration order."""

    name: str
    members: tuple[tuple[str, str], ...]


@dataclass(frozen=True, slots=True)
class Part:
    """One top-level global of a snapshot (one read): its work copy, types and member paths."""

    variable: str  # the global the PC reads
    work: str  # the SPS fills this one, then assigns it to ``variable`` in one statement
    type_name: str
    types: tuple[StrucType, ...]  # declaration order: groups first, the top structure last
    paths: tuple[tuple[str, Slot], ...]  # "G1.AXIS_ACT" or "AXIS_ACT", per slot


def resolve_variable(
    name: str,
    type_name: str | None,
    taken: set[str],
    registry: TypeRegistry,
    limits: SnapshotLimits,
) -> Variable:
    """The slots of variable ``name`` (a ``(name, type)`` pair: type None = a system variable)."""
    source = "".join(name.split()).upper()
    m = _VAR.match(source)
    if m is None:
        raise ValueError(f"{name!r} is not a KRL variable name")
    base, index, members = m.group(1), m.group(2), m.group(3)
    type_expr = (type_name or "").replace(" ", "").upper() or _system_type(
        name, base, index, members, registry
    )
    spec, length = _resolve(name, type_expr, registry)
    if index is not None and not index.strip():  # NAME[]: one member per element
        if members:
            raise ValueError(f"{name!r}: a member of a whole array means nothing")
        if length is None:
            raise ValueError(
                f"{name!r} is a whole array: give its length, e.g. ({name!r}, 'REAL[10]')"
            )
        if length > limits.max_elements:
            raise ValueError(
                f"{name!r} has {length} elements; a snapshot takes at most "
                f"{limits.max_elements} of one array: name the elements you need"
            )
        elem = spec.elem if spec.kind is Kind.ARRAY and spec.elem is not None else spec
        slots = tuple(
            _slot(f"{base}[{i}]", elem, taken, registry, limits) for i in range(1, length + 1)
        )
        return Variable(name, type_expr, slots, True)
    if length is not None:
        raise ValueError(
            f"{name!r} is an array ({type_expr}): read it whole as '{base}[]' or name an element"
        )
    return Variable(name, type_expr, (_slot(source, spec, taken, registry, limits),), False)


def _system_type(
    name: str, base: str, index: str | None, members: str, registry: TypeRegistry
) -> str:
    declared = system_type(base)
    if declared is None:
        raise ValueError(
            f"the type of {name!r} is unknown: give it, e.g. ({name!r}, 'REAL') in Python"
            f" or {name}:REAL on the command line"
        )
    tm = _TYPE.match(declared)
    assert tm is not None
    elem, length = tm.group(1), tm.group(2)
    if index is None:
        if length is not None and members:
            raise ValueError(f"{name!r}: {base} is an array, index it first")
        type_expr = declared
    elif not index.strip():
        return declared  # NAME[]: the whole array
    else:
        if length is None:
            raise ValueError(f"{name!r}: {base} is not an array")
        parts = [p.strip() for p in index.split(",")]
        if len(parts) != 1 or not 1 <= int(parts[0]) <= int(length):
            raise ValueError(f"{name!r}: index out of range 1..{length} of {base}")
        type_expr = elem
    for member in filter(None, members.split(".")):
        struct = registry.struct(type_expr)
        member_type = struct.member_type(member) if struct is not None else None
        if member_type is None:
            raise ValueError(f"{name!r}: {type_expr} has no member {member}")
        type_expr = member_type
    return type_expr


def _resolve(name: str, type_expr: str, registry: TypeRegistry) -> tuple[TypeSpec, int | None]:
    tm = _TYPE.match(type_expr)
    if tm is None:
        raise ValueError(f"{name!r}: {type_expr!r} is not a KRL type (e.g. REAL, E6POS, INT[12])")
    base, length = tm.group(1), tm.group(2)
    if base == "CHAR":
        raise ValueError(
            f"{name!r} is CHAR text: KRL copies a CHAR array only with STRCOPY, which"
            " snapshots do not generate; read it on its own"
        )
    try:
        spec = registry.resolve(base)
    except KrlValueError:
        if not _IDENT.match(base):
            raise ValueError(f"{name!r}: {type_expr!r} is not a KRL type") from None
        # a user type this client does not know: declared as given, its text parsed untyped
        spec = TypeSpec(Kind.STRUCT, base)
    if spec.kind is Kind.STRUCT and _holds_array(spec, registry):
        raise ValueError(
            f"{name!r}: STRUC {base} holds an array; KRL documents only CHAR arrays"
            " as STRUC members, so a snapshot cannot nest it"
        )
    return spec, None if length is None else int(length)


def _slot(
    source: str, spec: TypeSpec, taken: set[str], registry: TypeRegistry, limits: SnapshotLimits
) -> Slot:
    member = _member_name(source, taken, registry, limits.name_length)
    taken.add(member)
    return Slot(source, member, spec.name, len(member) + 3 + _text_max(spec, registry))


def layout(name: str, variables: Sequence[Variable], limits: SnapshotLimits) -> list[Part]:
    """The parts of a snapshot: as few top-level structures as the limits allow, in order."""
    parts: list[Part] = []
    slots = [s for v in variables for s in v.slots]
    index = 0
    number = 1
    while index < len(slots):
        taken: list[Slot] = []
        layout: Part | None = None
        while index + len(taken) < len(slots):
            trial = _part(name, number, [*taken, slots[index + len(taken)]], limits)
            if trial is None:
                break
            taken.append(slots[index + len(taken)])
            layout = trial
        if layout is None:
            slot = slots[index]
            raise ValueError(f"{slot.source} alone does not fit the limits ({limits}): raise them")
        parts.append(layout)
        index += len(taken)
        number += 1
    return parts


def _part(name: str, number: int, slots: list[Slot], limits: SnapshotLimits) -> Part | None:
    """The part holding ``slots`` (flat or nested), or None if the limits forbid it."""
    lim = limits
    suffix = "" if number == 1 else str(number)
    variable, type_name = f"{name}{suffix}", f"{name}{suffix}_T"
    text = sum(s.text_max for s in slots) + len(type_name) + 24  # "{T: CYCLE n, ...}"
    if text > lim.max_text:
        return None
    counter = (COUNTER, "INT")
    flat = StrucType(type_name, (counter, *((s.member, s.type_name) for s in slots)))
    if len(struc_line(flat)) <= lim.struc_line:
        paths = tuple((s.member, s) for s in slots)
        return _checked(name, limits, Part(variable, f"{variable}_W", type_name, (flat,), paths))
    groups: list[list[Slot]] = [[]]
    for s in slots:
        trial = StrucType(
            f"{type_name}{len(groups)}",
            tuple((x.member, x.type_name) for x in [*groups[-1], s]),
        )
        if groups[-1] and len(struc_line(trial)) > lim.struc_line:
            groups.append([])
        groups[-1].append(s)
    types = [
        StrucType(f"{type_name}{k}", tuple((s.member, s.type_name) for s in g))
        for k, g in enumerate(groups, 1)
    ]
    if any(len(struc_line(t)) > lim.struc_line for t in types):
        return None
    top = StrucType(type_name, (counter, *((f"G{k}", t.name) for k, t in enumerate(types, 1))))
    # each group adds "Gk {TYPE: ...}, " to the reply
    text += sum(len(t.name) + 12 for t in types)
    if len(struc_line(top)) > lim.struc_line or text > lim.max_text:
        return None
    paths = tuple((f"G{k}.{s.member}", s) for k, g in enumerate(groups, 1) for s in g)
    return _checked(name, limits, Part(variable, f"{variable}_W", type_name, (*types, top), paths))


def _checked(name: str, limits: SnapshotLimits, part: Part) -> Part | None:
    longest = max([part.work, *(t.name for t in part.types), f"{name}_SPS"], key=len)
    if len(longest) > limits.name_length:
        if part.variable == name:  # even the first part's names are too long
            raise ValueError(
                f"snapshot name {name!r} is too long: it makes {longest!r}, and KRL"
                f" names have at most {limits.name_length} characters"
            )
        return None
    return part


def struc_line(t: StrucType) -> str:
    """``STRUC NAME INT CYCLE, E6AXIS AXIS_ACT, REAL A, B``: consecutive members of one type
    share it, as KRL allows."""
    out: list[str] = []
    previous = None
    for member, type_name in t.members:
        out.append(member if type_name == previous else f"{type_name} {member}")
        previous = type_name
    return f"STRUC {t.name} {', '.join(out)}"


def check_name(name: str, limits: SnapshotLimits, what: str) -> str:
    upper = name.strip().upper()
    if not _IDENT.match(upper) or upper in KRL_KEYWORDS:
        raise ValueError(f"{what} name {name!r} is not a KRL name (letters, digits, _; no $)")
    if len(upper) > limits.name_length:
        raise ValueError(f"{what} name {name!r} is longer than {limits.name_length} characters")
    return upper


def unique_names(items: list[tuple[str, str | None]]) -> list[tuple[str, str | None]]:
    seen: set[str] = set()
    for name, _ in items:
        key = "".join(name.split()).upper()
        if key in seen:
            raise ValueError(f"{name!r} is in the snapshot twice")
        seen.add(key)
    return items


def _member_name(source: str, taken: set[str], registry: TypeRegistry, limit: int) -> str:
    """A member name derived from the copied expression: ``$TORQUE_AXIS_ACT[3]`` →
    ``TORQUE_AXIS_ACT_3``; unique, at most ``limit`` characters, never a keyword or type name."""
    stem = re.sub(r"[^A-Z0-9_]+", "_", source.upper()).strip("_") or "V"
    if stem[0].isdigit() or stem in KRL_KEYWORDS or stem in registry or re.fullmatch(r"G\d+", stem):
        stem = f"V_{stem}"
    candidate, k = stem[:limit], 1
    while candidate in taken:
        k += 1
        tail = f"_{k}"
        candidate = stem[: limit - len(tail)] + tail
    return candidate


def _text_max(spec: TypeSpec, registry: TypeRegistry, depth: int = 0) -> int:
    if spec.kind in _SCALAR_TEXT:
        return _SCALAR_TEXT[spec.kind]
    if spec.kind is Kind.ENUM:
        values = spec.enum.values if spec.enum is not None else ()
        return 1 + max((len(v) for v in values), default=_ENUM_TEXT - 1)
    if spec.kind is Kind.STRUCT and spec.struct is not None and depth < 8:
        inner = registry.member_specs(spec.struct)
        body = sum(len(m) + 3 + _text_max(s, registry, depth + 1) for m, s in inner.items())
        return len(spec.name) + 4 + body
    return 256  # a type this client cannot size: assume a modest structure


def _holds_array(spec: TypeSpec, registry: TypeRegistry, depth: int = 0) -> bool:
    if spec.struct is None or depth > 8:
        return False
    for _, type_name in spec.struct.members:
        tm = _TYPE.match(type_name.replace(" ", ""))
        if tm is not None and tm.group(2) is not None and tm.group(1) != "CHAR":
            return True
        try:
            inner = registry.resolve(type_name)
        except KrlValueError:
            continue
        if inner.kind is Kind.STRUCT and _holds_array(inner, registry, depth + 1):
            return True
    return False
