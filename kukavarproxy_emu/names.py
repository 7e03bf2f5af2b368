"""Variable names and what they address: KRL name parsing and the layout of a declared variable.

A KUKAVARPROXY request names a variable as text: ``NAME``, ``NAME.MEMBER.MEMBER``, ``NAME[i]`` /
``NAME[i,j]`` (1-based), ``NAME[i].MEMBER`` or ``NAME[]`` (the whole 1-D array; a CHAR array is
one text). :func:`parse_name` turns that text into a :class:`VarPath`, and :meth:`Var.slot`
maps a path onto the storage of one declared variable, refusing forms that do not fit it.
Names are case-insensitive, as in KRL: everything is upper-cased here.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from math import prod

from pyopenshowvar.krl import Kind, KrlValue, TypeRegistry, TypeSpec
from pyopenshowvar.krl.datfile import MAX_ELEMENTS

from .values import Range, Refused, member_specs

__all__ = ["Var", "VarPath", "parse_name"]

_NAME = re.compile(
    r"(@?[A-Z_$][A-Z0-9_$]*)(?:\[([0-9,\s]*)\])?((?:\.[A-Z_$][A-Z0-9_$]*)*)\Z", re.ASCII
)


@dataclass(frozen=True, slots=True)
class VarPath:
    """A parsed variable name: base, optional index (``()`` = ``NAME[]``), members."""

    base: str
    index: tuple[int, ...] | None
    members: tuple[str, ...]


#: Names up to this many characters are cached. A KRL identifier has at most 24 characters, so
#: every real path (``MYE6ARRAY[512].A1``) fits; longer names, which only a client probing the
#: server sends, are parsed each time instead of pinning their text in memory.
CACHED_NAME_LENGTH = 96
#: Cached names: with the length limit above the cache holds at most ~2 MB of text.
NAME_CACHE_SIZE = 8192


def parse_name(name: str) -> VarPath | None:
    """The path ``name`` spells, or None when it is not a variable name."""
    if len(name) <= CACHED_NAME_LENGTH:
        return _parse_cached(name)
    return _parse(name)


def _parse(name: str) -> VarPath | None:
    m = _NAME.match(name.strip().upper())
    if m is None:
        return None
    base, inside, members = m.groups()
    index: tuple[int, ...] | None = None
    if inside is not None:
        if inside.strip():
            try:
                index = tuple(int(part) for part in inside.split(","))
            except ValueError:
                return None
        elif members:
            return None  # "NAME[].X" means nothing
        else:
            index = ()
    return VarPath(base, index, tuple(members[1:].split(".")) if members else ())


# Cached: a server sees the same few names thousands of times a second.
_parse_cached = lru_cache(maxsize=NAME_CACHE_SIZE)(_parse)


class Var:
    """One declared variable. Arrays keep a flat row-major list; a CHAR array is one str."""

    __slots__ = (
        "dims", "elem_text", "elems", "name", "ranges", "read_only", "spec", "text_len",
        "type_name",
    )  # fmt: skip

    def __init__(self, name: str, type_name: str, spec: TypeSpec, dims: tuple[int, ...]) -> None:
        self.name = name
        self.type_name = type_name
        self.spec = spec
        self.dims = dims
        self.read_only = False
        self.ranges: Range | Mapping[str, Range] | None = None
        # A CHAR array is text (one str value); every other array holds its elements.
        self.text_len = dims[0] if spec.kind is Kind.STR and dims else 0
        if prod(dims) > MAX_ELEMENTS:
            raise ValueError(f"{prod(dims)} elements exceed the limit of {MAX_ELEMENTS}")
        size = prod(dims) if dims and not self.text_len else 1
        self.elems: list[KrlValue | None] = [None] * size
        #: KRC4 text of each element for whole-array reads (None: not formatted since it
        #: changed); allocated at the first whole-array read.
        self.elem_text: list[str | None] | None = None

    @property
    def is_array(self) -> bool:
        return bool(self.dims) and not self.text_len

    def slot(self, path: VarPath) -> int:
        """The flat index ``path`` addresses; raises Refused for a form that does not fit."""
        if self.text_len:
            if path.index == () or (path.index is not None and len(path.index) == 1):
                return 0
            raise Refused("a CHAR array is addressed as NAME[] or NAME[i]")
        if not self.dims:
            if path.index is not None:
                raise Refused("not an array")
            return 0
        if not path.index:
            raise Refused("an array needs an index NAME[i]")
        if len(path.index) != len(self.dims):
            raise Refused(f"needs {len(self.dims)} indices")
        flat = 0
        for i, size in zip(path.index, self.dims, strict=True):
            if not 1 <= i <= size:
                raise Refused(f"index {i} out of bounds 1..{size}")
            flat = flat * size + i - 1
        return flat

    def chain(self, registry: TypeRegistry, members: tuple[str, ...]) -> list[tuple[TypeSpec, str]]:
        """(spec, type name) of an element and of each member on ``members``, outermost first."""
        if self.spec.kind is Kind.STR:  # a CHAR array is text; a single CHAR is one character
            elem_type = f"CHAR[{self.text_len or 1}]"
        else:
            elem_type = self.type_name
        return member_specs(registry, self.spec, elem_type, members)

    def put_char(self, i: int, char: KrlValue) -> str:
        """The text of a CHAR array with character ``i`` (1-based) replaced by ``char``."""
        if not 1 <= i <= self.text_len:
            raise Refused(f"index {i} out of bounds 1..{self.text_len}")
        if not isinstance(char, str) or len(char) != 1:
            raise Refused("a CHAR element takes exactly one character")
        old = self.elems[0]
        # Characters before i that were never set become blanks (KRL leaves them undefined).
        text = (old if isinstance(old, str) else "").ljust(i - 1)
        return text[: i - 1] + char + text[i:]
