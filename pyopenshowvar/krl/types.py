"""The KRL value model: enums, structs and the typed pose structs (AXIS, E6AXIS, FRAME, POS, E6POS).

Scalars are plain Python values (``bool``, ``int``, ``float``, ``str`` for CHAR text) and a
whole array is a ``list``; only what Python lacks gets a class here:

* :class:`KrlEnum` — an ENUM value such as ``#T1``;
* :class:`Struct` — any STRUC value, members upper-case and in text order, possibly partial
  (a never-initialised member is simply absent, as the controller leaves it out of the text);
* :class:`Axis`, :class:`E6Axis`, :class:`Frame`, :class:`Pos`, :class:`E6Pos` — the pose
  structs, with keyword constructors, canonical member order and numpy conversion.

Parsing and printing live in :mod:`.parse` and :mod:`.format`, so this module has no text rules.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import (
    TYPE_CHECKING,
    Any,
    ClassVar,
    Generic,
    Self,
    TypeAlias,
    TypeVar,
    cast,
    overload,
)

from ..errors import KrlValueError

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

__all__ = [
    "TYPED_STRUCTS",
    "Axis",
    "E6Axis",
    "E6Pos",
    "Frame",
    "KrlEnum",
    "KrlValue",
    "Pos",
    "Struct",
]

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

_T = TypeVar("_T", float, int)


class _Member(Generic[_T]):
    """Descriptor giving ``pos.x`` a precise type: the member's value, or None when missing."""

    __slots__ = ("_key",)

    def __set_name__(self, owner: type[Any], name: str) -> None:
        self._key = name.upper()

    @overload
    def __get__(self, obj: None, owner: type[Any]) -> _Member[_T]: ...
    @overload
    def __get__(self, obj: Struct, owner: type[Any]) -> _T | None: ...
    def __get__(self, obj: Struct | None, owner: type[Any]) -> _Member[_T] | _T | None:
        if obj is None:
            return self
        return cast("_T | None", obj._members.get(self._key))

    def __set__(self, obj: Struct, value: _T) -> None:
        raise AttributeError("KRL structs are immutable; use .replace()")


_Real = _Member[float]
_Int = _Member[int]
_Number: TypeAlias = "float | int | np.integer[Any] | np.floating[Any]"


class _TypedStruct(Struct):
    """Common code of the pose structs: fixed type name, canonical order, coercion, numpy."""

    __slots__ = ()
    TYPE_NAME: ClassVar[str]
    MEMBERS: ClassVar[tuple[str, ...]]
    MAIN: ClassVar[tuple[str, ...]]
    EXTERNAL: ClassVar[tuple[str, ...]] = ()
    INT_MEMBERS: ClassVar[frozenset[str]] = frozenset()
    _MEMBER_SET: ClassVar[frozenset[str]]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls._MEMBER_SET = frozenset(cls.MEMBERS)

    def __init__(
        self, members: Mapping[str, _Number | None] | None = None, /, **kw: _Number | None
    ) -> None:
        given: dict[str, KrlValue] = {}
        for source in (members or {}, kw):
            for k, v in source.items():
                key = k.upper()
                if key not in self._MEMBER_SET:
                    raise KrlValueError(f"{self.TYPE_NAME} has no member {k!r}")
                if v is None:
                    given.pop(key, None)
                else:
                    given[key] = self._coerce(key, v)
        object.__setattr__(self, "_type_name", self.TYPE_NAME)
        object.__setattr__(self, "_members", {k: given[k] for k in self.MEMBERS if k in given})

    @classmethod
    def _coerce(cls, key: str, v: object) -> float | int:
        bools, ints, reals = scalar_types()
        if isinstance(v, bools) or not isinstance(v, ints + reals):
            raise KrlValueError(f"{cls.TYPE_NAME}.{key} must be a number, not {v!r}")
        number = cast("float", v)  # a Python or numpy int or float, checked just above
        if key in cls.INT_MEMBERS:
            if not math.isfinite(number) or int(number) != number:
                raise KrlValueError(f"{cls.TYPE_NAME}.{key} must be an integer, not {v!r}")
            return int(number)
        f = float(number)
        if not math.isfinite(f):
            raise KrlValueError(f"{cls.TYPE_NAME}.{key} must be finite, not {v!r}")
        return f

    @classmethod
    def _from_parsed(cls, members: dict[str, KrlValue]) -> Self:
        """Fast path for the parser: members are checked against the StructDef already."""
        order = cls.MEMBERS
        if len(members) == len(order) and tuple(members) == order:
            return cls._new(cls.TYPE_NAME, members)
        return cls._new(cls.TYPE_NAME, {k: members[k] for k in order if k in members})

    def _with(self, members: dict[str, KrlValue]) -> Self:
        return type(self)(cast("dict[str, _Number | None]", members))

    @property
    def is_complete(self) -> bool:
        """True when every member of the type is present."""
        return len(self._members) == len(self.MEMBERS)

    def to_numpy(self, *, with_external: bool = False) -> npt.NDArray[np.float64]:
        """The six main values (A1..A6 or X..C) as a float array; E1..E6 appended on request."""
        if with_external and not self.EXTERNAL:
            raise KrlValueError(f"{self.TYPE_NAME} has no external axes")
        names = self.MAIN + self.EXTERNAL if with_external else self.MAIN
        missing = [n for n in names if n not in self._members]
        if missing:
            raise KrlValueError(f"{self.TYPE_NAME} value lacks {', '.join(missing)}: {self!r}")
        import numpy as np  # numpy only for the numpy conversions (kvp read starts faster)

        return np.array([self._members[n] for n in names], dtype=np.float64)

    @classmethod
    def from_numpy(cls, arr: npt.ArrayLike, **extra: _Number | None) -> Self:
        """Build from 6 main values (or 12 = main + E1..E6 for E6 types); ``extra`` adds
        members by keyword, e.g. ``Pos.from_numpy(xyzabc, s=2, t=2)``."""
        import numpy as np

        a = np.asarray(arr, dtype=np.float64)
        n_main, n_all = len(cls.MAIN), len(cls.MAIN) + len(cls.EXTERNAL)
        if a.ndim != 1 or a.shape[0] not in {n_main, n_all}:
            sizes = f"{n_main} or {n_all}" if cls.EXTERNAL else f"{n_main}"
            raise KrlValueError(
                f"{cls.TYPE_NAME}.from_numpy needs {sizes} values, got shape {a.shape}"
            )
        names = cls.MAIN + cls.EXTERNAL if a.shape[0] == n_all else cls.MAIN
        members: dict[str, _Number | None] = {n: float(x) for n, x in zip(names, a, strict=True)}
        for k, v in extra.items():
            members[k.upper()] = v
        return cls(members)

    def __repr__(self) -> str:
        inner = ", ".join(f"{k.lower()}={v!r}" for k, v in self._members.items())
        return f"{type(self).__name__}({inner})"


_A = ("A1", "A2", "A3", "A4", "A5", "A6")
_E = ("E1", "E2", "E3", "E4", "E5", "E6")
_XYZABC = ("X", "Y", "Z", "A", "B", "C")


class Axis(_TypedStruct):
    """``AXIS``: A1..A6 in degrees (mm for linear axes)."""

    __slots__ = ()
    TYPE_NAME = "AXIS"
    MEMBERS = _A
    MAIN = _A
    a1, a2, a3, a4, a5, a6 = _Real(), _Real(), _Real(), _Real(), _Real(), _Real()


class E6Axis(_TypedStruct):
    """``E6AXIS``: A1..A6 then the external axes E1..E6."""

    __slots__ = ()
    TYPE_NAME = "E6AXIS"
    MEMBERS = _A + _E
    MAIN = _A
    EXTERNAL = _E
    a1, a2, a3, a4, a5, a6 = _Real(), _Real(), _Real(), _Real(), _Real(), _Real()
    e1, e2, e3, e4, e5, e6 = _Real(), _Real(), _Real(), _Real(), _Real(), _Real()


class Frame(_TypedStruct):
    """``FRAME``: X, Y, Z in mm and A, B, C in degrees (R = Rz(A)·Ry(B)·Rx(C))."""

    __slots__ = ()
    TYPE_NAME = "FRAME"
    MEMBERS = _XYZABC
    MAIN = _XYZABC
    x, y, z, a, b, c = _Real(), _Real(), _Real(), _Real(), _Real(), _Real()


class Pos(_TypedStruct):
    """``POS``: a FRAME plus the INT status S and turn T that pick the axis configuration."""

    __slots__ = ()
    TYPE_NAME = "POS"
    MEMBERS = (*_XYZABC, "S", "T")
    MAIN = _XYZABC
    INT_MEMBERS = frozenset({"S", "T"})
    x, y, z, a, b, c = _Real(), _Real(), _Real(), _Real(), _Real(), _Real()
    s, t = _Int(), _Int()


class E6Pos(_TypedStruct):
    """``E6POS``: POS plus E1..E6; text order X Y Z A B C S T E1..E6 as every KRC prints it."""

    __slots__ = ()
    TYPE_NAME = "E6POS"
    MEMBERS = (*_XYZABC, "S", "T", *_E)
    MAIN = _XYZABC
    EXTERNAL = _E
    INT_MEMBERS = frozenset({"S", "T"})
    x, y, z, a, b, c = _Real(), _Real(), _Real(), _Real(), _Real(), _Real()
    s, t = _Int(), _Int()
    e1, e2, e3, e4, e5, e6 = _Real(), _Real(), _Real(), _Real(), _Real(), _Real()


TYPED_STRUCTS: Mapping[str, type[_TypedStruct]] = {
    c.TYPE_NAME: c for c in (Axis, E6Axis, Frame, Pos, E6Pos)
}
