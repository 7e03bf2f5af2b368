"""Typed KRL values: one parser, one formatter (KRC4 exact), no I/O.

>>> from pyopenshowvar.krl import parse_value, format_krc4, E6Axis
>>> home = parse_value("{E6AXIS: A1 0.0, A2 -90.0000, A3 90.0000}")
>>> home == E6Axis(a1=0.0, a2=-90.0, a3=90.0)
True
>>> format_krc4(home)
'{E6AXIS: A1 0.0, A2 -90.0000, A3 90.0000}'

Both the client and the emulator use this package, so whatever one side prints the other parses.
"""

from __future__ import annotations

from .format import format_krc4, format_value
from .numfmt import float32, format_real_krc4, format_real_shortest
from .parse import parse_array, parse_value
from .poses import TYPED_STRUCTS, Axis, E6Axis, E6Pos, Frame, Pos
from .typedefs import BUILTIN_TYPES, EnumDef, Kind, StructDef, TypeRegistry, TypeSpec
from .types import KrlEnum, KrlValue, Struct

__all__ = [
    "BUILTIN_TYPES",
    "TYPED_STRUCTS",
    "Axis",
    "E6Axis",
    "E6Pos",
    "EnumDef",
    "Frame",
    "Kind",
    "KrlEnum",
    "KrlValue",
    "Pos",
    "Struct",
    "StructDef",
    "TypeRegistry",
    "TypeSpec",
    "float32",
    "format_krc4",
    "format_real_krc4",
    "format_real_shortest",
    "format_value",
    "parse_array",
    "parse_value",
]
