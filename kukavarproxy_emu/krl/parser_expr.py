"""KRL expression parsing: the token cursor and precedence climbing shared by the parser.

Operator priority follows the KUKA System Software manual ("Priority of operators"), which
is *not* the C order: comparisons bind loosest, below ``OR``. So ``A > 1 AND B < 2`` means
``A > (1 AND B) < 2`` on a real KRC, and KRL code brackets its comparisons
(``(A > 1) AND (B < 2)``). The emulator reproduces that so programs behave as on the robot.

    1  NOT  B_NOT  unary - +          (prefix, binds tightest)
       :                               geometric operator (frame composition)
    2  *  /
    3  +  -
    4  AND  B_AND
    5  EXOR  B_EXOR
    6  OR  B_OR
    7  ==  <>  <  <=  >  >=            (loosest)

All binary operators associate to the left.

Nesting is limited to ``MAX_NESTING`` levels (parentheses, signs, aggregates, and the depth of
the finished expression tree, which a long chain of operators also deepens): the parser and the
executor walk expressions recursively, and a syntax error at the offending token is better
than running out of stack.
"""

from __future__ import annotations

from . import ast
from .lexer import KrlSyntaxError, Token

__all__ = ["BINARY_PRIORITY", "MAX_NESTING", "ExprParser"]

#: Deepest expression (and, in the statement parser, block) nesting accepted.
MAX_NESTING = 64

# Binding power of every binary operator: larger binds tighter (see the module docstring).
BINARY_PRIORITY: dict[str, int] = {
    ":": 8,
    "*": 7,
    "/": 7,
    "+": 6,
    "-": 6,
    "AND": 5,
    "B_AND": 5,
    "EXOR": 4,
    "B_EXOR": 4,
    "OR": 3,
    "B_OR": 3,
    "==": 2,
    "<>": 2,
    "<": 2,
    "<=": 2,
    ">": 2,
    ">=": 2,
}
_WORD_OPERATORS = frozenset(op for op in BINARY_PRIORITY if op.isalpha() or "_" in op)
_UNARY_WORDS = frozenset({"NOT", "B_NOT"})


class ExprParser:
    """A cursor over the token list with the expression grammar on top of it."""

    def __init__(self, tokens: list[Token], text: str, filename: str) -> None:
        self.tokens = tokens
        self.text = text
        self.lines = text.split("\n")
        self.filename = filename
        self.pos = 0
        self.depth = 0  # expression nesting of the parse in progress

    # ------------------------------------------------------------------ cursor helpers

    @property
    def tok(self) -> Token:
        """The current token."""
        return self.tokens[self.pos]

    def peek(self, ahead: int = 1) -> Token:
        """The token ``ahead`` positions after the current one (EOF past the end)."""
        return self.tokens[min(self.pos + ahead, len(self.tokens) - 1)]

    def advance(self) -> Token:
        token = self.tokens[self.pos]
        if token.kind != "EOF":
            self.pos += 1
        return token

    def error(self, message: str, token: Token | None = None) -> KrlSyntaxError:
        """A syntax error pointing at ``token`` (default: the current token)."""
        token = self.tok if token is None else token
        text = self.lines[token.line - 1] if token.line <= len(self.lines) else ""
        return KrlSyntaxError(
            message, filename=self.filename, line=token.line, column=token.column, text=text
        )

    def describe(self, token: Token) -> str:
        """How a token reads in an error message."""
        if token.kind == "NEWLINE":
            return "end of line"
        if token.kind == "EOF":
            return "end of file"
        return repr(self.text[token.start : token.end])

    def is_op(self, value: str) -> bool:
        return self.tok.kind == "OP" and self.tok.value == value

    def is_word(self, *words: str) -> bool:
        return self.tok.kind == "NAME" and self.tok.value in words

    def accept_op(self, value: str) -> bool:
        if self.is_op(value):
            self.pos += 1
            return True
        return False

    def expect_op(self, value: str, what: str | None = None) -> Token:
        if not self.is_op(value):
            wanted = what or f"'{value}'"
            raise self.error(f"expected {wanted}, found {self.describe(self.tok)}")
        return self.advance()

    def expect_word(self, word: str) -> Token:
        if not self.is_word(word):
            raise self.error(f"expected {word}, found {self.describe(self.tok)}")
        return self.advance()

    def expect_name(self, what: str) -> Token:
        if self.tok.kind != "NAME":
            raise self.error(f"expected {what}, found {self.describe(self.tok)}")
        return self.advance()

    # --------------------------------------------------------------------- expressions

    def expression(self) -> ast.Expr:
        """Parse a full expression (precedence climbing over :data:`BINARY_PRIORITY`)."""
        start = self.tok
        expr = self._binary(0)
        if self.depth == 0 and _deeper_than(expr, MAX_NESTING):
            raise self.error(f"expression nested deeper than {MAX_NESTING} levels", start)
        return expr

    def _enter(self, token: Token) -> None:
        self.depth += 1
        if self.depth > MAX_NESTING:
            raise self.error(f"expression nested deeper than {MAX_NESTING} levels", token)

    def _binary_op(self) -> str | None:
        token = self.tok
        if token.kind == "OP" and token.value in BINARY_PRIORITY:
            return token.value
        if token.kind == "NAME" and token.value in _WORD_OPERATORS:
            return token.value
        return None

    def _binary(self, min_priority: int) -> ast.Expr:
        left = self._unary()
        while True:
            op = self._binary_op()
            if op is None or BINARY_PRIORITY[op] <= min_priority:
                if self.is_op("="):
                    raise self.error("'=' is assignment; compare with '=='")
                return left
            op_token = self.advance()
            right = self._binary(BINARY_PRIORITY[op])
            left = ast.Binary(op, left, right, line=op_token.line, column=op_token.column)

    def _unary(self) -> ast.Expr:
        token = self.tok
        self._enter(token)
        try:
            if (token.kind == "OP" and token.value in "-+") or (
                token.kind == "NAME" and token.value in _UNARY_WORDS
            ):
                self.advance()
                operand = self._unary()
                return ast.Unary(token.value, operand, line=token.line, column=token.column)
            return self.postfix(self.primary())
        finally:
            self.depth -= 1

    def primary(self) -> ast.Expr:
        """A literal, aggregate, name, call or parenthesised expression."""
        token = self.tok
        where = {"line": token.line, "column": token.column}
        kind = token.kind
        if kind == "INT":
            self.advance()
            return ast.IntLit(int(token.value), **where)
        if kind == "REAL":
            self.advance()
            return ast.RealLit(float(token.value), **where)
        if kind == "BITS":
            self.advance()
            digits = token.value[2:-1]
            if not digits:
                raise self.error("empty bit literal", token)
            try:
                value = int(digits, 2 if token.value[1] == "B" else 16)
            except ValueError:  # the lexer accepts hex digits for both forms
                raise self.error(f"bad bit literal {token.value}", token) from None
            return ast.IntLit(value, **where)
        if kind == "STRING":
            self.advance()
            return ast.StrLit(token.value, **where)
        if kind == "ENUM":
            self.advance()
            return ast.EnumLit(token.value, **where)
        if kind == "OP" and token.value == "(":
            self.advance()
            inner = self.expression()
            self.expect_op(")", "')'")
            return inner
        if kind == "OP" and token.value == "{":
            return self.aggregate()
        if kind == "NAME":
            if token.value in ("TRUE", "FALSE"):
                self.advance()
                return ast.BoolLit(token.value == "TRUE", **where)
            self.advance()
            if self.is_op("("):
                return ast.Call(token.value, self.arguments(), **where)
            return ast.Name(token.value, **where)
        raise self.error(f"expected an expression, found {self.describe(token)}")

    def arguments(self) -> tuple[ast.Expr, ...]:
        """``( [expr {, expr}] )`` starting at the ``(``."""
        self.expect_op("(")
        args: list[ast.Expr] = []
        if not self.accept_op(")"):
            args.append(self.expression())
            while not self.accept_op(")"):
                self.expect_op(",", "',' or ')'")
                args.append(self.expression())
        return tuple(args)

    def postfix(self, base: ast.Expr) -> ast.Expr:
        """Array indices ``[i, j]`` and members ``.NAME`` after a primary."""
        while True:
            token = self.tok
            if self.accept_op("["):
                if self.accept_op("]"):  # NAME[]: the whole (CHAR) array, as in NAME[]="text"
                    base = ast.Index(base, (), line=token.line, column=token.column)
                    continue
                indices = [self.expression()]
                while not self.accept_op("]"):
                    self.expect_op(",", "',' or ']'")
                    indices.append(self.expression())
                base = ast.Index(base, tuple(indices), line=token.line, column=token.column)
            elif self.accept_op("."):
                member = self.expect_name("a member name")
                base = ast.Member(base, member.value, line=member.line, column=member.column)
            else:
                return base

    def aggregate(self) -> ast.Aggregate:
        """``{[TYPE:] NAME value, ...}``; member values are constants, as in real KRL."""
        open_token = self.expect_op("{")
        type_name: str | None = None
        if self.tok.kind == "NAME" and self.peek().kind == "OP" and self.peek().value == ":":
            type_name = self.advance().value
            self.advance()
        items: list[ast.AggregateItem] = []
        if not self.is_op("}"):
            while True:
                name = self.expect_name("a member name")
                value = self._constant()
                items.append(
                    ast.AggregateItem(name.value, value, line=name.line, column=name.column)
                )
                if self.is_op("}"):
                    break
                self.expect_op(",", "',' or '}'")
        close = self.advance()
        text = self.text[open_token.start : close.end]
        return ast.Aggregate(
            type_name, tuple(items), text, line=open_token.line, column=open_token.column
        )

    def _constant(self) -> ast.Expr:
        token = self.tok
        self._enter(token)
        try:
            return self._constant_inner(token)
        finally:
            self.depth -= 1

    def _constant_inner(self, token: Token) -> ast.Expr:
        if token.kind == "OP" and token.value in "-+":
            self.advance()
            operand = self._constant()
            if not isinstance(operand, ast.IntLit | ast.RealLit):
                raise self.error("a sign must be followed by a number", token)
            return ast.Unary(token.value, operand, line=token.line, column=token.column)
        if token.kind in ("INT", "REAL", "BITS", "STRING", "ENUM") or self.is_op("{"):
            return self.primary()
        if token.kind == "NAME" and token.value in ("TRUE", "FALSE"):
            return self.primary()
        raise self.error(
            f"aggregate members must be constants, found {self.describe(token)}", token
        )


def _deeper_than(expr: ast.Expr, limit: int) -> bool:
    """Whether the expression tree is more than ``limit`` levels deep (no recursion here)."""
    stack: list[tuple[ast.Expr, int]] = [(expr, 1)]
    while stack:
        node, depth = stack.pop()
        if depth > limit:
            return True
        children: tuple[ast.Expr, ...] = ()
        if isinstance(node, ast.Binary):
            children = (node.left, node.right)
        elif isinstance(node, ast.Unary):
            children = (node.operand,)
        elif isinstance(node, ast.Index):
            children = (node.base, *node.indices)
        elif isinstance(node, ast.Member):
            children = (node.base,)
        elif isinstance(node, ast.Call):
            children = node.args
        elif isinstance(node, ast.Aggregate):
            children = tuple(item.value for item in node.items)
        stack.extend((child, depth + 1) for child in children)
    return False
