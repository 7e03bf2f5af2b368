"""Parser for KRL data lists (``$CONFIG.DAT`` and module ``.DAT`` files).

This is the one place that understands KRL declaration syntax: the emulator's variable store
loads its globals with it, its KRL interpreter reads module data lists with it, and the apps
list the names a ``$CONFIG.DAT`` declares (``kvp --config``). It is
purely syntactic: initial values stay KRL literal text (``={A1 0.0, A2 -90.0}``, ``=#T1``,
``="text"``) and are handed to :func:`pyopenshowvar.krl.parse_value` by whoever knows the types,
so this module does not depend on the type registry at all.

Accepted lines (keywords are case-insensitive, names are returned upper-case because KRL names
are case-insensitive)::

    &ACCESS RVP                          header lines: ignored
    DEFDAT $CONFIG PUBLIC                optional wrapper ... ENDDAT
    ;FOLD USER GLOBALS ... ;ENDFOLD      comments and folds: ignored
    EXT BAS(BAS_COMMAND:IN, REAL:IN)     EXT/EXTFCT/EXTP/EXTFCTP: ignored
    DECL GLOBAL E6AXIS HOME={A1 0.0, ...}
    DECL INT A, B=2, C[10]               several names, arrays, initialisers
    INT COUNT=0                          DECL may be omitted
    DECL CONST INT MAXN=10               constants (the store makes them read-only)
    OUTPUT_VARS[3]=TRUE                  element initialisation after the declaration
    NAME[]="hello"                       whole CHAR array initialisation
    GLOBAL STRUC MYTYPE REAL X, Y, INT N, E6AXIS AX
    GLOBAL ENUM COLORS RED, GREEN, BLUE
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from .datline import DatSyntaxError, Line, comment_start

__all__ = [
    "MAX_ELEMENTS",
    "Assignment",
    "DatFile",
    "DatSyntaxError",
    "Declaration",
    "EnumDecl",
    "StrucDecl",
    "parse_dat",
    "parse_declaration",
    "read_dat",
]

#: Elements of one array variable at most (2**18). Bounds the memory and the time one
#: declaration costs (a KRC's data memory holds far less); larger arrays are a syntax error.
MAX_ELEMENTS = 1 << 18

# Statements that declare procedures/functions of other modules: nothing for a data store.
_IGNORED_KEYWORDS = frozenset({"EXT", "EXTFCT", "EXTP", "EXTFCTP", "IMPORT"})
# Words that can never be a variable name in a declaration; catching them gives better errors.
_RESERVED = frozenset(
    {"DECL", "GLOBAL", "CONST", "STRUC", "ENUM", "DEFDAT", "ENDDAT", "PUBLIC", *_IGNORED_KEYWORDS}
)


@dataclass(frozen=True, slots=True)
class Declaration:
    """One declared variable; ``init`` is the literal text after ``=`` (``None``: no value).

    For a CHAR array ``CHAR NAME[20]`` the type is ``"CHAR"`` and ``dims`` is ``(20,)``.
    """

    name: str
    type_name: str
    dims: tuple[int, ...]
    init: str | None
    is_global: bool
    is_const: bool
    line: int
    #: Column (1-based) of the name, for messages (not part of equality).
    column: int = field(default=1, compare=False)


@dataclass(frozen=True, slots=True)
class Assignment:
    """An initialisation line such as ``OUTPUT_VARS[3]=TRUE`` or ``NAME[]="hi"``.

    ``target`` is the normalised left-hand side (upper-case, no blanks), i.e. a name the
    variable store understands.
    """

    target: str
    value: str
    line: int
    #: Column (1-based) where the target starts (not part of equality).
    column: int = field(default=1, compare=False)


@dataclass(frozen=True, slots=True)
class StrucDecl:
    """A user structure type. Member types are KRL type names; text members are ``CHAR[n]``."""

    name: str
    members: tuple[tuple[str, str], ...]
    is_global: bool
    line: int


@dataclass(frozen=True, slots=True)
class EnumDecl:
    """A user enumeration type with its values in declaration order (without ``#``)."""

    name: str
    values: tuple[str, ...]
    is_global: bool
    line: int


@dataclass(frozen=True, slots=True)
class DatFile:
    """Everything a data list declares, in source order within each kind."""

    filename: str
    name: str | None
    public: bool
    declarations: tuple[Declaration, ...]
    assignments: tuple[Assignment, ...]
    structs: tuple[StrucDecl, ...]
    enums: tuple[EnumDecl, ...]


class _Parser:
    def __init__(self, filename: str) -> None:
        self.filename = filename
        self.name: str | None = None
        self.public = False
        self.ended = False
        self.declarations: list[Declaration] = []
        self.assignments: list[Assignment] = []
        self.structs: list[StrucDecl] = []
        self.enums: list[EnumDecl] = []

    def statement(self, line: Line) -> None:
        if self.ended:
            raise line.error("text after ENDDAT")
        start = line.pos
        word = line.ident("a declaration")
        if word == "DEFDAT":
            if self.name is not None or self.declarations or self.assignments:
                raise line.error("DEFDAT must be the first statement", start)
            self.name = line.ident("the data list name")
            if not line.at_end():
                if line.ident("PUBLIC or the end of the line") != "PUBLIC":
                    raise line.error("expected PUBLIC", line.pos)
                self.public = True
        elif word == "ENDDAT":
            self.ended = True
        elif word in _IGNORED_KEYWORDS:
            return
        else:
            self._declaration(line, word, start)
        if not line.at_end():
            raise line.error("unexpected text")

    def _declaration(self, line: Line, word: str, start: int) -> None:
        is_global = is_const = has_decl = False
        # The modifiers may come in either order (KSS accepts "GLOBAL DECL" and "DECL GLOBAL").
        while word in ("GLOBAL", "DECL", "CONST"):
            is_global |= word == "GLOBAL"
            is_const |= word == "CONST"
            has_decl |= word == "DECL"
            word = line.ident("a type name")
        if word == "STRUC":
            self.structs.append(self._struc(line, is_global))
        elif word == "ENUM":
            self.enums.append(self._enum(line, is_global))
        elif has_decl or is_global or is_const or line.peek_ident() is not None:
            # "TYPE NAME" without DECL is an implicit declaration; KRL allows it.
            self._decl_items(line, word, is_global, is_const)
        else:
            self._assignment(line, word, start)

    def _decl_items(self, line: Line, type_name: str, is_global: bool, is_const: bool) -> None:
        if type_name in _RESERVED:
            raise line.error("expected a type name", line.pos - len(type_name))
        while True:
            name_pos = line.mark()
            name = line.ident("a variable name")
            if name in _RESERVED:
                raise line.error("expected a variable name", name_pos)
            dims: tuple[int, ...] = ()
            if line.accept("["):
                dims = self._dims(line)
            init = line.value_text(stop_at_comma=True) if line.accept("=") else None
            self.declarations.append(
                Declaration(
                    name, type_name, dims, init, is_global, is_const, line.lineno, name_pos + 1
                )
            )
            if not line.accept(","):
                return

    def _dims(self, line: Line) -> tuple[int, ...]:
        dims = []
        count = 1
        while True:
            size_pos = line.mark()
            size = line.integer("an array size")
            if size < 1:
                raise line.error("array size must be positive", size_pos)
            count *= size
            if count > MAX_ELEMENTS:
                raise line.error(
                    f"array of {count} elements exceeds the emulator's limit of {MAX_ELEMENTS}",
                    size_pos,
                )
            dims.append(size)
            if line.accept("]"):
                return tuple(dims)
            line.expect(",", "',' or ']'")

    def _assignment(self, line: Line, name: str, start: int) -> None:
        target = name
        if line.accept("["):
            if line.accept("]"):
                target += "[]"
            else:
                indices = [str(line.integer("an index"))]
                while not line.accept("]"):
                    line.expect(",", "',' or ']'")
                    indices.append(str(line.integer("an index")))
                target += "[" + ",".join(indices) + "]"
        while line.accept("."):
            target += "." + line.ident("a member name")
        if not line.accept("="):
            raise line.error("expected a declaration or an assignment", start)
        value = line.value_text(stop_at_comma=False)
        self.assignments.append(Assignment(target, value, line.lineno, start + 1))

    def _struc(self, line: Line, is_global: bool) -> StrucDecl:
        name = line.ident("the structure name")
        members: list[tuple[str, str]] = []
        seen: set[str] = set()
        member_type = line.ident("a member type")
        while True:
            member_pos = line.mark()
            member = line.ident("a member name")
            member_type_here = member_type
            if line.accept("["):
                # Only CHAR arrays (text) are usual in structures.
                dims = self._dims(line)
                if member_type != "CHAR" or len(dims) != 1:
                    raise line.error("only 1-D CHAR arrays are supported as members", member_pos)
                member_type_here = f"CHAR[{dims[0]}]"
            if member in seen:
                raise line.error(f"duplicate member {member}", member_pos)
            seen.add(member)
            members.append((member, member_type_here))
            if line.at_end():
                return StrucDecl(name, tuple(members), is_global, line.lineno)
            line.expect(",", "',' between members")
            # "REAL X, Y, INT N": a second word before the next comma starts a new type.
            save = line.pos
            first = line.ident("a member name")
            if line.peek_ident() is not None:
                member_type = first
            else:
                line.pos = save

    def _enum(self, line: Line, is_global: bool) -> EnumDecl:
        name = line.ident("the enumeration name")
        values: list[str] = []
        while True:
            value_pos = line.mark()
            value = line.ident("an enumeration value")
            if value in values:
                raise line.error(f"duplicate enumeration value {value}", value_pos)
            values.append(value)
            if not line.accept(","):
                return EnumDecl(name, tuple(values), is_global, line.lineno)

    def result(self) -> DatFile:
        return DatFile(
            filename=self.filename,
            name=self.name,
            public=self.public,
            declarations=tuple(self.declarations),
            assignments=tuple(self.assignments),
            structs=tuple(self.structs),
            enums=tuple(self.enums),
        )


def parse_declaration(raw: str, lineno: int, column: int, filename: str = "<src>") -> DatFile:
    """Parse the one declaration (DECL, STRUC, ENUM...) starting at ``column`` (1-based) of a
    source line: the KRL parser hands declaration lines inside a DEF to this same parser."""
    parser = _Parser(filename)
    line = Line(raw, lineno, filename, comment_start(raw))
    line.pos = column - 1
    parser.statement(line)
    return parser.result()


def parse_dat(
    text: str, filename: str = "<dat>", *, checkpoint: Callable[[], None] | None = None
) -> DatFile:
    """Parse the text of a data list; raises :class:`DatSyntaxError` on the first bad line.
    ``checkpoint`` is called before every line (a long parse lets other work in)."""
    parser = _Parser(filename)
    for lineno, raw in enumerate(text.splitlines(), start=1):
        if checkpoint is not None:
            checkpoint()
        stripped = raw.lstrip()
        # "&ACCESS RVP", "&REL 1", "&PARAM ..." are editor metadata, not KRL.
        if not stripped or stripped.startswith("&"):
            continue
        line = Line(raw, lineno, filename, comment_start(raw))
        if line.at_end():
            continue
        parser.statement(line)
    if parser.name is not None and not parser.ended:
        raise DatSyntaxError(
            "missing ENDDAT", filename=filename, line=len(text.splitlines()), column=1, text=""
        )
    return parser.result()


def read_dat(path: str | Path, encoding: str = "latin-1") -> DatFile:
    """Read and parse a data list file; KRC files are Windows-1252/latin-1, not UTF-8."""
    path = Path(path)
    return parse_dat(path.read_text(encoding=encoding), filename=str(path))
