"""The KRL parser: corpus files, shipped programs, tree structure, positions and precedence."""

from __future__ import annotations

import time
from importlib import resources
from pathlib import Path

import pytest

from kukavarproxy_emu.krl import ast, parse_dat, parse_src, read_src, tokenize
from kukavarproxy_emu.krl.parser_expr import BINARY_PRIORITY

CORPUS = Path(__file__).parent / "krl_corpus"
PROGRAMS = resources.files("kukavarproxy_emu").joinpath("programs")


def body(src: str) -> tuple[ast.Stmt, ...]:
    """The statements of a one-routine module."""
    return parse_src(src, "t.src").main.body


def expr(text: str) -> ast.Expr:
    """Parse ``text`` as the right-hand side of an assignment."""
    (stmt,) = body(f"DEF T()\n  X = {text}\nEND\n")
    assert isinstance(stmt, ast.Assign)
    return stmt.value


def show(node: ast.Expr) -> str:
    """A fully parenthesised rendering, to assert the tree shape compactly."""
    if isinstance(node, ast.Binary):
        return f"({show(node.left)} {node.op} {show(node.right)})"
    if isinstance(node, ast.Unary):
        return f"({node.op} {show(node.operand)})"
    if isinstance(node, ast.Name):
        return node.name
    if isinstance(node, ast.IntLit | ast.RealLit):
        return repr(node.value)
    if isinstance(node, ast.BoolLit):
        return str(node.value).upper()
    if isinstance(node, ast.Call):
        return f"{node.name}({', '.join(show(a) for a in node.args)})"
    if isinstance(node, ast.Member):
        return f"{show(node.base)}.{node.member}"
    if isinstance(node, ast.Index):
        return f"{show(node.base)}[{', '.join(show(i) for i in node.indices)}]"
    return type(node).__name__


# ------------------------------------------------------------------ corpus and programs


@pytest.mark.parametrize("path", sorted(CORPUS.glob("*.src")), ids=lambda p: p.name)
def test_corpus_parses(path: Path) -> None:
    module = read_src(path)
    assert module.routines
    assert module.name == module.routines[0].name == path.stem.upper()


def test_corpus_dat_parses_with_the_shared_parser() -> None:
    dat = parse_dat((CORPUS / "module.dat").read_text(), "module.dat")
    assert dat.name == "MODULE" and dat.public
    assert [d.name for d in dat.declarations] == ["XP1", "FP1", "COUNTER"]
    assert dat.declarations[2].is_global


SHIPPED = {
    "follow.src": "FOLLOW",
    "actuator.src": "ACTUATOR",
    "ext_move_axis.src": "EXT_MOVE_AXIS",
    "joint_path.src": "JOINT_PATH",
    "cart_path.src": "CART_PATH",
    "sps.sub": "SPS",
}


@pytest.mark.parametrize(("filename", "name"), sorted(SHIPPED.items()))
def test_shipped_programs_parse(filename: str, name: str) -> None:
    resource = PROGRAMS.joinpath(filename)
    text = resource.read_text(encoding="latin-1")
    assert "Algorithm 4." in text or filename == "follow.src"  # header cites its source
    module = parse_src(text, filename)
    assert module.name == name
    assert any(isinstance(s, ast.Loop) for s in module.main.body)


@pytest.mark.parametrize("name", ["actuator", "ext_move_axis"])
def test_shipped_dat_declares_home(name: str) -> None:
    with resources.as_file(PROGRAMS.joinpath(f"{name}.src")) as path:
        module = read_src(path)
    assert module.dat is not None and module.dat.name == name.upper()
    (home,) = module.dat.declarations
    assert (home.name, home.type_name) == ("HOME", "E6AXIS")


def test_follow_structure() -> None:
    module = parse_src(PROGRAMS.joinpath("follow.src").read_text(), "follow.src")
    bas, bco, loop = module.main.body
    assert isinstance(bas, ast.CallStmt) and bas.name == "BAS"  # inside ;FOLD INI
    assert isinstance(bco, ast.Motion) and bco.kind == "PTP"
    assert bco.target == ast.Name("$AXIS_ACT", line=bco.line, column=7)
    assert isinstance(loop, ast.Loop)
    (ptp,) = loop.body
    assert isinstance(ptp, ast.Motion)
    assert (ptp.kind, show(ptp.target), ptp.approx) == ("PTP", "MYAXIS", "C_PTP")


def test_sps_copies_sixteen_outputs() -> None:
    module = parse_src(PROGRAMS.joinpath("sps.sub").read_text(), "sps.sub")
    (loop,) = module.main.body
    assert isinstance(loop, ast.Loop)
    copies = [(show(s.target), show(s.value)) for s in loop.body if isinstance(s, ast.Assign)]
    assert copies == [(f"$OUT[{i}]", f"OUTPUT_VARS[{i}]") for i in range(1, 17)]


def test_path_runner_structure() -> None:
    module = parse_src(PROGRAMS.joinpath("cart_path.src").read_text(), "cart_path.src")
    decl, _bas, _bco, loop = module.main.body
    assert isinstance(decl, ast.Decl) and decl.declarations[0].name == "ROW"
    assert module.main.decls == (decl,)
    assert isinstance(loop, ast.Loop)
    kinds = [type(s).__name__ for s in loop.body]
    assert kinds == ["WaitFor", "Assign", "Assign", "For", "If", "WaitSec"] + ["Assign"] * 3
    loop_for = loop.body[3]
    assert isinstance(loop_for, ast.For) and show(loop_for.stop) == "(PATH_COUNT - 1)"
    motion = loop_for.body[1]
    assert isinstance(motion, ast.Motion)
    assert (motion.kind, show(motion.target), motion.approx) == ("LIN", "MYPOSARRAY[ROW]", "C_DIS")


def test_thesis_inline_ptp_home() -> None:
    module = parse_src(PROGRAMS.joinpath("actuator.src").read_text(), "actuator.src")
    ini, home, advance, loop, _home_again = module.main.body
    assert isinstance(ini, ast.Ini)
    assert isinstance(home, ast.InlineMotion)
    assert (home.kind, show(home.target), home.unit, home.dataset) == (
        "PTP",
        "HOME",
        "%",
        "DEFAULT",
    )
    assert home.velocity == ast.IntLit(100, line=home.line, column=home.column + 15)
    assert isinstance(advance, ast.Assign) and show(advance.target) == "$ADVANCE"
    assert isinstance(loop, ast.Loop)
    (rel,) = loop.body
    assert isinstance(rel, ast.Motion) and (rel.kind, rel.approx) == ("PTP_REL", "C_PTP")


# ----------------------------------------------------------------------- tree structure

CONTROL = (CORPUS / "control_flow.src").read_text()


def test_routines_params_and_functions() -> None:
    module = parse_src(CONTROL, "control_flow.src")
    main, norm2, helper = module.routines
    assert [(p.name, p.direction) for p in main.params] == [("COUNT", "IN"), ("RESULT", "OUT")]
    assert not main.is_function and not main.is_global
    assert norm2.is_function and norm2.return_type == "REAL" and norm2.is_global
    (_decl, ret) = norm2.body
    assert isinstance(ret, ast.Return) and show(ret.value) == "SQRT(((X * X) + (Y * Y)))"  # type: ignore[arg-type]
    assert module.routine("helper") is helper and module.routine("nope") is None
    assert (norm2.line, norm2.column) == (41, 1)


def test_statement_kinds_and_lines() -> None:
    main = parse_src(CONTROL, "control_flow.src").main
    found = [(type(s).__name__, s.line) for s in main.body]
    assert found == [
        ("Decl", 3), ("Decl", 4), ("Decl", 5), ("Decl", 6), ("Assign", 7), ("For", 8),
        ("For", 11), ("While", 16), ("Repeat", 20), ("Switch", 23), ("WaitFor", 31),
        ("WaitSec", 32), ("Continue", 33), ("If", 34),
    ]  # fmt: skip
    implicit = main.body[3]
    assert isinstance(implicit, ast.Decl) and implicit.declarations[0].type_name == "INT"
    loop_for = main.body[6]
    assert isinstance(loop_for, ast.For) and show(loop_for.step) == "(- 1)"  # type: ignore[arg-type]
    (inner_if,) = loop_for.body
    assert isinstance(inner_if, ast.If) and isinstance(inner_if.then_body[0], ast.Exit)
    switch = main.body[9]
    assert isinstance(switch, ast.Switch)
    assert [[show(v) for v in c.values] for c in switch.cases] == [["1", "2"], ["3"]]
    assert switch.default is not None and isinstance(switch.default[0], ast.Halt)
    repeat = main.body[8]
    assert isinstance(repeat, ast.Repeat) and show(repeat.cond) == "(I <= 0)"
    last_if = main.body[13]
    assert isinstance(last_if, ast.If)
    bits = last_if.then_body[0]
    assert isinstance(bits, ast.Assign) and show(bits.value) == "(10 + 31)"


def test_motions_in_helper() -> None:
    helper = parse_src(CONTROL, "control_flow.src").routines[2]
    motions = [s for s in helper.body if isinstance(s, ast.Motion)]
    assert [(m.kind, m.approx, m.frame) for m in motions] == [
        ("PTP", "C_PTP", None), ("PTP_REL", "C_PTP", None), ("LIN_REL", "C_DIS", "TOOL"),
        ("LIN", "C_VEL", None), ("CIRC", "C_ORI", None),
    ]  # fmt: skip
    circ = motions[-1]
    assert isinstance(circ.aux, ast.Aggregate) and isinstance(circ.target, ast.Aggregate)
    assert circ.aux.text == "{X 1.0, Y 2.0, Z 3.0}"
    assert isinstance(helper.body[-1], ast.Return) and helper.body[-1].value is None


def test_aggregates() -> None:
    agg = expr("{E6AXIS: A1 0.0, A2 -90.0, S 'B010', M #BASE, N \"x\", P {X 1}, Q TRUE}")
    assert isinstance(agg, ast.Aggregate) and agg.type_name == "E6AXIS"
    assert [i.name for i in agg.items] == ["A1", "A2", "S", "M", "N", "P", "Q"]
    a2 = agg.items[1].value
    assert (
        isinstance(a2, ast.Unary)
        and a2.op == "-"
        and a2.operand == ast.RealLit(90.0, line=2, column=28)
    )
    assert agg.items[2].value == ast.IntLit(2, line=2, column=36)
    assert isinstance(agg.items[5].value, ast.Aggregate)
    assert agg.text.startswith("{E6AXIS:") and agg.text.endswith("Q TRUE}")
    empty = expr("{}")
    assert isinstance(empty, ast.Aggregate) and empty.items == ()


def test_inline_forms() -> None:
    stmts = parse_src((CORPUS / "kuka_template.src").read_text(), "k.src").main.body
    inline = [s for s in stmts if isinstance(s, ast.InlineMotion)]
    assert [(m.kind, show(m.target), m.cont, m.unit, m.dataset, m.tool, m.base) for m in inline] == [
        ("PTP", "P1", True, "%", "PDAT1", 1, 0),
        ("LIN", "P2", False, "M/S", "CPDAT1", 1, 2),
        ("PTP", "HOME", False, "%", "DEFAULT", None, None),
    ]  # fmt: skip
    # The expanded fold ($H_POS=XHOME, BAS(#PTP_PARAMS,100), PTP XHOME) is ordinary code.
    assert sum(isinstance(s, ast.CallStmt) and s.name == "BAS" for s in stmts) == 2


def test_lvalues_and_whole_array() -> None:
    stmts = parse_src((CORPUS / "types.src").read_text(), "types.src").main.body
    struc, enum, *_ = stmts
    assert isinstance(struc, ast.StrucDef) and struc.struc.members[2] == ("ID", "INT")
    assert isinstance(enum, ast.EnumDef) and enum.enum.values == ("RED", "GREEN", "BLUE")
    targets = [show(s.target) for s in stmts if isinstance(s, ast.Assign)]
    assert targets == ["P.X", "C", "NAME[]", "GRID[2, 3]", "MYE6ARRAY[(P.ID + 1)].A2"]
    grid = next(s for s in stmts if isinstance(s, ast.Decl) and s.declarations[-1].name == "GRID")
    assert grid.declarations[-1].dims == (3, 4)


def test_case_insensitive_names_and_keywords() -> None:
    (loop,) = body("def t()\n  loop\n    ptp myAxis c_ptp\n  endloop\nend\n")
    assert isinstance(loop, ast.Loop)
    (ptp,) = loop.body
    assert isinstance(ptp, ast.Motion) and show(ptp.target) == "MYAXIS" and ptp.approx == "C_PTP"


def test_columns_point_at_tokens() -> None:
    (stmt,) = body("DEF T()\n    $OUT[3] = NOT $IN[2]\nEND\n")
    assert isinstance(stmt, ast.Assign) and (stmt.line, stmt.column) == (2, 5)
    assert isinstance(stmt.value, ast.Unary) and stmt.value.column == 15
    assert isinstance(stmt.value.operand, ast.Index) and stmt.value.operand.column == 22


# --------------------------------------------------------------------------- precedence


@pytest.mark.parametrize(
    ("text", "tree"),
    [
        ("1 + 2 * 3", "(1 + (2 * 3))"),
        ("(1 + 2) * 3", "((1 + 2) * 3)"),
        ("1 - 2 - 3", "((1 - 2) - 3)"),
        ("8 / 4 / 2", "((8 / 4) / 2)"),
        ("-A * B", "((- A) * B)"),
        ("- -A", "(- (- A))"),
        ("NOT A AND B", "((NOT A) AND B)"),
        ("A OR B AND C", "(A OR (B AND C))"),
        ("A OR B EXOR C", "(A OR (B EXOR C))"),
        ("A EXOR B AND C", "(A EXOR (B AND C))"),
        # KSS priority table: comparisons bind loosest, so KRL code brackets them.
        ("A > 1 AND B < 2", "((A > (1 AND B)) < 2)"),
        ("(A > 1) AND (B < 2)", "((A > 1) AND (B < 2))"),
        ("A == B OR C", "(A == (B OR C))"),
        ("A + 1 >= B * 2", "((A + 1) >= (B * 2))"),
        ("A <> B", "(A <> B)"),
        ("F1 : F2 * 2", "((F1 : F2) * 2)"),
        ("A B_AND 'H0F' B_OR B_NOT C", "((A B_AND 15) B_OR (B_NOT C))"),
        ("SIN(30.0) + COS(X) * ATAN2(1, 2)", "(SIN(30.0) + (COS(X) * ATAN2(1, 2)))"),
        ("ABS(-P.X)", "ABS((- P.X))"),
        ("1.5E3 + .5 + 2E-2", "((1500.0 + 0.5) + 0.02)"),
        ("TRUE AND FALSE", "(TRUE AND FALSE)"),
    ],
)
def test_precedence(text: str, tree: str) -> None:
    assert show(expr(text)) == tree


def test_priority_table_is_total() -> None:
    assert set(BINARY_PRIORITY) >= {"*", "/", "+", "-", "AND", "OR", "EXOR", "==", "<>", ":"}


def test_literals() -> None:
    assert expr('"hello; not a comment"') == ast.StrLit("hello; not a comment", line=2, column=7)
    assert expr("#t1") == ast.EnumLit("T1", line=2, column=7)
    assert expr("'b1111'") == ast.IntLit(15, line=2, column=7)
    assert expr("false") == ast.BoolLit(False, line=2, column=7)


# ------------------------------------------------------------------------------- lexer


def test_lexer_drops_comments_and_headers() -> None:
    tokens = tokenize("&ACCESS RVP\n  ;FOLD x\nX=1 ; c\n", "f")
    assert [(t.kind, t.value) for t in tokens if t.kind != "NEWLINE"] == [
        ("NAME", "X"), ("OP", "="), ("INT", "1"), ("EOF", ""),
    ]  # fmt: skip


def test_lexer_is_linear_on_large_input() -> None:
    line = "  X = X + 1.5E-3 * $AXIS_ACT.A1 ; comment {\n"
    text = "DEF BIG()\n" + line * 20000 + "END\n"
    # CPU time, not wall time: the property is the work done, which a loaded machine does not
    # change (it stretches the wall clock)
    started = time.thread_time()
    module = parse_src(text, "big.src")
    assert len(module.main.body) == 20000
    assert time.thread_time() - started < 10
    # A pathological literal (long digit runs, unterminated aggregate) fails fast.
    started = time.thread_time()
    with pytest.raises(ValueError):
        parse_src("DEF T()\n X = {" + "A1 1" * 50000 + "\nEND\n", "bad.src")
    assert time.thread_time() - started < 5
