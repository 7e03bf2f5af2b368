"""The one KRL value formatter, in two flavours.

* :func:`format_value` — the literal a client WRITES: shortest round-trip REALs (``1.5E-05``),
  untyped partial aggregates ``{X 1.5, Z 3.0}`` kept untyped so that KRL leaves the other
  members alone.
* :func:`format_krc4` — byte-identical to what a KRC4 PRINTS on a read (REAL as float32 via
  ``%#.6g``/``%#.9g``, whole arrays with a trailing space); the emulator's store prints with it
  and, like KUKAVARPROXY, trims the value before it goes on the wire.

Both are locale independent and both round-trip through :func:`~.parse.parse_value`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import SupportsFloat, SupportsInt, cast

from ..errors import KrlValueError
from .numfmt import format_real_krc4, format_real_shortest
from .types import KrlEnum, KrlValue, Struct, scalar_types

__all__ = ["format_krc4", "format_real_krc4", "format_value"]


def _text(v: str) -> str:
    if '"' in v:
        # KRL has no escape sequences: a quote cannot be part of a CHAR text literal
        raise KrlValueError(f"a KRL CHAR text cannot contain a double quote: {v!r}")
    try:
        v.encode("latin-1")
    except UnicodeEncodeError:
        raise KrlValueError(f"a KRL CHAR text must be latin-1: {v!r}") from None
    return f'"{v}"'


def _fmt(v: object, real: Callable[[float], str], krc4: bool, in_list: bool = False) -> str:
    bools, ints, reals = scalar_types()  # numpy's scalars too, once numpy is loaded
    # bool before int: bool is an int subclass
    if isinstance(v, bools):
        return "TRUE" if v else "FALSE"
    if isinstance(v, ints):
        return str(int(cast(SupportsInt, v)))
    if isinstance(v, reals):
        return real(float(cast(SupportsFloat, v)))
    if isinstance(v, str):
        return _text(v)
    if isinstance(v, KrlEnum):
        return f"#{v.name}"
    if isinstance(v, Struct):
        body = ", ".join(f"{k} {_fmt(m, real, krc4)}" for k, m in v.items())
        return f"{{{v.type_name}: {body}}}" if v.type_name is not None else f"{{{body}}}"
    if isinstance(v, list | tuple) and not in_list:
        parts = [_fmt(e, real, krc4, in_list=True) for e in v]
        if krc4:
            # a KRC prints every element of a NAME[] read followed by one space
            return "".join(p + " " for p in parts)
        return " ".join(parts)
    raise KrlValueError(f"cannot format {v!r} as a KRL value")


def format_value(value: KrlValue | Sequence[KrlValue]) -> str:
    """The KRL literal to write for ``value``.

    REALs use the shortest text that reads back as the same Python float, always with ``.``
    or an upper-case ``E`` exponent; NaN and infinities raise :class:`KrlValueError`, as do
    CHAR texts containing ``"`` or non-latin-1 characters. Structs print with their type name
    when they have one; lists print space separated (without a trailing space).
    """
    return _fmt(value, format_real_shortest, krc4=False)


def format_krc4(value: KrlValue | Sequence[KrlValue]) -> str:
    """``value`` printed exactly as a KRC4 prints it on a read (reference §4.2)."""
    return _fmt(value, format_real_krc4, krc4=True)
