"""KRL syntax errors: every error path names file:line:column, quotes the line, shows a caret."""

from __future__ import annotations

import pytest

from kukavarproxy_emu.krl import KrlSyntaxError, parse_dat, parse_src


def wrap(*lines: str) -> str:
    """A routine around ``lines`` (which therefore start on line 2)."""
    return "DEF T()\n" + "".join(f"{line}\n" for line in lines) + "END\n"


CASES = [
    # lexer
    (wrap('  X = "open'), 2, 7, "unterminated string"),
    (wrap("  X = 'B1G'"), 2, 7, "bad bit literal"),
    (wrap("  X = 1 ? 2"), 2, 9, "unexpected character '?'"),
    (wrap("  X = 'B'"), 2, 7, "empty bit literal"),
    (wrap("  X = 'B102'"), 2, 7, "bad bit literal 'B102'"),
    (wrap("  X = A.B.1"), 2, 10, "unexpected '.1' after the statement"),
    # expressions
    (wrap("  IF A = 1 THEN", "  ENDIF"), 2, 8, "'=' is assignment; compare with '=='"),
    (wrap("  X = (1 + 2"), 2, 13, "expected ')'"),
    (wrap("  X = 1 +"), 2, 10, "expected an expression, found end of line"),
    (wrap("  X = SIN(1 2)"), 2, 13, "expected ',' or ')'"),
    (wrap("  X = A[1 2]"), 2, 11, "expected ',' or ']'"),
    (wrap("  X = A.1"), 2, 8, "unexpected '.1' after the statement"),
    (wrap("  X = {1}"), 2, 8, "expected a member name"),
    (wrap("  X = {A1 1 A2 2}"), 2, 13, "expected ',' or '}'"),
    (wrap("  X = {A1 Y}"), 2, 11, "aggregate members must be constants, found 'Y'"),
    (wrap("  X = {A1 -#E}"), 2, 11, "a sign must be followed by a number"),
    # statements
    (wrap("  X = 1 2"), 2, 9, "unexpected '2' after the statement"),
    (wrap("  5 = X"), 2, 3, "expected a statement, found '5'"),
    (wrap("  TRUE = X"), 2, 3, "expected a variable to assign to"),
    (wrap("  SIN(1) = X"), 2, 10, "cannot assign to a function call"),
    (wrap("  MYPROC"), 2, 3, "unknown statement MYPROC (a call needs '()')"),
    (wrap("  X + 1"), 2, 5, "expected '=' after the assignment target"),
    (wrap("  IF A", "  ENDIF"), 2, 7, "expected THEN"),
    (wrap("  FOR I 1 TO 3", "  ENDFOR"), 2, 9, "expected '=' after the loop counter"),
    (wrap("  FOR I = 1 UNTIL 3", "  ENDFOR"), 2, 13, "expected TO"),
    (wrap("  LOOP", "  ENDFOR"), 3, 3, "ENDFOR without a matching opening statement"),
    (wrap("  ENDIF"), 2, 3, "ENDIF without a matching opening statement (expected END)"),
    ("DEF T()\n  LOOP\n", 3, 1, "missing ENDLOOP before the end of file"),
    (wrap("  WAIT 3"), 2, 8, "expected FOR or SEC after WAIT"),
    (wrap("  INTERRUPT DECL 3 WHEN $IN[1] DO STOPIT()"), 2, 3, "INTERRUPT is not supported"),
    (wrap("  TRIGGER WHEN DISTANCE=0 DELAY=0 DO $OUT[1]=TRUE"), 2, 3, "TRIGGER is not supported"),
    (wrap("  DEF INNER()"), 2, 3, "DEF inside a routine (missing END?)"),
    (wrap("  DECL INT"), 2, 11, "expected a variable name"),
    (wrap("  DECL INT A[0]"), 2, 14, "array size must be positive"),
    # SWITCH
    (wrap("  SWITCH X", "  ENDSWITCH"), 3, 3, "SWITCH needs at least one CASE"),
    (wrap("  SWITCH X", "  X = 1", "  ENDSWITCH"), 3, 3, "expected CASE, DEFAULT or ENDSWITCH"),
    (wrap("  SWITCH X", "  DEFAULT", "  CASE 1", "  ENDSWITCH"), 4, 3, "CASE after DEFAULT"),
    (
        wrap("  SWITCH X", "  CASE 1", "  DEFAULT", "  DEFAULT", "  ENDSWITCH"),
        5,
        3,
        "second DEFAULT",
    ),
    # motions
    (wrap("  PTP P1 C_LIN"), 2, 10, "unexpected 'C_LIN' after the motion target"),
    (wrap("  PTP P1 C_PTP C_PTP"), 2, 16, "unexpected 'C_PTP' after the motion target"),
    (wrap("  LIN P1 #TOOL"), 2, 10, "#TOOL is only allowed with relative motions"),
    (wrap("  CIRC P1 P2"), 2, 11, "expected ',' between the CIRC auxiliary point and the target"),
    (wrap("  CIRC P1 Vel=1 m/s CPDAT"), 2, 11, "the inline form is supported for PTP and LIN"),
    (wrap("  PTP HOME Vel 100 % DEFAULT"), 2, 16, "expected '=' after Vel"),
    (wrap("  PTP HOME Vel = 100 DEFAULT"), 2, 22, "expected '%' or 'm/s' after the velocity"),
    (wrap("  LIN P1 Vel = 2 %"), 2, 19, "LIN velocity must be given in m/s"),
    (wrap("  PTP P1 Vel = 100 % PDAT1 Tool[X]"), 2, 33, "expected the Tool number"),
    (wrap("  PTP P1 CONT 100 %"), 2, 15, "expected VEL"),
    # routines and modules
    ("", 1, 1, "expected DEF: the file defines no routine"),
    ("X = 1\n", 1, 1, "expected DEF or DEFFCT, found 'X'"),
    ("DEF\nEND\n", 1, 4, "expected the routine name"),
    ("DEF T\nEND\n", 1, 6, "expected '(' after the routine name"),
    ("DEF T(A:INOUT)\nEND\n", 1, 9, "expected IN or OUT"),
    ("DEF T(A B)\nEND\n", 1, 9, "expected ',' or ')'"),
    ("DEF T(1)\nEND\n", 1, 7, "expected a parameter name"),
    ("DEFFCT (A)\nENDFCT\n", 1, 8, "expected the function's return type"),
    ("DEFFCT INT F()\nEND\n", 2, 1, "END without a matching opening statement (expected ENDFCT)"),
    ("DEF T()\nEND X\n", 2, 5, "unexpected 'X' after the statement"),
    ("DEF T()\nEND\nDEF t()\nEND\n", 3, 1, "routine T defined twice"),
]


@pytest.mark.parametrize(("source", "line", "column", "message"), CASES)
def test_syntax_error(source: str, line: int, column: int, message: str) -> None:
    with pytest.raises(KrlSyntaxError) as info:
        parse_src(source, "prog.src")
    error = info.value
    assert isinstance(error, ValueError)
    assert message in error.reason
    assert (error.filename, error.line, error.column) == ("prog.src", line, column)
    first, quoted, caret = str(error).split("\n")
    assert first.startswith(f"prog.src:{line}:{column}: ")
    source_lines = source.split("\n")
    assert quoted.strip() == (source_lines[line - 1].strip() if source_lines else "")
    assert caret.index("^") == column - 1 + 4  # four spaces of indentation


def test_error_text_shows_line_and_caret() -> None:
    with pytest.raises(KrlSyntaxError) as info:
        parse_src(wrap("  LOOP", "    PTP MYAXIS C_PDP", "  ENDLOOP"), "follow.src")
    assert str(info.value) == (
        "follow.src:3:16: unexpected 'C_PDP' after the motion target "
        "(expected C_PTP, C_DIS, C_VEL, C_ORI, #TOOL or #BASE)\n"
        "        PTP MYAXIS C_PDP\n"
        "                   ^"
    )


def test_dat_errors_are_krl_syntax_errors() -> None:
    with pytest.raises(KrlSyntaxError) as info:
        parse_dat("DEFDAT M\nDECL INT A[\nENDDAT\n", "m.dat")
    assert (info.value.line, info.value.column) == (2, 12)
    assert str(info.value).startswith("m.dat:2:12: expected an array size")
    assert "^" in str(info.value)
