"""The one KRL value parser: controller text (or a literal we wrote) to a typed Python value.

It accepts everything real controllers print — KRC4 9-digit and KRC2 7-digit REALs, trailing
zeros, exponents, missing struct members, nested and user structs, any spacing and case — and
rejects anything else with :class:`~pyopenshowvar.errors.KrlValueError` naming the position.

Design: one compiled regex splits the text into tokens in a single ``findall`` (possessive
quantifiers, so no backtracking blow-up on hostile input), then a small recursive-descent
parser walks the token list, carrying the expected :class:`~.typedefs.TypeSpec` down so that
every value is typed in a single pass. Token positions are only computed for error messages.
Parsing an E6POS takes about 50 µs.
"""

from __future__ import annotations

import math
import re

from ..errors import KrlValueError
from .poses import TYPED_STRUCTS
from .typedefs import BUILTIN_TYPES, Kind, TypeRegistry, TypeSpec
from .types import KrlEnum, KrlValue, Struct

__all__ = ["parse_array", "parse_number_list", "parse_number_struct", "parse_value"]

# One scan over the whole text. Group 1 is a good token, group 2 a run of anything else (an
# error). Every quantifier that could backtrack is possessive/atomic and the error run eats up
# to the next separator, so scanning stays linear even on hostile input.
_TOKEN = re.compile(
    r"""[ \t\r\n\f\v]*+(?:(
      (?>[+-]?(?:[0-9]++(?:\.[0-9]*+)?|\.[0-9]++)(?:[eE][+-]?[0-9]++)?)(?![A-Za-z0-9_$.])
    | [A-Za-z_$][A-Za-z0-9_$]*+
    | \#[A-Za-z_$][A-Za-z0-9_$]*+
    | "[^"]*+"
    | [{}:,]
    | '[BbHh][0-9A-Fa-f]++'
    )|([^ \t\r\n\f\v{}:,]++|[^ \t\r\n\f\v]))""",
    re.VERBOSE | re.ASCII,
)
_SPACE = " \t\r\n\f\v"
# The fast paths' shapes (see parse_number_list): the scanner's number token, names, blanks.
_NUM_RE = r"[+-]?+(?:[0-9]++(?:\.[0-9]*+)?+|\.[0-9]++)(?:[eE][+-]?+[0-9]++)?+"
_NAME_RE = r"[A-Za-z_$][A-Za-z0-9_$]*+"
_NUMBER_LIST = re.compile(rf"[ \t]*+{_NUM_RE}(?:[ \t]++{_NUM_RE})*+[ \t]*+", re.ASCII)
_NUMBER_STRUCT = re.compile(
    rf"\{{[ \t]*+(?:{_NAME_RE}[ \t]*+:[ \t]*+)?+{_NAME_RE}[ \t]++{_NUM_RE}"
    rf"(?:[ \t]*+,[ \t]*+{_NAME_RE}[ \t]++{_NUM_RE})*+[ \t]*+\}}",
    re.ASCII,
)
_MAX_DEPTH = 32  # KRL nests structs a few levels deep; the limit keeps recursion bounded
_INT_MIN, _INT_MAX = -(2**31), 2**31 - 1
_EXPECTED = {
    Kind.INT: "an INT",
    Kind.REAL: "a REAL",
    Kind.BOOL: "a BOOL (TRUE/FALSE)",
    Kind.STR: 'a CHAR text "..."',
    Kind.ENUM: "an ENUM value #NAME",
    Kind.STRUCT: "a struct {...}",
}
# a token's kind follows from its first character (the scanner guarantees the rest)
_NUM, _NAME, _ENUM, _STR, _PUNCT, _BITS, _END = range(7)
_KIND = {c: _NUM for c in "0123456789+-."}
_KIND.update({c: _NAME for c in "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz_$"})
_KIND.update({"#": _ENUM, '"': _STR, "{": _PUNCT, "}": _PUNCT, ":": _PUNCT, ",": _PUNCT})
_KIND["'"] = _BITS


def _shorten(text: str) -> str:
    return repr(text if len(text) <= 200 else text[:200] + "...")


def _positions(text: str) -> list[int]:
    """Start offsets of the tokens; computed only when an error message needs one."""
    return [m.start(1) if m.group(1) else m.start(2) for m in _TOKEN.finditer(text.rstrip(_SPACE))]


def _tokenize(text: str) -> list[str]:
    # trailing whitespace would make the scanner retry at every blank; strip it first
    pairs = _TOKEN.findall(text.rstrip(_SPACE))
    tokens = [good for good, _ in pairs]
    if "" in tokens:
        k = tokens.index("")
        raise KrlValueError(
            f"invalid KRL value {_shorten(text)}: unexpected {pairs[k][1][:20]!r} "
            f"at {_positions(text)[k]}"
        )
    return tokens


class _Parser:
    __slots__ = ("i", "n", "reg", "text", "toks")

    def __init__(self, text: str, registry: TypeRegistry) -> None:
        self.text = text
        self.reg = registry
        self.toks = _tokenize(text)
        self.n = len(self.toks)
        self.i = 0

    # --- helpers -----------------------------------------------------------------------------
    def peek(self) -> str:
        """The next token, or "" at the end (no real token is empty)."""
        return self.toks[self.i] if self.i < self.n else ""

    def at_end(self) -> bool:
        return self.i >= self.n

    def fail(self, what: str, index: int | None = None) -> KrlValueError:
        k = self.i if index is None else index
        if k >= self.n:
            got, pos = "end of text", len(self.text)
        else:
            got, pos = repr(self.toks[k]), _positions(self.text)[k]
        return KrlValueError(f"invalid KRL value {_shorten(self.text)}: {what}, got {got} at {pos}")

    # --- values ------------------------------------------------------------------------------
    def value(self, spec: TypeSpec | None, depth: int = 0) -> KrlValue:
        if spec is not None and spec.kind is Kind.ARRAY:
            return self.sequence(spec.elem, depth, stop=(",", "}"))
        tok = self.peek()
        if tok == "{":
            return self.struct(spec, depth)
        kind = _KIND[tok[0]] if tok else _END
        if kind == _END or kind == _PUNCT:
            raise self.fail(f"expected {_EXPECTED[spec.kind] if spec is not None else 'a value'}")
        self.i += 1
        if spec is None:
            return self.infer(tok, kind)
        return self.scalar(tok, kind, spec)

    def infer(self, tok: str, kind: int) -> KrlValue:
        if kind == _NUM:
            return self.number(tok, integral=None)
        if kind == _STR:
            return tok[1:-1]
        if kind == _ENUM:
            return KrlEnum._from_parsed(tok[1:].upper())
        if kind == _BITS:
            return int(tok[2:-1], 2 if tok[1] in "Bb" else 16)
        up = tok.upper()
        if up == "TRUE":
            return True
        if up == "FALSE":
            return False
        raise self.fail("expected a value", self.i - 1)

    def scalar(self, tok: str, kind: int, spec: TypeSpec) -> KrlValue:
        k = spec.kind
        if k is Kind.REAL and kind == _NUM:
            return self.number(tok, integral=False)
        if k is Kind.INT and (kind == _NUM or kind == _BITS):
            v = self.infer(tok, kind) if kind == _BITS else self.number(tok, integral=True)
            assert isinstance(v, int)
            if not _INT_MIN <= v <= _INT_MAX:
                raise self.fail("INT out of the 32-bit range", self.i - 1)
            return v
        if k is Kind.BOOL and kind == _NAME and tok.upper() in ("TRUE", "FALSE"):
            return tok.upper() == "TRUE"
        if k is Kind.STR and kind == _STR:
            return tok[1:-1]
        if k is Kind.ENUM and kind == _ENUM:
            name = tok[1:].upper()
            if spec.enum is not None and name not in spec.enum.values:
                raise self.fail(f"{tok!r} is not a value of ENUM {spec.name}", self.i - 1)
            return KrlEnum._from_parsed(name)
        raise self.fail(f"expected {_EXPECTED[k]}", self.i - 1)

    def number(self, tok: str, integral: bool | None) -> int | float:
        """``integral``: None infer from the literal, True INT wanted, False REAL wanted."""
        is_int_literal = "." not in tok and "e" not in tok and "E" not in tok
        try:
            if is_int_literal and integral is not False:
                return int(tok)
            f = float(tok)
        except ValueError:  # e.g. more digits than int() accepts
            raise self.fail("number too long", self.i - 1) from None
        if not math.isfinite(f):
            raise self.fail("number out of range", self.i - 1)
        if integral:
            # the KRC converts REAL text to INT on writes; accept integral values only
            if f != int(f):
                raise self.fail("expected an INT", self.i - 1)
            return int(f)
        return f

    def sequence(
        self, elem: TypeSpec | None, depth: int, stop: tuple[str, ...] = ()
    ) -> list[KrlValue]:
        items: list[KrlValue] = []
        while self.i < self.n and self.toks[self.i] not in stop:
            items.append(self.value(elem, depth))
        if not items:
            raise self.fail("expected array elements")
        return items

    def struct(self, spec: TypeSpec | None, depth: int) -> Struct:
        if depth >= _MAX_DEPTH:
            raise self.fail("structs nested too deeply")
        if spec is not None and spec.kind is not Kind.STRUCT:
            raise self.fail(f"expected {_EXPECTED[spec.kind]}")
        toks, reg, n = self.toks, self.reg, self.n
        i = self.i + 1  # past "{"
        type_name: str | None = None
        if i + 1 < n and toks[i + 1] == ":" and _KIND[toks[i][0]] == _NAME:
            type_name = toks[i].upper()
            i += 2
        # the declared type wins over the text's (a {FRAME: ...} written into a POS variable
        # is checked against POS); with no declared type the text's type name is looked up
        sdef = spec.struct if spec is not None else (reg.struct(type_name) if type_name else None)
        members: dict[str, KrlValue] = {}
        mspecs = reg.member_specs(sdef) if sdef is not None else None
        if i < n and toks[i] == "}":
            self.i = i + 1
        else:
            while True:
                tok = toks[i] if i < n else ""
                if not tok or _KIND[tok[0]] != _NAME:
                    raise self.fail("expected a member name", i)
                name = tok.upper()
                if name in members:
                    raise self.fail(f"duplicate member {name}", i)
                mspec: TypeSpec | None = None
                if mspecs is not None:
                    mspec = mspecs.get(name)
                    if mspec is None:
                        mtype = sdef.member_type(name) if sdef is not None else None
                        if mtype is None:
                            raise self.fail(f"{sdef.name if sdef else ''} has no member {name}", i)
                        mspec = reg.resolve(mtype)  # raises: the member's type is unknown
                i += 1
                nxt = toks[i] if i < n else ""
                if mspec is not None and mspec.kind is Kind.REAL and nxt and _KIND[nxt[0]] == _NUM:
                    # hot path of every pose read: a REAL member with a number
                    self.i = i + 1
                    members[name] = self.number(nxt, integral=False)
                else:
                    self.i = i
                    members[name] = self.value(mspec, depth + 1)
                i = self.i
                sep = toks[i] if i < n else ""
                if sep == ",":
                    i += 1
                    continue
                if sep == "}":
                    self.i = i + 1
                    break
                raise self.fail("expected ',' or '}'", i)
        final = sdef.name if sdef is not None else type_name
        cls = TYPED_STRUCTS.get(final) if final is not None else None
        if cls is not None and sdef is not None and sdef.member_names == cls.MEMBERS:
            return cls._from_parsed(members)
        return Struct._new(final, members)


def parse_value(
    text: str, type_name: str | None = None, *, registry: TypeRegistry | None = None
) -> KrlValue:
    """Parse KRL value text; with ``type_name`` (``"INT"``, ``"E6POS"``, ``"REAL[]"``, an ENUM
    or user STRUC name, ...) coerce and validate against that type.

    Without a type: ``TRUE``/``FALSE`` → bool, ``#X`` → :class:`KrlEnum`, ``"..."`` → str,
    integer → int, real → float, ``{...}`` → :class:`Struct` (a typed subclass for the pose
    types), several space-separated values → list. Empty text is never a value (KVP returns
    it for unknown variables) and raises :class:`KrlValueError` like any other bad text.
    """
    reg = BUILTIN_TYPES if registry is None else registry
    spec = reg.resolve(type_name) if type_name is not None else None
    p = _Parser(text, reg)
    if p.at_end():
        raise KrlValueError(f"empty text {text!r} is not a KRL value")
    if spec is not None and spec.kind is Kind.ARRAY:
        return p.sequence(spec.elem, 0)
    v = p.value(spec)
    if p.at_end():
        return v
    if spec is not None:
        raise p.fail(f"unexpected text after the {spec.name} value")
    items = [v, *p.sequence(None, 0)]
    return items


def parse_array(
    text: str, elem_type: str | None = None, *, registry: TypeRegistry | None = None
) -> list[KrlValue] | str:
    """Parse the reply to a whole-array read ``NAME[]``: elements separated by spaces (a KRC
    prints a trailing space, KUKAVARPROXY trims it; both are accepted). A CHAR array comes back
    quoted and is returned as its text (str).

    ``elem_type`` is the element type (``"REAL"``; ``"REAL[]"`` is accepted too).
    """
    reg = BUILTIN_TYPES if registry is None else registry
    spec: TypeSpec | None = None
    if elem_type is not None:
        spec = reg.resolve(elem_type)
        if spec.kind is Kind.ARRAY:
            spec = spec.elem
    p = _Parser(text, reg)
    if p.at_end():
        raise KrlValueError(f"empty text {text!r} is not a KRL array")
    if (spec is not None and spec.kind is Kind.STR) or (spec is None and p.toks[0][0] == '"'):
        s = p.value(spec)
        if not p.at_end():
            raise p.fail("unexpected text after the CHAR array text")
        return s if isinstance(s, str) else [s]
    return p.sequence(spec, 0)


# ---------------------------------------------------------------------------------------------
# Fast paths for the two shapes a poller reads hundreds of times a second: a REAL array read
# whole (``$VEL_AXIS_ACT[]``) and a struct of numbers (``$AXIS_ACT``). One regex match checks
# the whole shape in C; anything else (or a number out of range) gets None, and the caller uses
# parse_value, which also explains what is wrong. Ten times cheaper than the general parser on
# these texts (bench/gateway.py's cell reads four of them per robot per poll).


def parse_number_list(text: str) -> list[float] | None:
    """The numbers of a blank-separated list (``"1.5 -2 3.0E-06"``) as floats, or None.

    Where it answers it agrees with ``parse_value`` (each element as a float); None for any
    other text, including a non-finite number, which parse_value refuses.
    """
    if _NUMBER_LIST.fullmatch(text) is None:
        return None
    values = [float(t) for t in text.split()]
    for v in values:
        if v - v != 0.0:  # inf or nan (an exponent or a very long literal overflowed)
            return None
    return values


def parse_number_struct(text: str) -> dict[str, float] | None:
    """The members of a struct of numbers (``"{E6AXIS: A1 1.5, A2 -90.0}"``), or None.

    Member names upper-cased, values as floats; the type name is not checked against a
    declaration (parse_value does that). None for any other text, a duplicate member or a
    non-finite number.
    """
    if _NUMBER_STRUCT.fullmatch(text) is None:
        return None
    # the match proved the shape, so plain splitting is exact: "{" [TYPE ":"] members "}"
    body = text[1:-1]
    pairs = [item.split() for item in body[body.find(":") + 1 :].split(",")]
    members = {name.upper(): float(num) for name, num in pairs}
    if len(members) != len(pairs):
        return None
    for v in members.values():
        if v - v != 0.0:
            return None
    return members
