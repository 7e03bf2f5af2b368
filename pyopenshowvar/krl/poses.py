"""The typed pose structs: AXIS, E6AXIS, FRAME, POS and E6POS.

Each is a :class:`~.types.Struct` with its KRL type name and member order fixed, members
coerced to numbers when built (S and T to INT), keyword constructors (``Pos(x=1, y=2, ...)``),
attribute access with precise types (``pos.x`` is a float or None) and conversion to and from
numpy arrays. :data:`TYPED_STRUCTS` maps a type name to its class, for the parser.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar, Generic, Self, TypeAlias, TypeVar, cast, overload

from ..errors import KrlValueError
from .types import KrlValue, Struct, scalar_types

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

__all__ = ["TYPED_STRUCTS", "Axis", "E6Axis", "E6Pos", "Frame", "Pos"]

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
