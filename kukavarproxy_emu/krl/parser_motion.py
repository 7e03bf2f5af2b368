"""KRL motion statements: ``PTP``/``LIN``/``CIRC`` (and ``_REL``) plus KUKA's inline form.

Split from the statement parser to keep each module readable; the grammar is

    PTP|PTP_REL|LIN|LIN_REL target [C_PTP|C_DIS|C_VEL|C_ORI] [#TOOL|#BASE]
    CIRC|CIRC_REL aux, target [approximation]
    PTP|LIN target [CONT] Vel = v (% | m/s) [DATASET] [Tool[n][:NAME]] [Base[n][:NAME]]
"""

from __future__ import annotations

from . import ast
from .parser_expr import ExprParser

__all__ = ["MOTIONS", "MotionParser"]

MOTIONS = frozenset({"PTP", "PTP_REL", "LIN", "LIN_REL", "CIRC", "CIRC_REL"})
_APPROX = frozenset({"C_PTP", "C_DIS", "C_VEL", "C_ORI"})


class MotionParser(ExprParser):
    """Motion statements; the statement parser dispatches here on a motion keyword."""

    def motion(self) -> ast.Motion | ast.InlineMotion:
        start = self.advance()
        where = {"line": start.line, "column": start.column}
        kind = start.value
        first = self.expression()
        if self.is_word("CONT", "VEL"):
            if kind not in ("PTP", "LIN"):
                raise self.error(f"the inline form is supported for PTP and LIN, not {kind}")
            return self.inline_motion(kind, first, where)
        aux = None
        target = first
        if kind.startswith("CIRC"):
            self.expect_op(",", "',' between the CIRC auxiliary point and the target")
            aux, target = first, self.expression()
        approx: str | None = None
        frame: str | None = None
        while self.tok.kind not in ("NEWLINE", "EOF"):
            token = self.tok
            if token.kind == "NAME" and token.value in _APPROX and approx is None:
                approx = token.value
            elif token.kind == "ENUM" and token.value in ("TOOL", "BASE") and frame is None:
                if not kind.endswith("_REL"):
                    raise self.error(f"#{token.value} is only allowed with relative motions")
                frame = token.value
            else:
                raise self.error(f"unexpected {self.describe(token)} after the motion target "
                                 "(expected C_PTP, C_DIS, C_VEL, C_ORI, #TOOL or #BASE)")  # fmt: skip
            self.advance()
        return ast.Motion(kind, target, aux, approx, frame, **where)

    def inline_motion(self, kind: str, target: ast.Expr, where: dict[str, int]) -> ast.InlineMotion:
        """``PTP P1 [CONT] Vel = 100 % [PDAT1] [Tool[1]] [Base[0]]`` (KUKA inline form)."""
        cont = False
        if self.is_word("CONT"):
            cont = True
            self.advance()
        self.expect_word("VEL")
        self.expect_op("=", "'=' after Vel")
        velocity = self.primary()
        if self.accept_op("%"):
            unit = "%"
        elif self.is_word("M") and self.peek().value == "/" and self.peek(2).value == "S":
            self.pos += 3
            unit = "M/S"
        else:
            raise self.error(f"expected '%' or 'm/s' after the velocity, found "
                             f"{self.describe(self.tok)}")  # fmt: skip
        if (unit == "%") != (kind == "PTP"):
            raise self.error(f"{kind} velocity must be given in {'%' if kind == 'PTP' else 'm/s'}")
        dataset = None
        if self.tok.kind == "NAME" and self.tok.value not in ("TOOL", "BASE"):
            dataset = self.advance().value
        numbers: dict[str, int | None] = {"TOOL": None, "BASE": None}
        while self.is_word("TOOL", "BASE"):
            word = self.advance().value
            self.expect_op("[")
            number = self.tok
            if number.kind != "INT":
                raise self.error(f"expected the {word.title()} number")
            self.advance()
            self.expect_op("]")
            if self.accept_op(":"):  # "Tool[1]:GRIPPER": the KCP shows the frame's name
                self.expect_name(f"the {word.title()} name")
            numbers[word] = int(number.value)
        return ast.InlineMotion(kind, target, cont, velocity, unit, dataset,
                                numbers["TOOL"], numbers["BASE"], **where)  # fmt: skip
