"""The KRL value model: enums and structs (the typed pose structs are in :mod:`.poses`).

Scalars are plain Python values (``bool``, ``int``, ``float``, ``str`` for CHAR text) and a
whole array is a ``list``; only what Python lacks gets a class here:

* :class:`KrlEnum` — an ENUM value such as ``#T1``;
* :class:`Struct` — any STRUC value, members upper-case and in text order, possibly partial
  (a never-initialised member is simply absent, as the controller leaves it out of the text);
* the pose structs (:class:`~.poses.Axis`, :class:`~.poses.E6Pos`, ...) are Structs too, with
  keyword constructors, canonical member order and numpy conversion (:mod:`.poses`).

Parsing and printing live in :mod:`.parse` and :mod:`.format`, so this module has no text rules.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import (
    TYPE_CHECKING,
    Any,
    Self,
    TypeAlias,
)

from ..errors import KrlValueError

if TYPE_CHECKING:
    pass

__all__ = ["KrlEnum", "KrlValue", "Struct", "scalar_types"]

#: (bool types, int types, real types) a KRL scalar may come as: Python's own, plus numpy's
#: scalars once numpy is loaded (see :func:`scalar_types`).
ScalarTypes: TypeAlias = tuple[tuple[type, ...], tuple[type, ...], tuple[type, ...]]
_PLAIN_SCALARS: ScalarTypes = ((bool,), (int,), (float,))
_numpy_scalars: ScalarTypes | None = None


def scalar_types() -> ScalarTypes:
    """The Python and (when loaded) numpy scalar types, for isinstance checks.

    A numpy scalar can only exist once numpy is imported, so looking in ``sys.modules``
    instead of importing numpy here gives the same answers and keeps numpy out of processes
    that never use it: ``kvp read`` starts without paying for numpy's import.
    """
    global _numpy_scalars
    if _numpy_scalars is not None:
        return _numpy_scalars
    np_module = sys.modules.get("numpy")
    try:
        if np_module is None:
            return _PLAIN_SCALARS
        _numpy_scalars = (
            (bool, np_module.bool_),
            (int, np_module.integer),
            (float, np_module.floating),
        )
    except AttributeError:  # numpy is half-way through its own import (another thread)
        return _PLAIN_SCALARS
    return _numpy_scalars


_IDENT = re.compile(r"[A-Za-z_$][A-Za-z0-9_$]*\Z", re.ASCII)


def _ident(name: str, what: str) -> str:
    if not isinstance(name, str) or not _IDENT.match(name):
        raise KrlValueError(f"invalid KRL {what} {name!r}")
    return name.upper()


@dataclass(frozen=True, slots=True)
class KrlEnum:
    """An ENUM value. ``KrlEnum("t1")`` and ``KrlEnum("#T1")`` are equal; ``str()`` is ``#T1``."""

    name: str

    def __post_init__(self) -> None:
        name = self.name[1:] if isinstance(self.name, str) and self.name[:1] == "#" else self.name
        object.__setattr__(self, "name", _ident(name, "enum value"))

    def __str__(self) -> str:
        return f"#{self.name}"

    @classmethod
    def _from_parsed(cls, name: str) -> KrlEnum:
        """Build from an already validated upper-case name (the parser's fast path)."""
        obj = object.__new__(cls)
        object.__setattr__(obj, "name", name)
        return obj


class Struct:
    """A STRUC value: optional type name plus members in text order.

    Member names are upper-case; lookup is case-insensitive (``s["x"]``, ``s.get("X")``,
    ``s.x``). Two structs are equal when their type names match (both None, or the same name in
    any case) and their members are equal as dicts. Instances are immutable: use
    :meth:`replace` or :meth:`merged` to derive a changed copy.
    """

    __slots__ = ("_members", "_type_name")
    _type_name: str | None
    _members: dict[str, KrlValue]

    def __init__(
        self, type_name: str | None = None, members: Mapping[str, KrlValue] | None = None
    ) -> None:
        ms: dict[str, KrlValue] = {}
        for k, v in (members or {}).items():
            key = _ident(k, "member name")
            if key in ms:
                raise KrlValueError(f"duplicate struct member {k!r}")
            ms[key] = v
        tn = None if type_name is None else _ident(type_name, "type name")
        object.__setattr__(self, "_type_name", tn)
        object.__setattr__(self, "_members", ms)

    @classmethod
    def _new(cls, type_name: str | None, members: dict[str, KrlValue]) -> Self:
        """Build without validation; for the parser, which has checked everything already."""
        obj = object.__new__(cls)
        object.__setattr__(obj, "_type_name", type_name)
        object.__setattr__(obj, "_members", members)
        return obj

    def _with(self, members: dict[str, KrlValue]) -> Self:
        """A new struct of the same class and type with these members (typed classes re-check)."""
        return self._new(self._type_name, members)

    # --- read access -------------------------------------------------------------------------
    @property
    def type_name(self) -> str | None:
        """The STRUC type name, upper-case, or None for an untyped aggregate ``{X 1.0}``."""
        return self._type_name

    @property
    def members(self) -> Mapping[str, KrlValue]:
        """A read-only view of the members, in order."""
        return _ReadOnly(self._members)

    def __getitem__(self, key: str) -> KrlValue:
        return self._members[key.upper()]

    def get(self, key: str, default: KrlValue | None = None) -> KrlValue | None:
        return self._members.get(key.upper(), default)

    def __contains__(self, key: object) -> bool:
        return isinstance(key, str) and key.upper() in self._members

    def __iter__(self) -> Iterator[str]:
        return iter(self._members)

    def __len__(self) -> int:
        return len(self._members)

    def keys(self) -> Iterator[str]:
        return iter(self._members.keys())

    def items(self) -> Iterator[tuple[str, KrlValue]]:
        return iter(self._members.items())

    def values(self) -> Iterator[KrlValue]:
        return iter(self._members.values())

    def __getattr__(self, name: str) -> KrlValue:
        # only reached when normal lookup fails; private/dunder names must fail normally so
        # that copy, pickle and hasattr() behave
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            return self._members[name.upper()]
        except KeyError:
            raise AttributeError(f"struct {self._type_name or ''} has no member {name!r}") from None

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError("KRL structs are immutable; use .replace() or .merged()")

    def __delattr__(self, name: str) -> None:
        raise AttributeError("KRL structs are immutable; use .replace() or .merged()")

    # --- derived copies ----------------------------------------------------------------------
    def replace(self, **members: KrlValue | None) -> Self:
        """A copy with the given members (any case) set; a value of None removes the member."""
        new = dict(self._members)
        for k, v in members.items():
            key = k.upper()
            if v is None:
                new.pop(key, None)
            else:
                new[key] = v
        return self._with(new)

    def merged(self, other: Struct | Mapping[str, KrlValue]) -> Self:
        """KRL partial-aggregate assignment: members of ``other`` override, the rest stay.

        Nested structs merge recursively, so ``{CM {X 1.0}}`` changes only ``CM.X``.
        """
        new = dict(self._members)
        for k, v in other.items():
            key = k.upper()
            old = new.get(key)
            if isinstance(old, Struct) and isinstance(v, Struct):
                new[key] = old.merged(v)
            else:
                new[key] = v
        return self._with(new)

    # --- protocol ----------------------------------------------------------------------------
    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Struct):
            return NotImplemented
        return self._type_name == other._type_name and self._members == other._members

    def __hash__(self) -> int:
        # like a tuple: hashable unless a member is a list
        return hash((self._type_name, tuple(self._members.items())))

    def __repr__(self) -> str:
        return f"Struct({self._type_name!r}, {self._members!r})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (_rebuild, (type(self), self._type_name, dict(self._members)))


def _rebuild(cls: type[Struct], type_name: str | None, members: dict[str, KrlValue]) -> Struct:
    return cls._new(type_name, members)


class _ReadOnly(Mapping[str, "KrlValue"]):
    """Read-only, case-insensitive view of a struct's members."""

    __slots__ = ("_d",)

    def __init__(self, d: dict[str, KrlValue]) -> None:
        self._d = d

    def __getitem__(self, key: str) -> KrlValue:
        return self._d[key.upper()]

    def __iter__(self) -> Iterator[str]:
        return iter(self._d)

    def __len__(self) -> int:
        return len(self._d)

    def __repr__(self) -> str:
        return repr(self._d)


KrlValue: TypeAlias = "bool | int | float | str | KrlEnum | Struct | list[KrlValue]"
