"""KRL parser: ``.src``/``.sub`` text to a :class:`~kukavarproxy_emu.krl.ast.Module`.

Statements are line-based (one per line, blank/comment lines skipped); expressions come from
:class:`~kukavarproxy_emu.krl.parser_expr.ExprParser` and motions from
:mod:`~kukavarproxy_emu.krl.parser_motion`. Declaration lines (``DECL``, implicit
``INT I``, ``STRUC``, ``ENUM``) are handed, line by line, to the one declaration parser of
:mod:`pyopenshowvar.krl.datfile`, so ``$CONFIG.DAT``, module ``.dat`` files and ``DEF`` bodies
accept exactly the same declaration syntax.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from pyopenshowvar.krl import datfile

from . import ast
from .lexer import KrlSyntaxError, tokenize
from .parser_expr import MAX_NESTING
from .parser_motion import MOTIONS, MotionParser

__all__ = ["KrlSyntaxError", "parse_dat", "parse_src", "read_src"]

_DECL_WORDS = frozenset({"DECL", "GLOBAL", "CONST", "STRUC", "ENUM"})
# Words that end a statement block; which one is legal depends on the enclosing construct.
_BLOCK_END = frozenset(
    {"END", "ENDFCT", "ENDIF", "ELSE", "ENDLOOP", "ENDFOR", "ENDWHILE", "UNTIL", "CASE",
     "DEFAULT", "ENDSWITCH"}
)  # fmt: skip
# Statement keywords: a line starting with one is never an implicit "TYPE NAME" declaration.
_KEYWORDS = MOTIONS | _BLOCK_END | frozenset(
    {"IF", "LOOP", "EXIT", "FOR", "WHILE", "REPEAT", "SWITCH", "WAIT", "HALT", "CONTINUE",
     "INI", "RETURN", "DEF", "DEFFCT", "INTERRUPT", "TRIGGER", "GOTO", "BRAKE", "RESUME",
     "ANIN", "ANOUT", "PULSE", "SIGNAL", "EXT", "EXTFCT"}
)  # fmt: skip
# Statements that open a block of statements (their nesting is limited).
_OPENERS = frozenset({"IF", "LOOP", "FOR", "WHILE", "REPEAT", "SWITCH"})
# Recognised but outside the emulated subset: a clear message beats "unexpected text".
_UNSUPPORTED = frozenset(
    {"INTERRUPT", "TRIGGER", "GOTO", "BRAKE", "RESUME", "ANIN", "ANOUT", "PULSE", "SIGNAL"}
)


class _Parser(MotionParser):
    """Statement and module grammar on top of the expression parser."""

    #: Statement blocks open in the parse in progress (nesting of IF, LOOP, FOR, ...).
    blocks = 0
    #: Called before every statement: a long parse lets other work in (kukavarproxy_emu.slices).
    checkpoint: Callable[[], None] | None = None

    # ------------------------------------------------------------------------ helpers

    def end_of_statement(self) -> None:
        if self.tok.kind not in ("NEWLINE", "EOF"):
            raise self.error(f"unexpected {self.describe(self.tok)} after the statement")
        self.skip_newlines()

    def skip_newlines(self) -> None:
        while self.tok.kind == "NEWLINE":
            self.pos += 1

    def skip_line(self) -> None:
        while self.tok.kind not in ("NEWLINE", "EOF"):
            self.pos += 1
        self.skip_newlines()

    # ------------------------------------------------------------------------ modules

    def module(self) -> ast.Module:
        self.skip_newlines()
        routines: list[ast.Routine] = []
        seen: set[str] = set()
        first = self.tok
        while self.tok.kind != "EOF":
            if self.is_word("EXT", "EXTFCT", "EXTP", "EXTFCTP"):
                self.skip_line()  # declarations of other modules' routines: nothing to run
                continue
            start = self.tok
            routine = self.routine()
            if routine.name in seen:
                raise self.error(f"routine {routine.name} defined twice", start)
            seen.add(routine.name)
            routines.append(routine)
        if not routines:
            raise self.error("expected DEF: the file defines no routine", first)
        return ast.Module(self.filename, tuple(routines), None, line=1, column=1)

    def routine(self) -> ast.Routine:
        start = self.tok
        is_global = False
        if self.is_word("GLOBAL"):
            is_global = True
            self.advance()
        if self.is_word("DEF"):
            self.advance()
            return_type: str | None = None
            closing = "END"
        elif self.is_word("DEFFCT"):
            self.advance()
            return_type = self.expect_name("the function's return type").value
            closing = "ENDFCT"
        else:
            raise self.error(f"expected DEF or DEFFCT, found {self.describe(self.tok)}")
        name = self.expect_name("the routine name")
        params = self.params()
        self.end_of_statement()
        body = self.block(closing)
        if not self.is_word(closing):
            raise self.error(f"expected {closing} to close {name.value}, found "
                             f"{self.describe(self.tok)}")  # fmt: skip
        self.advance()
        self.end_of_statement()
        decls = tuple(s for s in body if isinstance(s, ast.Decl | ast.StrucDef | ast.EnumDef))
        return ast.Routine(
            name.value, params, return_type, is_global, decls, body,
            line=start.line, column=start.column,
        )  # fmt: skip

    def params(self) -> tuple[ast.Param, ...]:
        self.expect_op("(", "'(' after the routine name")
        params: list[ast.Param] = []
        if self.accept_op(")"):
            return ()
        while True:
            name = self.expect_name("a parameter name")
            direction = "OUT"  # KRL passes by reference unless :IN is written
            if self.accept_op(":"):
                word = self.expect_name("IN or OUT")
                if word.value not in ("IN", "OUT"):
                    raise self.error("expected IN or OUT", word)
                direction = word.value
            params.append(ast.Param(name.value, direction, line=name.line, column=name.column))
            if self.accept_op(")"):
                return tuple(params)
            self.expect_op(",", "',' or ')'")

    # ---------------------------------------------------------------------- statements

    def block(self, *closers: str) -> tuple[ast.Stmt, ...]:
        """Statements up to (not including) one of the ``closers`` words or EOF."""
        self.blocks += 1
        try:
            if self.blocks > MAX_NESTING + 1:  # the routine's own body is one level
                raise self.error(f"control structures nested deeper than {MAX_NESTING} levels")
            return self._block_body(closers)
        finally:
            self.blocks -= 1

    def _block_body(self, closers: tuple[str, ...]) -> tuple[ast.Stmt, ...]:
        body: list[ast.Stmt] = []
        while True:
            token = self.tok
            if token.kind == "EOF":
                raise self.error(f"missing {' or '.join(closers)} before the end of file")
            if token.kind == "NAME" and token.value in closers:
                return tuple(body)
            if token.kind == "NAME" and token.value in _BLOCK_END:
                raise self.error(f"{token.value} without a matching opening statement "
                                 f"(expected {' or '.join(closers)})")  # fmt: skip
            if self.checkpoint is not None:
                self.checkpoint()
            body.append(self.statement())

    def statement(self) -> ast.Stmt:
        token = self.tok
        where = {"line": token.line, "column": token.column}
        word = token.value if token.kind == "NAME" else ""
        stmt: ast.Stmt
        if word in _DECL_WORDS or (word and word not in _KEYWORDS and self.peek().kind == "NAME"):
            return self.declaration()
        if word in _UNSUPPORTED:
            raise self.error(f"{word} is not supported by the emulator's KRL subset")
        if word in ("DEF", "DEFFCT"):
            raise self.error(f"{word} inside a routine (missing END?)")
        if word in _OPENERS and self.blocks > MAX_NESTING:
            raise self.error(f"control structures nested deeper than {MAX_NESTING} levels")
        if word in MOTIONS:
            stmt = self.motion()
        elif word == "IF":
            stmt = self.if_statement()
        elif word == "LOOP":
            self.advance()
            self.end_of_statement()
            stmt = ast.Loop(self.block("ENDLOOP"), **where)
            self.close("ENDLOOP")
        elif word == "FOR":
            stmt = self.for_statement()
        elif word == "WHILE":
            self.advance()
            cond = self.expression()
            self.end_of_statement()
            stmt = ast.While(cond, self.block("ENDWHILE"), **where)
            self.close("ENDWHILE")
        elif word == "REPEAT":
            self.advance()
            self.end_of_statement()
            body = self.block("UNTIL")
            self.advance()
            stmt = ast.Repeat(body, self.expression(), **where)
        elif word == "SWITCH":
            stmt = self.switch_statement()
        elif word == "WAIT":
            self.advance()
            if self.is_word("FOR"):
                self.advance()
                stmt = ast.WaitFor(self.expression(), **where)
            elif self.is_word("SEC"):
                self.advance()
                stmt = ast.WaitSec(self.expression(), **where)
            else:
                raise self.error(f"expected FOR or SEC after WAIT, found {self.describe(self.tok)}")
        elif word in ("EXIT", "HALT", "CONTINUE", "INI"):
            self.advance()
            simple: dict[str, type[ast.Exit | ast.Halt | ast.Continue | ast.Ini]] = {
                "EXIT": ast.Exit, "HALT": ast.Halt, "CONTINUE": ast.Continue, "INI": ast.Ini
            }  # fmt: skip
            stmt = simple[word](**where)
        elif word == "RETURN":
            self.advance()
            value = None if self.tok.kind in ("NEWLINE", "EOF") else self.expression()
            stmt = ast.Return(value, **where)
        else:
            stmt = self.assignment_or_call()
        self.end_of_statement()
        return stmt

    def close(self, word: str) -> None:
        """Consume the closing keyword the preceding :meth:`block` stopped at."""
        self.expect_word(word)

    def declaration(self) -> ast.Decl | ast.StrucDef | ast.EnumDef:
        """Hand the whole line to the data-list parser: one declaration syntax everywhere."""
        token = self.tok
        raw = self.lines[token.line - 1]
        try:
            result = datfile.parse_declaration(raw, token.line, token.column, self.filename)
        except datfile.DatSyntaxError as exc:
            raise KrlSyntaxError(exc.reason, filename=self.filename, line=exc.line,
                                 column=exc.column, text=raw) from None  # fmt: skip
        self.skip_line()
        where = {"line": token.line, "column": token.column}
        if result.structs:
            return ast.StrucDef(result.structs[0], **where)
        if result.enums:
            return ast.EnumDef(result.enums[0], **where)
        if not result.declarations:
            raise self.error("expected a declaration", token)
        return ast.Decl(result.declarations, **where)

    def assignment_or_call(self) -> ast.Assign | ast.CallStmt:
        token = self.tok
        if token.kind != "NAME":
            raise self.error(f"expected a statement, found {self.describe(token)}")
        target = self.postfix(self.primary())
        where = {"line": token.line, "column": token.column}
        if isinstance(target, ast.Call):
            if self.is_op("="):
                raise self.error("cannot assign to a function call")
            return ast.CallStmt(target.name, target.args, **where)
        if not isinstance(target, ast.Name | ast.Index | ast.Member):
            raise self.error("expected a variable to assign to", token)
        if not self.is_op("="):
            if isinstance(target, ast.Name) and self.tok.kind in ("NEWLINE", "EOF"):
                raise self.error(f"unknown statement {target.name} (a call needs '()')", token)
            raise self.error(f"expected '=' after the assignment target, found "
                             f"{self.describe(self.tok)}")  # fmt: skip
        self.advance()
        return ast.Assign(target, self.expression(), **where)

    def if_statement(self) -> ast.If:
        start = self.advance()
        cond = self.expression()
        self.expect_word("THEN")
        self.end_of_statement()
        then_body = self.block("ELSE", "ENDIF")
        else_body: tuple[ast.Stmt, ...] = ()
        if self.is_word("ELSE"):
            self.advance()
            self.end_of_statement()
            else_body = self.block("ENDIF")
        self.close("ENDIF")
        return ast.If(cond, then_body, else_body, line=start.line, column=start.column)

    def for_statement(self) -> ast.For:
        start = self.advance()
        var = self.expect_name("the loop counter")
        self.expect_op("=", "'=' after the loop counter")
        first = self.expression()
        self.expect_word("TO")
        last = self.expression()
        step = None
        if self.is_word("STEP"):
            self.advance()
            step = self.expression()
        self.end_of_statement()
        body = self.block("ENDFOR")
        self.close("ENDFOR")
        return ast.For(var.value, first, last, step, body, line=start.line, column=start.column)

    def switch_statement(self) -> ast.Switch:
        start = self.advance()
        selector = self.expression()
        self.end_of_statement()
        cases: list[ast.Case] = []
        default: tuple[ast.Stmt, ...] | None = None
        while not self.is_word("ENDSWITCH"):
            token = self.tok
            if self.is_word("CASE"):
                if default is not None:
                    raise self.error("CASE after DEFAULT")
                self.advance()
                values = [self.expression()]
                while self.accept_op(","):
                    values.append(self.expression())
                self.end_of_statement()
                body = self.block("CASE", "DEFAULT", "ENDSWITCH")
                cases.append(ast.Case(tuple(values), body, line=token.line, column=token.column))
            elif self.is_word("DEFAULT"):
                if default is not None:
                    raise self.error("second DEFAULT in SWITCH")
                self.advance()
                self.end_of_statement()
                default = self.block("CASE", "DEFAULT", "ENDSWITCH")
            else:
                raise self.error(f"expected CASE, DEFAULT or ENDSWITCH, found "
                                 f"{self.describe(token)}")  # fmt: skip
        if not cases:
            raise self.error("SWITCH needs at least one CASE")
        self.advance()
        return ast.Switch(selector, tuple(cases), default, line=start.line, column=start.column)


def parse_src(
    text: str, filename: str = "<src>", *, checkpoint: Callable[[], None] | None = None
) -> ast.Module:
    """Parse a ``.src``/``.sub`` module; raises :class:`KrlSyntaxError` on the first error.
    ``checkpoint`` is called every few hundred tokens and before every statement."""
    parser = _Parser(tokenize(text, filename, checkpoint=checkpoint), text, filename)
    parser.checkpoint = checkpoint
    return parser.module()


def parse_dat(
    text: str, filename: str = "<dat>", *, checkpoint: Callable[[], None] | None = None
) -> datfile.DatFile:
    """Parse a module ``.dat`` data list with the shared :mod:`pyopenshowvar.krl.datfile`
    parser, reporting errors as :class:`KrlSyntaxError` (with the caret) like ``.src`` files."""
    try:
        return datfile.parse_dat(text, filename, checkpoint=checkpoint)
    except datfile.DatSyntaxError as exc:
        raise KrlSyntaxError(exc.reason, filename=filename, line=exc.line, column=exc.column,
                             text=exc.text) from None  # fmt: skip


def read_src(path: str | Path, *, encoding: str = "latin-1") -> ast.Module:
    """Read a ``.src``/``.sub`` file and, if it sits next to one, its ``.dat`` data list.

    KRC files are Windows-1252/latin-1, not UTF-8, hence the default encoding.
    """
    path = Path(path)
    module = parse_src(path.read_text(encoding=encoding), str(path))
    dat_path = path.with_suffix(".dat")
    if not dat_path.exists():
        dat_path = path.with_suffix(".DAT")
    if dat_path.exists() and dat_path != path:
        dat = parse_dat(dat_path.read_text(encoding=encoding), str(dat_path))
        return ast.Module(module.filename, module.routines, dat, line=1, column=1)
    return module
