"""KRL lexer: source text to a flat token list, plus the syntax error every stage raises.

KRL is line-oriented (one statement per line), so the lexer keeps line ends as ``NEWLINE``
tokens and drops what the parser never needs: ``;`` comments (which include ``;FOLD`` and
``;ENDFOLD`` markers, so folded code is ordinary code) and ``&`` editor header lines.

The scanner is one compiled alternation matched at the current position; every alternative
consumes at least one character and none nests a quantifier, so scanning is linear in the
input (no backtracking blow-ups on hostile text).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

from pyopenshowvar.krl.datfile import DatSyntaxError

__all__ = ["KrlSyntaxError", "Token", "tokenize"]


class KrlSyntaxError(DatSyntaxError):
    """A KRL syntax error; the message reads ``file:line:column: message`` followed by the
    offending source line and a caret under the column, ready to show to the user.

    A subclass of the data-list parser's error (same fields), so one ``except`` catches a bad
    declaration whichever file it came from."""

    @staticmethod
    def format(message: str, filename: str, line: int, column: int, text: str) -> str:
        source = text.rstrip("\r\n").expandtabs(1)
        caret = " " * max(column - 1, 0) + "^"
        return f"{filename}:{line}:{column}: {message}\n    {source}\n    {caret}"


@dataclass(frozen=True, slots=True)
class Token:
    """One token. ``kind`` is NAME, INT, REAL, BITS, STRING, ENUM, OP, NEWLINE or EOF.

    ``value`` is the normalised text: upper-case for NAME/ENUM/BITS (KRL is case-insensitive),
    the operator for OP, the literal text otherwise (STRING without quotes, ENUM without
    ``#``). ``start``/``end`` are offsets into the whole source, so the parser can slice the
    exact text of an aggregate; ``line``/``column`` are 1-based.
    """

    kind: str
    value: str
    line: int
    column: int
    start: int
    end: int


_SCANNER = re.compile(
    r"""
    (?P<WS>[ \t\f\v\r]+)
  | (?P<COMMENT>;[^\n]*)
  | (?P<NEWLINE>\n)
  | (?P<REAL>(?:[0-9]+\.[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[0-9]+[eE][+-]?[0-9]+)
  | (?P<INT>[0-9]+)
  | (?P<BITS>'[BbHh][0-9A-Fa-f]*')
  | (?P<STRING>"[^"\n]*")
  | (?P<ENUM>\#[A-Za-z_$][A-Za-z0-9_$]*)
  | (?P<NAME>[A-Za-z_$][A-Za-z0-9_$]*)
  | (?P<OP>==|<>|<=|>=|[-+*/:<>=,.()\[\]{}%])
    """,
    re.VERBOSE,
)


def tokenize(
    text: str, filename: str = "<krl>", *, checkpoint: Callable[[], None] | None = None
) -> list[Token]:
    """Split KRL source into tokens; raises :class:`KrlSyntaxError` on a stray character.
    ``checkpoint`` is called every 32 scanner steps (a long scan lets other work in)."""
    tokens: list[Token] = []
    steps = 0
    lines = text.split("\n")
    pos, line, line_start, size = 0, 1, 0, len(text)
    at_line_start = True
    while pos < size:
        if at_line_start:
            at_line_start = False
            # "&ACCESS RVP", "&REL 1", "&PARAM ..." are editor metadata, not KRL.
            first = pos
            while first < size and text[first] in " \t":
                first += 1
            if first < size and text[first] == "&":
                newline = text.find("\n", first)
                pos = size if newline < 0 else newline
                continue
        steps += 1
        if checkpoint is not None and not steps & 31:
            checkpoint()
        match = _SCANNER.match(text, pos)
        column = pos - line_start + 1
        if match is None:
            char = text[pos]
            if char == '"':
                message = "unterminated string (strings end on the same line)"
            elif char == "'":
                message = "bad bit literal (expected 'B0101' or 'H1F')"
            else:
                message = f"unexpected character {char!r}"
            raise KrlSyntaxError(
                message, filename=filename, line=line, column=column, text=lines[line - 1]
            )
        kind = match.lastgroup or ""
        end = match.end()
        raw = match.group()
        if kind == "NEWLINE":
            tokens.append(Token(kind, "\n", line, column, pos, end))
            line += 1
            line_start = end
            at_line_start = True
        elif kind not in ("WS", "COMMENT"):
            if kind == "STRING":
                value = raw[1:-1]
            elif kind == "ENUM":
                value = raw[1:].upper()
            elif kind in ("NAME", "BITS"):
                value = raw.upper()
            else:
                value = raw
            tokens.append(Token(kind, value, line, column, pos, end))
        pos = end
    tokens.append(Token("NEWLINE", "\n", line, pos - line_start + 1, size, size))
    tokens.append(Token("EOF", "", line, pos - line_start + 1, size, size))
    return tokens
