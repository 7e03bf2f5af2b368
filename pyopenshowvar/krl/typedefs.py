"""KRL type declarations: the STRUC and ENUM registry the parser uses to type values.

A KRC prints ``{LOAD: M 65.0000, CM {FRAME: ...}, ...}`` but the text alone does not say that
``S 2`` of an E6POS is an INT while ``X 2`` is a REAL, nor which names an ENUM allows. The
:class:`TypeRegistry` holds that knowledge: :data:`BUILTIN_TYPES` has the system types
(AXIS, E6AXIS, FRAME, POS, E6POS, LOAD, ...) and the emulator extends a :meth:`~TypeRegistry.copy`
with the user ``STRUC``/``ENUM`` declarations of its ``$CONFIG.DAT``.

:meth:`TypeRegistry.resolve` turns a type name as written in KRL (``"REAL"``, ``"CHAR[24]"``,
``"E6AXIS[]"``, ``"MODE_OP"``) into a :class:`TypeSpec`; results are cached per registry because
the parser resolves the same few member types for every E6POS it reads.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from enum import Enum

from ..errors import KrlValueError

__all__ = [
    "BUILTIN_TYPES",
    "SCALAR_TYPES",
    "EnumDef",
    "Kind",
    "StructDef",
    "TypeRegistry",
    "TypeSpec",
]

_IDENT = re.compile(r"[A-Za-z_$][A-Za-z0-9_$]*\Z", re.ASCII)
# NAME or NAME[...] (any dimensions, sizes optional): "CHAR[24]", "REAL[]", "E6AXIS[12]"
_TYPE_EXPR = re.compile(r"\s*([A-Za-z_$][A-Za-z0-9_$]*)\s*(\[[0-9,\s]*\])?\s*\Z", re.ASCII)


def _ident(name: str, what: str) -> str:
    """Return ``name`` upper-cased, or raise if it is not a KRL identifier."""
    if not _IDENT.match(name):
        raise KrlValueError(f"invalid KRL {what} name {name!r}")
    return name.upper()


class Kind(Enum):
    """What a resolved type is; the parser and formatter switch on this."""

    INT = "INT"
    REAL = "REAL"
    BOOL = "BOOL"
    STR = "CHAR"  # a CHAR array read as a whole, i.e. text
    ENUM = "ENUM"
    STRUCT = "STRUCT"
    ARRAY = "ARRAY"


SCALAR_TYPES: frozenset[str] = frozenset({"INT", "REAL", "BOOL", "CHAR"})


@dataclass(frozen=True, slots=True)
class StructDef:
    """A ``STRUC`` declaration: its name and ``(member, type)`` pairs in declaration order.

    Names are stored upper-case (KRL is case-insensitive). Member types are KRL type names as
    written in the declaration, e.g. ``"REAL"``, ``"FRAME"``, ``"CHAR[24]"``.
    """

    name: str
    members: tuple[tuple[str, str], ...]
    _index: dict[str, str] = field(init=False, repr=False, compare=False, hash=False)
    _names: tuple[str, ...] = field(init=False, repr=False, compare=False, hash=False)

    def __post_init__(self) -> None:
        members = tuple((_ident(m, "member"), " ".join(t.split()).upper()) for m, t in self.members)
        index = dict(members)
        if len(index) != len(members):
            raise KrlValueError(f"duplicate member in STRUC {self.name!r}: {self.members!r}")
        object.__setattr__(self, "name", _ident(self.name, "type"))
        object.__setattr__(self, "members", members)
        object.__setattr__(self, "_index", index)
        object.__setattr__(self, "_names", tuple(index))

    @property
    def member_names(self) -> tuple[str, ...]:
        """Member names in declaration order (the order a KRC prints them in)."""
        return self._names

    def member_type(self, member: str) -> str | None:
        """The declared type of ``member`` (any case), or None if the STRUC has no such member."""
        return self._index.get(member.upper())


@dataclass(frozen=True, slots=True)
class EnumDef:
    """An ``ENUM`` declaration: the type name and its value names (upper-case, no ``#``)."""

    name: str
    values: tuple[str, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", _ident(self.name, "type"))
        object.__setattr__(
            self, "values", tuple(_ident(v.lstrip("#"), "enum value") for v in self.values)
        )


@dataclass(frozen=True, slots=True)
class TypeSpec:
    """A resolved type: the kind plus the declaration (struct/enum) or element type (array)."""

    kind: Kind
    name: str
    struct: StructDef | None = None
    enum: EnumDef | None = None
    elem: TypeSpec | None = None


_SCALAR_SPECS = {
    "INT": TypeSpec(Kind.INT, "INT"),
    "REAL": TypeSpec(Kind.REAL, "REAL"),
    "BOOL": TypeSpec(Kind.BOOL, "BOOL"),
    "CHAR": TypeSpec(Kind.STR, "CHAR"),
}


class TypeRegistry:
    """Struct and enum declarations by (case-insensitive) name.

    A registry created with ``frozen=True`` (like :data:`BUILTIN_TYPES`) refuses additions so
    that one emulator's ``$CONFIG.DAT`` cannot leak into every other user; extend a
    :meth:`copy` instead. Copies are shallow (the declarations are immutable), hence cheap.
    """

    __slots__ = ("_cache", "_defs", "_frozen", "_member_cache")

    def __init__(
        self,
        structs: tuple[StructDef, ...] = (),
        enums: tuple[EnumDef, ...] = (),
        *,
        frozen: bool = False,
    ) -> None:
        self._defs: dict[str, StructDef | EnumDef] = {}
        self._cache: dict[str, TypeSpec] = {}
        self._member_cache: dict[str, dict[str, TypeSpec]] = {}
        self._frozen = False
        for s in structs:
            self.add_struct(s)
        for e in enums:
            self.add_enum(e)
        self._frozen = frozen

    def copy(self) -> TypeRegistry:
        """A mutable copy sharing the (immutable) declarations."""
        new = TypeRegistry()
        new._defs = dict(self._defs)
        return new

    @property
    def frozen(self) -> bool:
        return self._frozen

    def _add(self, d: StructDef | EnumDef) -> None:
        if self._frozen:
            raise TypeError("this TypeRegistry is read-only; extend a .copy() of it")
        if d.name in SCALAR_TYPES:
            raise KrlValueError(f"cannot redeclare the builtin type {d.name!r}")
        self._defs[d.name] = d
        # a redeclaration may change what cached member types resolve to
        self._cache.clear()
        self._member_cache.clear()

    def add_struct(
        self, struct: StructDef | str, members: Iterable[tuple[str, str]] = ()
    ) -> StructDef:
        """Declare a STRUC: ``add_struct(StructDef(...))`` or ``add_struct("NAME", members)``."""
        d = struct if isinstance(struct, StructDef) else StructDef(struct, tuple(members))
        self._add(d)
        return d

    def add_enum(self, enum: EnumDef | str, values: Iterable[str] = ()) -> EnumDef:
        """Declare an ENUM: ``add_enum(EnumDef(...))`` or ``add_enum("NAME", ("A", "B"))``."""
        d = enum if isinstance(enum, EnumDef) else EnumDef(enum, tuple(values))
        self._add(d)
        return d

    def get(self, name: str) -> StructDef | EnumDef | None:
        """The declaration named ``name`` (any case), or None."""
        return self._defs.get(name.upper())

    def struct(self, name: str) -> StructDef | None:
        """The STRUC named ``name`` (any case), or None (also for an ENUM of that name)."""
        d = self._defs.get(name.upper())
        return d if isinstance(d, StructDef) else None

    def enum(self, name: str) -> EnumDef | None:
        """The ENUM named ``name`` (any case), or None."""
        d = self._defs.get(name.upper())
        return d if isinstance(d, EnumDef) else None

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name.upper() in self._defs

    def __iter__(self) -> Iterator[StructDef | EnumDef]:
        return iter(self._defs.values())

    def names(self) -> tuple[str, ...]:
        return tuple(self._defs)

    def resolve(self, type_name: str) -> TypeSpec:
        """Resolve a KRL type expression; raise :class:`KrlValueError` for unknown types.

        ``CHAR`` with or without brackets is text (a ``str``); any other ``T[...]`` is an array
        of ``T`` (a ``list``).
        """
        spec = self._cache.get(type_name)
        if spec is not None:
            return spec
        m = _TYPE_EXPR.match(type_name)
        if m is None:
            raise KrlValueError(f"invalid KRL type name {type_name!r}")
        base, dims = m.group(1).upper(), m.group(2)
        spec = self._resolve_base(base, type_name)
        if dims is not None and spec.kind is not Kind.STR:
            spec = TypeSpec(Kind.ARRAY, f"{base}[]", elem=spec)
        self._cache[type_name] = spec
        return spec

    def member_specs(self, struct: StructDef) -> dict[str, TypeSpec]:
        """Resolved member types of ``struct``, cached (the parser's per-member lookup).

        Members whose type does not resolve are left out; :meth:`resolve` on their declared
        type gives the error when such a member is actually met.
        """
        specs = self._member_cache.get(struct.name)
        if specs is None:
            specs = {}
            for member, type_name in struct.members:
                try:
                    specs[member] = self.resolve(type_name)
                except KrlValueError:
                    pass
            self._member_cache[struct.name] = specs
        return specs

    def _resolve_base(self, base: str, original: str) -> TypeSpec:
        scalar = _SCALAR_SPECS.get(base)
        if scalar is not None:
            return scalar
        d = self._defs.get(base)
        if isinstance(d, StructDef):
            return TypeSpec(Kind.STRUCT, base, struct=d)
        if isinstance(d, EnumDef):
            return TypeSpec(Kind.ENUM, base, enum=d)
        raise KrlValueError(f"unknown KRL type {original!r}")


def _reals(*names: str) -> tuple[tuple[str, str], ...]:
    return tuple((n, "REAL") for n in names)


_AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
_EXT = ("E1", "E2", "E3", "E4", "E5", "E6")
_XYZABC = ("X", "Y", "Z", "A", "B", "C")
_ST = (("S", "INT"), ("T", "INT"))

BUILTIN_TYPES: TypeRegistry = TypeRegistry(
    structs=(
        StructDef("AXIS", _reals(*_AXES)),
        StructDef("E6AXIS", _reals(*_AXES, *_EXT)),
        StructDef("FRAME", _reals(*_XYZABC)),
        StructDef("POS", _reals(*_XYZABC) + _ST),
        # text order of a real E6POS is X Y Z A B C S T E1..E6 (reference §2.1)
        StructDef("E6POS", _reals(*_XYZABC) + _ST + _reals(*_EXT)),
        StructDef("INERTIA", _reals("X", "Y", "Z")),
        StructDef("LOAD", (("M", "REAL"), ("CM", "FRAME"), ("J", "INERTIA"))),
        StructDef("CP", _reals("CP", "ORI1", "ORI2")),
        StructDef("APO", (("CVEL", "INT"), ("CPTP", "INT"), ("CDIS", "REAL"), ("CORI", "REAL"))),
        StructDef(
            "DATE",
            tuple((n, "INT") for n in ("CSEC", "SEC", "MIN", "HOUR", "DAY", "MONTH", "YEAR")),
        ),
    ),
    enums=(
        EnumDef("MODE_OP", ("T1", "T2", "AUT", "EX", "INVALID")),
        EnumDef("PRO_STATE", ("P_FREE", "P_RESET", "P_ACTIVE", "P_STOP", "P_END")),
    ),
    frozen=True,
)
