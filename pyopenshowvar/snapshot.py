"""Consistent snapshots: many variables copied by the controller in one SPS pass, read in ONE request.

KUKAVARPROXY answers one variable per request, 2–3 ms each on a KRC4, so twenty variables read
one by one take ~50 ms and come from several interpolation cycles. A :class:`Snapshot` lets the
controller pack them instead: it lays the variables out as members of a KRL ``STRUC``, and
:mod:`pyopenshowvar.snapshot_krl` writes the KRL to install — the ``STRUC`` and ``DECL`` lines
for ``$CONFIG.DAT`` and an SPS fold that copies every variable into a work copy, counts the pass
in a ``CYCLE`` member and assigns the whole structure at once. The PC then reads that one
global (``Client.read_snapshot``) and gets typed values keyed by the original names, all from
one SPS pass, with the pass counter telling how old the snapshot is (docs/snapshots.md)::

    snap = Snapshot("CELL", ["$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[]", ("MYREAL", "REAL")])
    snap.write_krl("out/")                    # out/CELL.dat, out/CELL.sub
    reading = await kvp.read_snapshot(snap)   # reading["$AXIS_ACT"] -> E6Axis; reading.cycle

KRL's limits decide the layout (:class:`SnapshotLimits`): names of at most 24 characters, no
array inside a ``STRUC`` (KUKA documents only CHAR arrays there; a whole array ``X[]`` becomes
one member per element; CHAR text needs STRCOPY and is refused), and — our choices, since KUKA documents no maximum — STRUC declarations of at most
``struc_line`` characters (longer ones become nested group structures, still one read) and at
most ``max_text`` characters of reply text per read (more makes several top-level structures,
read pipelined and checked to come from the same pass). This module does no I/O: the read is
an operation (:mod:`pyopenshowvar.core`) both clients run.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .core import Op
from .errors import KrlValueError, UnknownVariableError, VariableError
from .krl import BUILTIN_TYPES, Kind, KrlValue, Struct, TypeRegistry, TypeSpec, parse_value
from .krl.systypes import system_type

__all__ = [
    "COUNTER",
    "KRL_KEYWORDS",
    "Snapshot",
    "SnapshotLimits",
    "SnapshotReading",
    "SnapshotTornError",
    "read_snapshot",
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


class SnapshotTornError(VariableError):
    """The parts of a multi-part snapshot kept coming from different SPS passes."""


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


class Snapshot:
    """A named group of variables the controller copies together; see the module docstring.

    ``variables``: names (system variables' types are known, :mod:`pyopenshowvar.krl.systypes`)
    or ``(name, type)`` pairs (``("MYPOS", "POS")``, ``("MYARR[]", "REAL[10]")``, the type of
    the value the name addresses), or a mapping name → type (None: look it up). ``registry``
    declares user STRUC/ENUM types used by them. Raises ``ValueError`` for anything KRL cannot
    hold, with the reason.
    """

    def __init__(
        self,
        name: str,
        variables: Iterable[str | tuple[str, str]] | Mapping[str, str | None],
        *,
        registry: TypeRegistry | None = None,
        limits: SnapshotLimits | None = None,
    ) -> None:
        self.limits = limits or SnapshotLimits()
        self.name = _check_name(name, self.limits, "snapshot")
        self._registry = registry if registry is not None else BUILTIN_TYPES
        items: list[tuple[str, str | None]]
        if isinstance(variables, Mapping):
            items = list(variables.items())
        else:
            items = [(v, None) if isinstance(v, str) else (v[0], v[1]) for v in variables]
        if not items:
            raise ValueError("a snapshot needs at least one variable")
        taken = {COUNTER}
        self.variables: tuple[Variable, ...] = tuple(
            self._variable(n, t, taken) for n, t in _unique(items)
        )
        self.parts: tuple[Part, ...] = tuple(self._layout())
        self._types = self._build_registry()

    # ------------------------------------------------------------------ public

    @property
    def names(self) -> tuple[str, ...]:
        """The variables as given, in order (the keys of a :class:`SnapshotReading`)."""
        return tuple(v.name for v in self.variables)

    @property
    def read_names(self) -> tuple[str, ...]:
        """The globals the PC reads: one, unless the limits split the snapshot."""
        return tuple(p.variable for p in self.parts)

    @property
    def registry(self) -> TypeRegistry:
        """The user registry plus the generated STRUC types (what the reply is parsed with)."""
        return self._types

    def krl_dat(self) -> str:
        """The ``$CONFIG.DAT`` declarations (a data list the emulator loads with ``--config``)."""
        from .snapshot_krl import dat_text

        return dat_text(self)

    def krl_sub(self) -> str:
        """The SPS that copies the variables each pass (``--sps`` of the emulator)."""
        from .snapshot_krl import sub_text

        return sub_text(self)

    def write_krl(self, directory: str | Path) -> tuple[Path, Path]:
        """Write ``DIR/<name>.dat`` and ``DIR/<name>.sub`` (latin-1, CRLF as a KRC expects)."""
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        paths = (out / f"{self.name}.dat", out / f"{self.name}.sub")
        for path, text in zip(paths, (self.krl_dat(), self.krl_sub()), strict=True):
            path.write_bytes(text.replace("\n", "\r\n").encode("latin-1"))
        return paths

    def parse(self, texts: Sequence[str], endpoint: str = "") -> SnapshotReading:
        """Typed values from the replies to :attr:`read_names` (same order).

        Raises :class:`KrlValueError` when a reply does not have this snapshot's layout (the
        controller runs other KRL than this definition generates) and
        :class:`SnapshotTornError` when the parts come from different SPS passes.
        """
        if len(texts) != len(self.parts):
            raise ValueError(f"expected {len(self.parts)} replies, got {len(texts)}")
        values: dict[str, KrlValue] = {}
        cycles: list[int] = []
        slot_values: dict[int, KrlValue] = {}
        for part, text in zip(self.parts, texts, strict=True):
            top = self._parse_part(part, text, endpoint)
            cycle = top.get(COUNTER)
            if not isinstance(cycle, int) or isinstance(cycle, bool):
                raise self._mismatch(part, f"no INT {COUNTER} member", endpoint)
            cycles.append(cycle)
            for path, slot in part.paths:
                try:
                    slot_values[id(slot)] = _member(top, path)
                except KeyError:
                    raise self._mismatch(
                        part, f"no member {path} (other KRL installed?)", endpoint
                    ) from None
        if len(set(cycles)) > 1:
            raise SnapshotTornError(
                f"parts {', '.join(self.read_names)} come from SPS passes {cycles}",
                name=self.name,
                endpoint=endpoint,
            )
        for var in self.variables:
            got = [slot_values[id(s)] for s in var.slots]
            values[var.name] = got if var.whole_array else got[0]
        return SnapshotReading(self, values, cycles[0])

    def __repr__(self) -> str:
        return f"Snapshot({self.name!r}, {list(self.names)!r})"

    # ------------------------------------------------------------------ variables

    def _variable(self, name: str, type_name: str | None, taken: set[str]) -> Variable:
        source = "".join(name.split()).upper()
        m = _VAR.match(source)
        if m is None:
            raise ValueError(f"{name!r} is not a KRL variable name")
        base, index, members = m.group(1), m.group(2), m.group(3)
        type_expr = (type_name or "").replace(" ", "").upper() or self._system_type(
            name, base, index, members
        )
        spec, length = self._resolve(name, type_expr)
        if index is not None and not index.strip():  # NAME[]: one member per element
            if members:
                raise ValueError(f"{name!r}: a member of a whole array means nothing")
            if length is None:
                raise ValueError(
                    f"{name!r} is a whole array: give its length, e.g. ({name!r}, 'REAL[10]')"
                )
            if length > self.limits.max_elements:
                raise ValueError(
                    f"{name!r} has {length} elements; a snapshot takes at most "
                    f"{self.limits.max_elements} of one array: name the elements you need"
                )
            elem = spec.elem if spec.kind is Kind.ARRAY and spec.elem is not None else spec
            slots = tuple(self._slot(f"{base}[{i}]", elem, taken) for i in range(1, length + 1))
            return Variable(name, type_expr, slots, True)
        if length is not None:
            raise ValueError(
                f"{name!r} is an array ({type_expr}): read it whole as '{base}[]' or name an element"
            )
        return Variable(name, type_expr, (self._slot(source, spec, taken),), False)

    def _system_type(self, name: str, base: str, index: str | None, members: str) -> str:
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
            struct = self._registry.struct(type_expr)
            member_type = struct.member_type(member) if struct is not None else None
            if member_type is None:
                raise ValueError(f"{name!r}: {type_expr} has no member {member}")
            type_expr = member_type
        return type_expr

    def _resolve(self, name: str, type_expr: str) -> tuple[TypeSpec, int | None]:
        tm = _TYPE.match(type_expr)
        if tm is None:
            raise ValueError(
                f"{name!r}: {type_expr!r} is not a KRL type (e.g. REAL, E6POS, INT[12])"
            )
        base, length = tm.group(1), tm.group(2)
        if base == "CHAR":
            raise ValueError(
                f"{name!r} is CHAR text: KRL copies a CHAR array only with STRCOPY, which"
                " snapshots do not generate; read it on its own"
            )
        try:
            spec = self._registry.resolve(base)
        except KrlValueError:
            if not _IDENT.match(base):
                raise ValueError(f"{name!r}: {type_expr!r} is not a KRL type") from None
            # a user type this client does not know: declared as given, its text parsed untyped
            spec = TypeSpec(Kind.STRUCT, base)
        if spec.kind is Kind.STRUCT and _holds_array(spec, self._registry):
            raise ValueError(
                f"{name!r}: STRUC {base} holds an array; KRL documents only CHAR arrays"
                " as STRUC members, so a snapshot cannot nest it"
            )
        return spec, None if length is None else int(length)

    def _slot(self, source: str, spec: TypeSpec, taken: set[str]) -> Slot:
        member = _member_name(source, taken, self._registry, self.limits.name_length)
        taken.add(member)
        return Slot(source, member, spec.name, len(member) + 3 + _text_max(spec, self._registry))

    # ------------------------------------------------------------------ layout

    def _layout(self) -> Iterator[Part]:
        slots = [s for v in self.variables for s in v.slots]
        index = 0
        number = 1
        while index < len(slots):
            taken: list[Slot] = []
            layout: Part | None = None
            while index + len(taken) < len(slots):
                trial = self._part(number, [*taken, slots[index + len(taken)]])
                if trial is None:
                    break
                taken.append(slots[index + len(taken)])
                layout = trial
            if layout is None:
                slot = slots[index]
                raise ValueError(
                    f"{slot.source} alone does not fit the limits ({self.limits}): raise them"
                )
            yield layout
            index += len(taken)
            number += 1

    def _part(self, number: int, slots: list[Slot]) -> Part | None:
        """The part holding ``slots`` (flat or nested), or None if the limits forbid it."""
        lim = self.limits
        suffix = "" if number == 1 else str(number)
        variable, type_name = f"{self.name}{suffix}", f"{self.name}{suffix}_T"
        text = sum(s.text_max for s in slots) + len(type_name) + 24  # "{T: CYCLE n, ...}"
        if text > lim.max_text:
            return None
        counter = (COUNTER, "INT")
        flat = StrucType(type_name, (counter, *((s.member, s.type_name) for s in slots)))
        if len(struc_line(flat)) <= lim.struc_line:
            paths = tuple((s.member, s) for s in slots)
            return self._checked(Part(variable, f"{variable}_W", type_name, (flat,), paths))
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
        return self._checked(Part(variable, f"{variable}_W", type_name, (*types, top), paths))

    def _checked(self, part: Part) -> Part | None:
        longest = max([part.work, *(t.name for t in part.types), f"{self.name}_SPS"], key=len)
        if len(longest) > self.limits.name_length:
            if part.variable == self.name:  # even the first part's names are too long
                raise ValueError(
                    f"snapshot name {self.name!r} is too long: it makes {longest!r}, and KRL"
                    f" names have at most {self.limits.name_length} characters"
                )
            return None
        return part

    def _build_registry(self) -> TypeRegistry:
        reg = self._registry.copy()
        for part in self.parts:
            for t in part.types:
                reg.add_struct(t.name, t.members)
        return reg

    # ------------------------------------------------------------------ parsing

    def _parse_part(self, part: Part, text: str, endpoint: str) -> Struct:
        try:
            value = parse_value(text, part.type_name, registry=self._types)
        except KrlValueError as exc:
            raise self._mismatch(part, str(exc), endpoint) from None
        if not isinstance(value, Struct) or value.type_name not in (None, part.type_name):
            raise self._mismatch(part, f"not a {part.type_name}", endpoint)
        return value

    def _mismatch(self, part: Part, why: str, endpoint: str) -> KrlValueError:
        where = f" on {endpoint}" if endpoint else ""
        return KrlValueError(
            f"snapshot {self.name!r}: {part.variable}{where} does not match this definition"
            f" ({why}); install the KRL generated for it (kvp snapshot krl)"
        )


class SnapshotReading(Mapping[str, KrlValue]):
    """One snapshot read: typed values keyed by the variable names as given, plus the pass.

    ``cycle`` is the SPS pass counter of the snapshot: two readings with the same cycle are the
    same copy, and its growth over time shows the SPS runs (docs/snapshots.md, "Age").
    """

    __slots__ = ("_values", "cycle", "snapshot")

    def __init__(self, snapshot: Snapshot, values: dict[str, KrlValue], cycle: int) -> None:
        self.snapshot = snapshot
        self._values = values
        self.cycle = cycle

    def __getitem__(self, name: str) -> KrlValue:
        return self._values[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        return f"SnapshotReading({self.snapshot.name!r}, cycle={self.cycle}, {self._values!r})"


def read_snapshot(
    io: Any, snapshot: Snapshot, *, retries: int = 3, timeout: float | None = None
) -> Op[SnapshotReading]:
    """Read ``snapshot`` in ONE request (one per part when its limits split it).

    Returns a :class:`SnapshotReading`: typed values keyed by the names the snapshot was made
    with, and the SPS pass counter. A multi-part snapshot whose parts come from different passes
    is read again, up to ``retries`` times, then :class:`SnapshotTornError`. A snapshot that is
    not on the controller (or that the SPS never filled) raises :class:`UnknownVariableError`
    saying so.
    """
    names = snapshot.read_names
    for attempt in range(retries + 1):
        try:
            if len(names) == 1:
                texts = [(yield ("read", (names[0],), {"timeout": timeout}))]
            else:
                results = yield ("read_many", (names,), {"timeout": timeout})
                texts = [results[n].unwrap() for n in names]
        except UnknownVariableError as exc:
            raise UnknownVariableError(
                f"snapshot {snapshot.name!r} is not readable: install its KRL (kvp snapshot krl,"
                " docs/snapshots.md) and check that the SPS runs",
                name=exc.name,
                endpoint=io.endpoint,
            ) from exc
        try:
            return snapshot.parse(texts, io.endpoint)
        except SnapshotTornError:
            if attempt == retries:
                raise
    raise AssertionError("unreachable")  # pragma: no cover


# --------------------------------------------------------------------------- helpers


def struc_line(t: StrucType) -> str:
    """``STRUC NAME INT CYCLE, E6AXIS AXIS_ACT, REAL A, B``: consecutive members of one type
    share it, as KRL allows."""
    out: list[str] = []
    previous = None
    for member, type_name in t.members:
        out.append(member if type_name == previous else f"{type_name} {member}")
        previous = type_name
    return f"STRUC {t.name} {', '.join(out)}"


def _check_name(name: str, limits: SnapshotLimits, what: str) -> str:
    upper = name.strip().upper()
    if not _IDENT.match(upper) or upper in KRL_KEYWORDS:
        raise ValueError(f"{what} name {name!r} is not a KRL name (letters, digits, _; no $)")
    if len(upper) > limits.name_length:
        raise ValueError(f"{what} name {name!r} is longer than {limits.name_length} characters")
    return upper


def _unique(items: list[tuple[str, str | None]]) -> list[tuple[str, str | None]]:
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


def _member(top: Struct, path: str) -> KrlValue:
    value: KrlValue = top
    for key in path.split("."):
        if not isinstance(value, Struct) or key not in value:
            raise KeyError(path)
        value = value[key]
    return value
