"""One line of a KRL data list as the data-list parser scans it, and its syntax error.

:class:`Line` walks a line left to right (blanks, names, integers, a value's literal text up to
the next comma or the end) and turns what it does not find into a :class:`DatSyntaxError` that
names file, line and column; :func:`comment_start` finds where a line's comment begins (a
``;`` outside a string). The statements themselves are parsed by :mod:`.datfile`.
"""

from __future__ import annotations

import re

__all__ = ["DatSyntaxError", "Line", "comment_start"]

_IDENT = re.compile(r"[A-Za-z_$][A-Za-z0-9_$]*")
_INT = re.compile(r"[+-]?[0-9]+")


class DatSyntaxError(ValueError):
    """A line of a data list that is not valid declaration syntax.

    The message names file, line and column and quotes the offending text, so the error can be
    shown to the user as is.
    """

    def __init__(self, message: str, *, filename: str, line: int, column: int, text: str) -> None:
        super().__init__(self.format(message, filename, line, column, text))
        self.reason = message
        self.filename = filename
        self.line = line
        self.column = column
        self.text = text

    @staticmethod
    def format(message: str, filename: str, line: int, column: int, text: str) -> str:
        """The message shown to the user; subclasses change only the layout."""
        return f"{filename}:{line}:{column}: {message}: {text.strip()!r}"


class Line:
    """A cursor over one source line; every error it raises points at the current column."""

    def __init__(self, text: str, lineno: int, filename: str, end: int) -> None:
        self.text = text
        self.lineno = lineno
        self.filename = filename
        self.pos = 0
        self.end = end  # where the comment starts: the statement ends there

    def error(self, message: str, pos: int | None = None) -> DatSyntaxError:
        column = (self.pos if pos is None else pos) + 1
        return DatSyntaxError(
            message, filename=self.filename, line=self.lineno, column=column, text=self.text
        )

    def skip_ws(self) -> None:
        while self.pos < self.end and self.text[self.pos] in " \t\f\v\r":
            self.pos += 1

    def mark(self) -> int:
        """The position of the next token (for error columns)."""
        self.skip_ws()
        return self.pos

    def at_end(self) -> bool:
        self.skip_ws()
        return self.pos >= self.end

    def peek(self) -> str:
        self.skip_ws()
        return self.text[self.pos] if self.pos < self.end else ""

    def accept(self, char: str) -> bool:
        if self.peek() == char:
            self.pos += 1
            return True
        return False

    def expect(self, char: str, what: str) -> None:
        if not self.accept(char):
            raise self.error(f"expected {what}")

    def ident(self, what: str = "a name") -> str:
        self.skip_ws()
        match = _IDENT.match(self.text, self.pos, self.end)
        if match is None:
            raise self.error(f"expected {what}")
        self.pos = match.end()
        return match.group().upper()

    def peek_ident(self) -> str | None:
        self.skip_ws()
        match = _IDENT.match(self.text, self.pos, self.end)
        return match.group().upper() if match else None

    def integer(self, what: str) -> int:
        self.skip_ws()
        match = _INT.match(self.text, self.pos, self.end)
        if match is None:
            raise self.error(f"expected {what}")
        if len(match.group()) > 18:  # int() refuses > 4300 digits; no KRL number is that long
            raise self.error(f"{what} is too large")
        self.pos = match.end()
        return int(match.group())

    def value_text(self, *, stop_at_comma: bool) -> str:
        """Literal text up to a top-level comma (or the end), skipping nested braces and strings."""
        self.skip_ws()
        start, depth, pos = self.pos, 0, self.pos
        while pos < self.end:
            char = self.text[pos]
            if char == '"':
                close = self.text.find('"', pos + 1, self.end)
                if close < 0:
                    raise self.error("unterminated string", pos)
                pos = close
            elif char == "{":
                depth += 1
            elif char == "}":
                depth -= 1
                if depth < 0:
                    raise self.error("unbalanced '}'", pos)
            elif char == "," and depth == 0 and stop_at_comma:
                break
            pos += 1
        if depth:
            raise self.error("unbalanced '{'", start)
        self.pos = pos
        text = self.text[start:pos].strip()
        if not text:
            raise self.error("expected a value after '='")
        return text


def comment_start(text: str) -> int:
    """Index of the ``;`` that starts the comment, ignoring ``;`` inside string literals."""
    in_string = False
    for index, char in enumerate(text):
        if char == '"':
            in_string = not in_string
        elif char == ";" and not in_string:
            return index
    return len(text)
