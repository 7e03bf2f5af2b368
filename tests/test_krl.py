"""Example-based tests of pyopenshowvar.krl with real controller strings (reference docs §2, §4)."""

from __future__ import annotations

import copy
import pickle
import struct

import numpy as np
import pytest

from pyopenshowvar.errors import KrlValueError
from pyopenshowvar.krl import (
    BUILTIN_TYPES,
    Axis,
    E6Axis,
    E6Pos,
    EnumDef,
    Frame,
    KrlEnum,
    Pos,
    Struct,
    StructDef,
    TypeRegistry,
    float32,
    format_krc4,
    format_real_krc4,
    format_value,
    parse_array,
    parse_value,
)


def f32(x: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", x))[0])


def parse_struct(text: str) -> Struct:
    v = parse_value(text)
    assert isinstance(v, Struct)
    return v


E6POS_CAPTURE = (
    "{E6POS: X 284.994965, Y -694.394653, Z 41.2478294, A 131.430344, B -0.0191543195, "
    "C 179.992111, S 2, T 10, E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)
LOAD_CAPTURE = (
    "{LOAD: M 65.0000, CM {FRAME: X 180.000, Y 0.0, Z 150.000, A 0.0, B 0.0, C 0.0}, "
    "J {INERTIA: X 19.5000, Y 19.5000, Z 19.5000}}"
)
TORQUE_CAPTURE = (
    "1.77311117E-11 -1.75174166E-12 -8.43800585E-11 0.0 0.0 0.0 0.0 0.0 0.0 0.0 0.0 0.0 "
)
HOME_E6AXIS = (
    "{E6AXIS: A1 0.0, A2 -90.0000, A3 90.0000, A4 0.0, A5 0.0, A6 0.0, "
    "E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)
HOME_E6POS = (
    "{E6POS: X 525.000, Y 0.0, Z 890.000, A 0.0, B 90.0000, C 0.0, S 2, T 2, "
    "E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)
ZEROS = {f"E{i}": 0.0 for i in range(1, 7)}


# --- parsing: real controller strings ----------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("100", 100),
        ("-875.0", -875.0),
        ("TRUE", True),
        ("false", False),
        ("#T1", KrlEnum("T1")),
        ("#p_active", KrlEnum("P_ACTIVE")),
        ('"xxxxxxxxxx"', "xxxxxxxxxx"),
        ('""', ""),
        ("284.994965", 284.994965),
        ("90.00000", 90.0),
        ("-1.162400", -1.1624),
        ("4.48259061E-06", 4.48259061e-06),
        ("1e-5", 1e-5),
        ("-2.22039314E-12", -2.22039314e-12),
        (".5", 0.5),
        ("+1.0", 1.0),
        ("100000.", 100000.0),
        ("  42  ", 42),
        ("'B1010'", 10),
        ("'H1F'", 31),
        (
            E6POS_CAPTURE,
            E6Pos(
                x=284.994965,
                y=-694.394653,
                z=41.2478294,
                a=131.430344,
                b=-0.0191543195,
                c=179.992111,
                s=2,
                t=10,
                **ZEROS,
            ),
        ),
        (
            # KRC2 / KSS 5.x: 7 significant digits, trailing zeros kept, members missing
            "{E6POS: X 12.84936, Y 1.0, Z 2.0, A 0.0, B 0.0, C -1.162400, S 18, T 10, E1 90.00000}",
            E6Pos(x=12.84936, y=1.0, z=2.0, a=0.0, b=0.0, c=-1.1624, s=18, t=10, e1=90.0),
        ),
        (
            "{E6POS: X 0.0, Y 0.0, Z 0.0, A 0.0, B 0.0, C 0.0}",
            E6Pos(x=0.0, y=0.0, z=0.0, a=0.0, b=0.0, c=0.0),
        ),
        (
            "{E6AXIS: A1 -2.820527, A2 -73.70981}",
            E6Axis(a1=-2.820527, a2=-73.70981),
        ),
        (
            LOAD_CAPTURE,
            Struct(
                "LOAD",
                {
                    "M": 65.0,
                    "CM": Frame(x=180.0, y=0.0, z=150.0, a=0.0, b=0.0, c=0.0),
                    "J": Struct("INERTIA", {"X": 19.5, "Y": 19.5, "Z": 19.5}),
                },
            ),
        ),
        ("{X 1.5, Z 3.0}", Struct(None, {"X": 1.5, "Z": 3.0})),
        ("{}", Struct(None, {})),
        ("{E6POS: }", E6Pos()),
        (
            # odd spacing, tabs, lower case everywhere
            "{  e6axis :a1   1.0 ,\ta2 -2.0,A3 3 }",
            E6Axis(a1=1.0, a2=-2.0, a3=3.0),
        ),
        ("{frame: x 1 , y 2}", Frame(x=1.0, y=2.0)),
        (
            # user struct: members inferred, nested known types typed
            "{KR_STATE_BLK: AXIS_ACT {E6AXIS: A1 1.0, A2 -59.9256401}, ON TRUE, MODE #T1, "
            'NAME "r1", CNT 7}',
            Struct(
                "KR_STATE_BLK",
                {
                    "AXIS_ACT": E6Axis(a1=1.0, a2=-59.9256401),
                    "ON": True,
                    "MODE": KrlEnum("T1"),
                    "NAME": "r1",
                    "CNT": 7,
                },
            ),
        ),
        ("1.0 2.0 3.0 ", [1.0, 2.0, 3.0]),
        ("1 2", [1, 2]),
        (TORQUE_CAPTURE, [1.77311117e-11, -1.75174166e-12, -8.43800585e-11] + [0.0] * 9),
    ],
)
def test_parse_real_text(text: str, expected: object) -> None:
    assert parse_value(text) == expected


def test_parse_returns_typed_classes_and_types() -> None:
    p = parse_value(E6POS_CAPTURE)
    assert type(p) is E6Pos
    assert p.s == 2 and type(p.s) is int
    assert p.t == 10 and type(p.t) is int
    assert type(p.e1) is float
    load = parse_value(LOAD_CAPTURE)
    assert isinstance(load, Struct) and type(load) is Struct
    assert type(load["CM"]) is Frame
    assert load.cm.z == 150.0  # type: ignore[union-attr]
    assert type(parse_value("{AXIS: A1 1}")) is Axis
    assert type(parse_value("{POS: X 1}")) is Pos


def test_s_and_t_land_in_s_and_t_not_in_e1_e2() -> None:
    """Regression: clients parsing by position put S/T into E1/E2 (reference §2.1)."""
    p = parse_value(E6POS_CAPTURE)
    assert isinstance(p, E6Pos)
    assert (p.s, p.t, p.e1, p.e2) == (2, 10, 0.0, 0.0)
    assert list(p.keys())[6:9] == ["S", "T", "E1"]
    # even when the text order is odd, S/T stay S/T and printing uses canonical order
    q = parse_value("{E6POS: E1 5.0, T 3, S 6, X 1.0}")
    assert isinstance(q, E6Pos)
    assert (q.s, q.t, q.e1) == (6, 3, 5.0)
    assert format_krc4(q) == "{E6POS: X 1.00000, S 6, T 3, E1 5.00000}"


def test_struct_member_values_with_commas_and_nesting() -> None:
    s = parse_value('{A {B {C "x,y"}, D 1}, E #X}')
    assert s == Struct(
        None, {"A": Struct(None, {"B": Struct(None, {"C": "x,y"}), "D": 1}), "E": KrlEnum("X")}
    )


# --- parsing with a declared type --------------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "type_name", "expected"),
    [
        ("50", "INT", 50),
        ("50.0", "INT", 50),
        ("5", "REAL", 5.0),
        ("TRUE", "BOOL", True),
        ('"abc"', "CHAR[]", "abc"),
        ('"abc"', "char", "abc"),
        ("#aut", "MODE_OP", KrlEnum("AUT")),
        ("{X 1}", "POS", Pos(x=1.0)),
        ("{X 1, S 2}", "pos", Pos(x=1.0, s=2)),
        ("{FRAME: X 1, Y 2}", "POS", Pos(x=1.0, y=2.0)),
        ("{CP 1, ORI1 2}", "CP", Struct("CP", {"CP": 1.0, "ORI1": 2.0})),
        ("{CVEL 50.0, CDIS 1}", "APO", Struct("APO", {"CVEL": 50, "CDIS": 1.0})),
        ("1 2 3 ", "REAL[]", [1.0, 2.0, 3.0]),
        ("{A1 1} {A1 2}", "E6AXIS[]", [E6Axis(a1=1.0), E6Axis(a1=2.0)]),
        ("{M 1, CM {X 2}}", "LOAD", Struct("LOAD", {"M": 1.0, "CM": Frame(x=2.0)})),
    ],
)
def test_parse_typed(text: str, type_name: str, expected: object) -> None:
    v = parse_value(text, type_name)
    assert v == expected
    assert type(v) is type(expected)


@pytest.mark.parametrize(
    ("text", "type_name", "fragment"),
    [
        ("", None, "empty"),
        ("   ", None, "empty"),
        ("1.5", "INT", "INT"),
        ("1", "BOOL", "BOOL"),
        ("TRUTH", None, "TRUTH"),
        ("#T9", "MODE_OP", "#T9"),
        ("{E6POS: Q 1.0}", None, "no member Q"),
        ("{X 1, E1 2}", "POS", "no member E1"),
        ("{X 1.0, X 2.0}", None, "duplicate"),
        ("{X 1.0 Y 2.0}", None, "','"),
        ("{X 1.0", None, "end of text"),
        ("{E6POS: X 1.0}}", None, "'}'"),
        ('"abc', None, "at 0"),
        ("1.0.0", None, "unexpected '1.0.0' at 0"),
        ("{X 1, Y 2x}", None, "unexpected '2x' at 8"),
        ("12TRUE", None, "unexpected '12TRUE'"),
        ("1.0 \u00a0", None, "unexpected"),
        ("#", None, "unexpected '#'"),
        ("{:}", None, "expected a member name, got ':' at 1"),
        ("{E6POS: X 1, Q 2}", None, "E6POS has no member Q, got 'Q' at 13"),
        ("{X 1, X 2}", None, "duplicate member X, got 'X' at 6"),
        ("{X 1,}", None, "expected a member name, got '}' at 5"),
        ("{X 1", None, "expected ',' or '}', got end of text at 4"),
        ("1 2", "INT", "unexpected"),
        ("1e999", None, "range"),
        ("99999999999", "INT", "32-bit"),
        ("{X 1}", "REAL", "REAL"),
        ("5", "NO_SUCH_TYPE", "NO_SUCH_TYPE"),
        ("{A " * 100, None, "deeply"),
    ],
)
def test_parse_errors_quote_the_text(text: str, type_name: str | None, fragment: str) -> None:
    with pytest.raises(KrlValueError) as exc:
        parse_value(text, type_name)
    assert fragment in str(exc.value)


def test_parse_error_reports_position() -> None:
    with pytest.raises(KrlValueError, match=r"got .Y. at 14"):
        parse_value("{E6POS: X 1.0 Y 2.0}")


def test_parse_array() -> None:
    assert parse_array(TORQUE_CAPTURE, "REAL")[:3] == [
        1.77311117e-11,
        -1.75174166e-12,
        -8.43800585e-11,
    ]
    assert parse_array("287 290 ", "INT") == [287, 290]
    assert parse_array("287 ", "INT") == [287]
    assert parse_array("1.5 ") == [1.5]
    assert parse_array('"xxxxxxxxxx"') == "xxxxxxxxxx"
    assert parse_array('"KR 6 R900 sixx"', "CHAR") == "KR 6 R900 sixx"
    assert parse_array("0.0 0.0 ", "REAL[]") == [0.0, 0.0]
    with pytest.raises(KrlValueError):
        parse_array("", "REAL")
    with pytest.raises(KrlValueError):
        parse_array("1.5 x", "REAL")


# --- registry ----------------------------------------------------------------------------------
def test_registry_builtin_and_user_types() -> None:
    e6pos = BUILTIN_TYPES.get("e6pos")
    assert isinstance(e6pos, StructDef)
    assert e6pos.member_names == ("X", "Y", "Z", "A", "B", "C", "S", "T", *ZEROS)
    assert BUILTIN_TYPES.struct("LOAD") == StructDef(
        "LOAD", (("M", "REAL"), ("CM", "FRAME"), ("J", "INERTIA"))
    )
    assert BUILTIN_TYPES.enum("MODE_OP") == EnumDef("MODE_OP", ("T1", "T2", "AUT", "EX", "INVALID"))
    with pytest.raises(TypeError):
        BUILTIN_TYPES.add_enum("X", ("A",))

    reg = BUILTIN_TYPES.copy()
    reg.add_enum("COLOR", ("RED", "GREEN"))
    reg.add_struct("BLK", (("POSE", "E6POS"), ("COL", "COLOR"), ("NAME", "CHAR[24]"), ("N", "INT")))
    assert "BLK" not in BUILTIN_TYPES and "blk" in reg
    v = parse_value('{BLK: POSE {X 1, S 2}, COL #red, NAME "a", N 3}', registry=reg)
    assert v == Struct(
        "BLK", {"POSE": E6Pos(x=1.0, s=2), "COL": KrlEnum("RED"), "NAME": "a", "N": 3}
    )
    with pytest.raises(KrlValueError, match="BLUE"):
        parse_value("{BLK: COL #BLUE}", registry=reg)
    with pytest.raises(KrlValueError, match="N"):
        parse_value("{BLK: N 1.5}", registry=reg)
    # a user struct unknown to the registry still parses, untyped members inferred
    assert parse_value("{BLK: N 1.5}") == Struct("BLK", {"N": 1.5})


# --- value classes -----------------------------------------------------------------------------
def test_struct_access_equality_and_immutability() -> None:
    s = Struct("load", {"m": 1.0, "Cm": Frame(x=1.0)})
    assert s.type_name == "LOAD"
    assert list(s) == ["M", "CM"]
    assert s["M"] == s["m"] == s.get("M") == s.m == 1.0
    assert s.get("nope") is None and "cm" in s and len(s) == 2
    with pytest.raises(AttributeError):
        _ = s.nope
    with pytest.raises(AttributeError):
        s.m = 2.0
    assert s == Struct("LOAD", {"CM": Frame(x=1.0), "M": 1.0})
    assert s != Struct(None, {"M": 1.0, "CM": Frame(x=1.0)})
    assert Struct(None, {"X": 1}) == Struct(None, {"x": 1})
    assert s != 1
    assert hash(s) == hash(Struct("LOAD", {"M": 1.0, "CM": Frame(x=1.0)}))
    assert pickle.loads(pickle.dumps(s)) == s
    assert copy.deepcopy(E6Pos(x=1.0)) == E6Pos(x=1.0)
    with pytest.raises(KrlValueError):
        Struct("bad name", {})


def test_replace_and_merged_follow_partial_aggregate_semantics() -> None:
    p = E6Pos(x=1.0, y=2.0, s=2, t=2)
    assert p.replace(x=5.0) == E6Pos(x=5.0, y=2.0, s=2, t=2)
    assert p.replace(y=None) == E6Pos(x=1.0, s=2, t=2)
    assert type(p.merged(Struct(None, {"Z": 3.0}))) is E6Pos
    assert p.merged(parse_struct("{Z 3, X 9}")) == E6Pos(x=9.0, y=2.0, z=3.0, s=2, t=2)
    with pytest.raises(KrlValueError):
        p.replace(q=1.0)
    load = parse_value(LOAD_CAPTURE)
    assert isinstance(load, Struct)
    changed = load.merged(parse_struct("{CM {X 1.0}}"))
    assert changed["CM"] == Frame(x=1.0, y=0.0, z=150.0, a=0.0, b=0.0, c=0.0)
    assert changed["M"] == 65.0


def test_typed_constructors() -> None:
    p = E6Pos(s=2, t=2, y=2, x=1)  # any order in, canonical order out
    assert list(p.keys()) == ["X", "Y", "S", "T"]
    assert type(p.x) is float and type(p.s) is int
    assert p.z is None and not p.is_complete
    assert E6Pos({"X": 1.0}, y=2.0) == E6Pos(x=1.0, y=2.0)
    assert Axis(a1=1, a2=2, a3=3, a4=4, a5=5, a6=6).is_complete
    assert Pos(s=np.int64(3)).s == 3
    for bad in ({"s": 1.5}, {"x": "1"}, {"x": True}, {"x": float("nan")}, {"e1": 1.0}):
        with pytest.raises(KrlValueError):
            Pos(**bad)
    assert repr(Pos(x=1.0, s=2)) == "Pos(x=1.0, s=2)"


def test_krl_enum() -> None:
    assert KrlEnum("#t1") == KrlEnum("T1")
    assert str(KrlEnum("p_end")) == "#P_END"
    with pytest.raises(KrlValueError):
        KrlEnum("no spaces")


# --- numpy interop -----------------------------------------------------------------------------
def test_numpy_roundtrip() -> None:
    home = parse_value(HOME_E6AXIS)
    assert isinstance(home, E6Axis)
    np.testing.assert_array_equal(home.to_numpy(), [0.0, -90.0, 90.0, 0.0, 0.0, 0.0])
    assert home.to_numpy(with_external=True).shape == (12,)
    assert home.to_numpy().dtype == np.float64

    pos = E6Pos.from_numpy(np.array([525.0, 0.0, 890.0, 0.0, 90.0, 0.0]), s=2, t=2)
    assert pos == E6Pos(x=525.0, y=0.0, z=890.0, a=0.0, b=90.0, c=0.0, s=2, t=2)
    assert type(pos.s) is int and type(pos.x) is float
    full = E6Pos.from_numpy(np.arange(12.0), s=2, t=2)
    assert full.is_complete and full.e6 == 11.0
    assert Frame.from_numpy([1, 2, 3, 4, 5, 6]) == Frame(x=1.0, y=2.0, z=3.0, a=4.0, b=5.0, c=6.0)
    assert Axis.from_numpy(home.to_numpy()) == Axis(a1=0.0, a2=-90.0, a3=90.0, a4=0, a5=0, a6=0)
    with pytest.raises(KrlValueError):
        Frame.from_numpy(np.zeros(12))
    with pytest.raises(KrlValueError):
        Frame(x=1.0).to_numpy()
    with pytest.raises(KrlValueError):
        Frame.from_numpy([1, 2, 3, 4, 5, 6]).to_numpy(with_external=True)
    with pytest.raises(KrlValueError):
        Pos.from_numpy(np.zeros(6), s=2.5)


# --- KRC4 formatting, byte exact ---------------------------------------------------------------
@pytest.mark.parametrize(
    "text",
    [
        "90.0000",
        "-90.0000",
        "-135.000",
        "525.000",
        "4500.00",
        "19.5000",
        "1339.90503",
        "-119.551010",
        "1.51813030",
        "-0.000508518540",
        "4.48259061E-06",
        "2.22039314E-12",
        "284.994965",
        "-24.7800",
        "-24.7812347",
        "-694.394653",
        "41.2478294",
        "-0.0191543195",
        "179.992111",
        "-0.680795908",
        "89.9999466",
        "27.0000057",
        "-4.45310388E-06",
        "18986.8809",
        "-9.35971737",
        "0.000123000",
    ],
)
def test_format_real_krc4_matches_captures(text: str) -> None:
    assert format_real_krc4(float(text)) == text
    assert format_real_krc4(f32(float(text))) == text


def test_format_real_krc4_zero_and_errors() -> None:
    assert format_real_krc4(0.0) == "0.0"
    assert format_real_krc4(-0.0) == "0.0"
    assert format_real_krc4(1e-50) == "0.0"  # below float32's smallest subnormal
    assert format_real_krc4(100000.0) == "100000."  # C's %#.6g keeps the point
    assert format_real_krc4(1e6) == "1.00000E+06"
    for bad in (float("nan"), float("inf"), -float("inf"), 1e39):
        with pytest.raises(KrlValueError):
            format_real_krc4(bad)


def test_format_krc4_structs_and_arrays() -> None:
    home = E6Axis(a1=0.0, a2=-90.0, a3=90.0, a4=0.0, a5=0.0, a6=0.0, **ZEROS)
    assert format_krc4(home) == HOME_E6AXIS
    pose = E6Pos(x=525.0, y=0.0, z=890.0, a=0.0, b=90.0, c=0.0, s=2, t=2, **ZEROS)
    assert format_krc4(pose) == HOME_E6POS
    assert format_krc4(Frame(x=525.0, y=0.0, z=890.0, a=0.0, b=90.0, c=0.0)) == (
        "{FRAME: X 525.000, Y 0.0, Z 890.000, A 0.0, B 90.0000, C 0.0}"
    )
    torque = [f32(x) for x in (1.77311117e-11, -1.75174166e-12, -8.43800585e-11)] + [0.0] * 9
    assert format_krc4(torque) == TORQUE_CAPTURE
    assert format_krc4(parse_value(LOAD_CAPTURE)) == LOAD_CAPTURE
    assert format_krc4(parse_value(E6POS_CAPTURE)) == E6POS_CAPTURE
    assert format_krc4(100) == "100"
    assert format_krc4(True) == "TRUE"
    assert format_krc4(KrlEnum("T1")) == "#T1"
    assert format_krc4("xxxxxxxxxx") == '"xxxxxxxxxx"'
    assert format_krc4(E6Pos()) == "{E6POS: }"
    # never-initialised members are left out, as the controller does
    assert format_krc4(E6Pos(x=0.0, y=0.0, z=0.0, a=0.0, b=0.0, c=0.0)) == (
        "{E6POS: X 0.0, Y 0.0, Z 0.0, A 0.0, B 0.0, C 0.0}"
    )


# --- write literals ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("value", "text"),
    [
        (1.0, "1.0"),
        (-90.0, "-90.0"),
        (1.5e-05, "1.5E-05"),
        (1e16, "1.0E+16"),
        (0.1, "0.1"),
        (-0.0, "-0.0"),
        (50, "50"),
        (False, "FALSE"),
        (KrlEnum("EX"), "#EX"),
        ("a b", '"a b"'),
        ("é", '"é"'),
        (np.float32(0.5), "0.5"),
        (np.int32(7), "7"),
        (Struct(None, {"X": 1.5, "Z": 3.0}), "{X 1.5, Z 3.0}"),
        (E6Axis(a1=0, a2=-90), "{E6AXIS: A1 0.0, A2 -90.0}"),
        (Pos(x=1, s=2, t=2), "{POS: X 1.0, S 2, T 2}"),
        (
            parse_value(LOAD_CAPTURE),
            "{LOAD: M 65.0, CM {FRAME: X 180.0, Y 0.0, Z 150.0, "
            "A 0.0, B 0.0, C 0.0}, J {INERTIA: X 19.5, Y 19.5, Z 19.5}}",
        ),
        ([1.0, 2, True], "1.0 2 TRUE"),
    ],
)
def test_format_value(value: object, text: str) -> None:
    assert format_value(value) == text  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "value", [float("nan"), float("inf"), 'say "hi"', "€", object(), [[1]], {"X": 1}]
)
def test_format_value_rejects(value: object) -> None:
    with pytest.raises(KrlValueError):
        format_value(value)  # type: ignore[arg-type]


def test_float32_helper() -> None:
    assert float32(0.1) == float(np.float32(0.1))
    with pytest.raises(KrlValueError):
        float32(1e40)


def test_registry_resolve_and_copy_independence() -> None:
    reg = TypeRegistry()
    reg.add_struct(StructDef("P", (("X", "REAL"),)))
    other = reg.copy()
    other.add_struct(StructDef("P", (("Y", "REAL"),)))  # redeclare in the copy only
    assert parse_value("{X 1}", "P", registry=reg) == Struct("P", {"X": 1.0})
    assert parse_value("{Y 1}", "P", registry=other) == Struct("P", {"Y": 1.0})
    with pytest.raises(KrlValueError):
        reg.add_struct(StructDef("INT", ()))
    with pytest.raises(KrlValueError):
        StructDef("D", (("A", "INT"), ("a", "REAL")))
