"""The $CONFIG.DAT-style declaration parser and loading its result into a VariableStore."""

from __future__ import annotations

import pytest

from kukavarproxy_emu.default_config import load_default_config
from kukavarproxy_emu.store import UnknownVariable, VariableStore, WriteRefused
from pyopenshowvar.krl.datfile import (
    Assignment,
    DatSyntaxError,
    Declaration,
    EnumDecl,
    StrucDecl,
    parse_dat,
)

REALISTIC = """\
&ACCESS RVO
&REL 12
&PARAM EDITMASK = *
DEFDAT  $CONFIG
;FOLD BASISTECH GLOBALS;%{PE}%V3.2.0,%MKUKATPBASIS,%CCONFIG,%VGLOBALS,%P
EXT  BAS (BAS_COMMAND  :IN,REAL  :IN )
extfct REAL my_func (INT :IN)
;ENDFOLD (BASISTECH GLOBALS)

;FOLD USER GLOBALS
; user types
GLOBAL ENUM COLORS RED, GREEN, BLUE
enum mode_t fast,slow
GLOBAL STRUC CELL_T REAL X, Y, INT N, E6AXIS AX, COLORS COL, CHAR LABEL[12]
STRUC  small_t  bool ok

DECL GLOBAL E6AXIS HOME_AX={A1 0.0, A2 -90.0, A3 90.0, A4 0.0, A5 0.0, A6 0.0}  ; home
decl int A, B=2, C[10]
INT COUNT=0
REAL SPEED=3.5
DECL BOOL OUTPUT_VARS[16]
OUTPUT_VARS[3]=TRUE
output_vars[ 4 ] = true ; spaces are fine
DECL REAL GRID[3,4]
GRID[2,3]=1.5
CHAR NAME[20]
NAME[]="a;b, {c}"
DECL CELL_T CELL={X 1.0, N 3, COL #GREEN, LABEL[] "cell"}
DECL MODE_T MODE=#SLOW
DECL CONST INT MAXN=10
DECL STATE_T MYSTATE
;ENDFOLD (USER GLOBALS)
ENDDAT
"""


def test_realistic_config_dat_is_parsed_completely() -> None:
    dat = parse_dat(REALISTIC, "$CONFIG.DAT")
    assert dat.name == "$CONFIG"
    assert not dat.public
    assert dat.enums == (
        EnumDecl("COLORS", ("RED", "GREEN", "BLUE"), True, 12),
        EnumDecl("MODE_T", ("FAST", "SLOW"), False, 13),
    )
    assert dat.structs == (
        StrucDecl(
            "CELL_T",
            (
                ("X", "REAL"),
                ("Y", "REAL"),
                ("N", "INT"),
                ("AX", "E6AXIS"),
                ("COL", "COLORS"),
                ("LABEL", "CHAR[12]"),
            ),
            True,
            14,
        ),
        StrucDecl("SMALL_T", (("OK", "BOOL"),), False, 15),
    )
    decls = {d.name: d for d in dat.declarations}
    assert list(decls) == [
        "HOME_AX", "A", "B", "C", "COUNT", "SPEED", "OUTPUT_VARS", "GRID", "NAME", "CELL",
        "MODE", "MAXN", "MYSTATE",
    ]  # fmt: skip
    assert decls["HOME_AX"] == Declaration(
        "HOME_AX",
        "E6AXIS",
        (),
        "{A1 0.0, A2 -90.0, A3 90.0, A4 0.0, A5 0.0, A6 0.0}",
        is_global=True,
        is_const=False,
        line=17,
    )
    assert (decls["A"].init, decls["B"].init, decls["C"].dims) == (None, "2", (10,))
    assert decls["COUNT"].type_name == "INT" and decls["COUNT"].init == "0"
    assert decls["GRID"].dims == (3, 4)
    assert decls["NAME"] == Declaration("NAME", "CHAR", (20,), None, False, False, 26)
    assert decls["CELL"].init == '{X 1.0, N 3, COL #GREEN, LABEL[] "cell"}'
    assert decls["MAXN"].is_const and decls["MAXN"].init == "10"
    assert dat.assignments == (
        Assignment("OUTPUT_VARS[3]", "TRUE", 22),
        Assignment("OUTPUT_VARS[4]", "true", 23),
        Assignment("GRID[2,3]", "1.5", 25),
        Assignment("NAME[]", '"a;b, {c}"', 27),
    )


def test_public_module_dat_and_no_wrapper() -> None:
    dat = parse_dat("defdat mymod public\nDECL GLOBAL INT X=1\nDECL INT Y\nenddat\n")
    assert dat.name == "MYMOD" and dat.public
    assert [(d.name, d.is_global) for d in dat.declarations] == [("X", True), ("Y", False)]
    bare = parse_dat("DECL INT X=1\n\n   ; only a comment\n")
    assert bare.name is None and [d.name for d in bare.declarations] == ["X"]


def test_multiple_aggregates_in_one_decl_split_at_top_level_commas() -> None:
    dat = parse_dat("DECL FRAME F1={X 1.0, Y 2.0}, F2, F3={Z 3.0}")
    assert [(d.name, d.init) for d in dat.declarations] == [
        ("F1", "{X 1.0, Y 2.0}"),
        ("F2", None),
        ("F3", "{Z 3.0}"),
    ]


@pytest.mark.parametrize(
    ("text", "line", "column", "reason"),
    [
        ("DECL INT\n", 1, 9, "expected a variable name"),
        ("DECL INT OK=1\nDECL REAL X[0]\n", 2, 13, "array size must be positive"),
        ("DECL INT X[3\n", 1, 13, "expected ',' or ']'"),
        ("\n\nDECL E6AXIS P={A1 0.0, A2 1.0\n", 3, 15, "unbalanced '{'"),
        ('DECL CHAR S[4]\nS[]="abc\n', 2, 5, "unterminated string"),
        ("DECL INT X=\n", 1, 12, "expected a value after '='"),
        ("DECL INT X Y\n", 1, 12, "unexpected text"),
        ("STRUC S INT\n", 1, 12, "expected a member name"),
        ("STRUC S INT A, B[3]\n", 1, 16, "only 1-D CHAR arrays are supported as members"),
        ("ENUM E A, A\n", 1, 11, "duplicate enumeration value A"),
        ("DEFDAT X\nDECL INT A\n", 2, 1, "missing ENDDAT"),
        ("DEFDAT X\nENDDAT\nDECL INT A\n", 3, 1, "text after ENDDAT"),
        ("DECL INT A\nDEFDAT X\nENDDAT\n", 2, 1, "DEFDAT must be the first statement"),
        ("FOO\n", 1, 1, "expected a declaration or an assignment"),
        ("DEFDAT X PRIVATE\nENDDAT\n", 1, 17, "expected PUBLIC"),
        ("DECL GLOBAL DECL\n", 1, 17, "expected a type name"),
    ],
)
def test_syntax_errors_name_file_line_column_and_text(
    text: str, line: int, column: int, reason: str
) -> None:
    with pytest.raises(DatSyntaxError) as info:
        parse_dat(text, "MY.DAT")
    err = info.value
    assert (err.filename, err.line, err.column, err.reason) == ("MY.DAT", line, column, reason)
    assert str(err).startswith(f"MY.DAT:{line}:{column}: {reason}: ")
    assert isinstance(err, ValueError)
    if err.text:
        assert repr(err.text.strip()) in str(err)


def test_default_config_declares_the_thesis_globals() -> None:
    dat = load_default_config()
    decls = {d.name: d for d in dat.declarations}
    assert decls["MYE6ARRAY"].dims == (512,) and decls["MYPOSARRAY"].type_name == "POS"
    for name in ("PATH_COUNT", "PATH_START", "PATH_BUSY", "PATH_DONE", "PATH_INDEX"):
        assert name in decls
    assert decls["OUTPUT_VARS"].dims == (16,)
    assert decls["MYSTRING"].dims == (32,)


def test_store_loads_user_types_globals_and_element_inits() -> None:
    store = VariableStore(default_config=False)
    declared = store.load_dat(REALISTIC.replace("DECL STATE_T MYSTATE\n", ""))
    assert "CELL" in declared and "MAXN" in declared
    assert store.read("cell.x") == "1.00000" and store.read("CELL.COL") == "#GREEN"
    assert store.read("CELL.LABEL") == '"cell"'
    with pytest.raises(UnknownVariable):
        store.read("CELL.Y")  # never initialised
    assert store.read("HOME_AX.A2") == "-90.0000"
    assert store.read("OUTPUT_VARS[3]") == "TRUE" and store.read("OUTPUT_VARS[4]") == "TRUE"
    assert store.read("GRID[2,3]") == "1.50000"
    assert store.read("NAME[]") == '"a;b, {c}"'
    assert store.read("MODE") == "#SLOW"
    store.write("CELL.AX", "{A1 5}")
    assert store.read("CELL.AX") == "{E6AXIS: A1 5.00000}"
    store.write("CELL.COL", "#BLUE")
    with pytest.raises(WriteRefused, match="not a value of ENUM COLORS"):
        store.write("CELL.COL", "#PURPLE")
    with pytest.raises(WriteRefused, match="read-only"):
        store.write("MAXN", "11")  # CONST
    assert store.read("B") == "2"


def test_store_skips_bad_declarations_unless_strict(caplog: pytest.LogCaptureFixture) -> None:
    text = "DECL STATE_T MYSTATE\nDECL INT OK=1\nDECL INT BAD=TRUE\nUNDECLARED[1]=1\n"
    store = VariableStore(default_config=False)
    assert store.load_dat(text) == ["OK"]
    assert "MYSTATE" in caplog.text and "BAD" in caplog.text and "UNDECLARED" in caplog.text
    with pytest.raises(ValueError, match=r"<dat>:1:14: declaration of MYSTATE"):
        VariableStore(default_config=False, strict=True).load_dat(text)


def test_module_dat_exports_only_global_declarations() -> None:
    store = VariableStore(default_config=False)
    store.load_dat("DEFDAT MOD PUBLIC\nDECL GLOBAL INT G=1\nDECL INT L=2\nENDDAT\n")
    assert store.read("G") == "1"
    assert "L" not in store.names()
