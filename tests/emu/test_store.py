"""VariableStore: KRC4-exact reads, validated atomic writes, names, arrays, system variables."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kukavarproxy_emu.store import UnknownVariable, VariableStore, WriteRefused
from pyopenshowvar.errors import KrlValueError
from pyopenshowvar.krl import E6Axis, Frame, KrlEnum, Struct, parse_value

HOME_AXIS = (
    "{E6AXIS: A1 0.0, A2 -90.0000, A3 90.0000, A4 0.0, A5 0.0, A6 0.0,"
    " E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)
HOME_POS = (
    "{E6POS: X 525.000, Y 0.0, Z 890.000, A 0.0, B 90.0000, C 0.0, S 2, T 2,"
    " E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)


@pytest.fixture(scope="module")
def pristine() -> VariableStore:
    return VariableStore()


@pytest.fixture
def store() -> VariableStore:
    return VariableStore()


# --- reads ------------------------------------------------------------------------------------
def test_home_pose_reads_byte_exact(pristine: VariableStore) -> None:
    assert pristine.read("$AXIS_ACT") == HOME_AXIS
    assert pristine.read("$AXIS_ACT_MEAS") == HOME_AXIS
    assert pristine.read("$POS_ACT") == HOME_POS
    assert pristine.read("$POS_ACT_MES") == HOME_POS
    assert pristine.read("MYAXIS") == HOME_AXIS


def test_members_elements_and_case_insensitive_names(pristine: VariableStore) -> None:
    assert pristine.read("$POS_ACT.X") == "525.000"
    assert pristine.read("  $pos_act.x ") == "525.000"
    assert pristine.read("$Axis_Act.a2") == "-90.0000"
    assert pristine.read("$POS_ACT.S") == "2"
    assert pristine.read("$TORQUE_AXIS_ACT[2]") == "-24.7800"
    assert pristine.read("$torque_axis_max[1]") == "334.800"
    assert pristine.read("$SOFTN_END[2]") == "-190.000"
    assert pristine.read("$LOAD.CM.X") == "0.0"
    assert pristine.read("$load.j") == "{INERTIA: X 0.0, Y 0.0, Z 0.0}"
    assert pristine.read("$MODE_OP") == "#AUT"
    assert pristine.read("$PRO_STATE0") == "#P_ACTIVE"
    assert pristine.read("$OV_PRO") == "100"
    assert pristine.read("$DRIVES_ON") == "TRUE"
    assert pristine.read("$OUT[4096]") == "FALSE"
    assert pristine.read("$VEL") == "{CP: CP 2.00000, ORI1 400.000, ORI2 400.000}"


def test_whole_arrays_have_a_trailing_space_and_char_arrays_are_quoted(
    pristine: VariableStore,
) -> None:
    assert pristine.read("$TORQUE_AXIS_ACT[]") == (
        "0.0 -24.7800 -25.5000 -0.800000 -0.600000 0.0 0.0 0.0 0.0 0.0 0.0 0.0 "
    )
    assert pristine.read("$MOT_TEMP[]") == "300 300 300 300 300 300 0 0 0 0 0 0 "
    assert pristine.read("$MODEL_NAME[]") == '"#KR6R900SIXX C4SR FLR"'
    assert pristine.read("$MODEL_NAME[2]") == '"K"'
    assert pristine.read("MYSTRING[]") == '""'
    assert pristine.read("@PROXY_TYPE") == "KUKAVARPROXY EMULATOR"


@pytest.mark.parametrize(
    "name",
    [
        "NOPE", "", "   ", "$OUT[", "$OUT[0]", "$OUT[4097]", "$OUT[1,1]", "$OUT", "$OV_PRO[1]",
        "$OV_PRO[]", "MYAXIS.Q", "MYAXIS.A1.X", "MYE6POS", "MYE6POS.X", "MYE6ARRAY[1]",
        "MYE6ARRAY[]", "MYE6ARRAY[513]", "$MODEL_NAME", "$MODEL_NAME[33]", "MYSTRING[1]",
        "$TORQUE_AXIS_ACT[].X", "$POS_ACT X", "@PROXY_TYPE.X", "PING",
    ],
)  # fmt: skip
def test_unknown_out_of_bounds_and_uninitialised_are_unknown(
    pristine: VariableStore, name: str
) -> None:
    with pytest.raises(UnknownVariable) as info:
        pristine.read(name)
    assert info.value.name == name


# --- writes -----------------------------------------------------------------------------------
def test_write_echoes_the_text_and_reads_back_krc4_text(store: VariableStore) -> None:
    assert store.write("$OV_PRO", "50") == "50"
    assert store.read("$ov_pro") == "50"
    assert store.write("myaxis.a3", " 45.5") == " 45.5"
    assert store.read("MYAXIS.A3") == "45.5000"
    assert store.read("MYAXIS").startswith("{E6AXIS: A1 0.0, A2 -90.0000, A3 45.5000, A4 0.0,")
    store.write("MYREAL", "1339.90503")
    assert store.read("MYREAL") == "1339.90503"


def test_partial_aggregates_change_only_named_members(store: VariableStore) -> None:
    store.write("MYPOS", "{X 10, Y 20.5}")
    assert store.read("MYPOS") == (
        "{POS: X 10.0000, Y 20.5000, Z 0.0, A 0.0, B 0.0, C 0.0, S 2, T 2}"
    )
    store.write("MYPOS", "{POS: Z -5, S 6}")
    assert store.read("MYPOS") == (
        "{POS: X 10.0000, Y 20.5000, Z -5.00000, A 0.0, B 0.0, C 0.0, S 6, T 2}"
    )
    store.write("$LOAD", "{M 6.0, CM {Z 50.0}}")
    assert store.read("$LOAD") == (
        "{LOAD: M 6.00000, CM {FRAME: X 0.0, Y 0.0, Z 50.0000, A 0.0, B 0.0, C 0.0},"
        " J {INERTIA: X 0.0, Y 0.0, Z 0.0}}"
    )
    store.write("$LOAD.CM.X", "180")
    assert store.read("$LOAD.CM") == "{FRAME: X 180.000, Y 0.0, Z 50.0000, A 0.0, B 0.0, C 0.0}"


def test_uninitialised_struct_and_array_elements_fill_member_by_member(
    store: VariableStore,
) -> None:
    store.write("MYE6ARRAY[3]", "{A2 2.0}")
    assert store.read("MYE6ARRAY[3]") == "{E6AXIS: A2 2.00000}"
    store.write("MYE6ARRAY[3].A1", "1")
    assert store.read("MYE6ARRAY[3]") == "{E6AXIS: A1 1.00000, A2 2.00000}"  # declaration order
    assert store.read("mye6array[3].a1") == "1.00000"
    with pytest.raises(UnknownVariable):
        store.read("MYE6ARRAY[3].A3")
    store.write("MYE6POS.S", "2")
    assert store.read("MYE6POS") == "{E6POS: S 2}"
    store.write("MYPOSARRAY[512]", "{FRAME: X 1, Y 2, Z 3, A 4, B 5, C 6}")
    assert store.read("MYPOSARRAY[512].C") == "6.00000"


def test_char_arrays(store: VariableStore) -> None:
    store.write("MYSTRING[]", '"hello"')
    assert store.read("MYSTRING[]") == '"hello"'
    assert store.read("MYSTRING[1]") == '"h"'
    with pytest.raises(UnknownVariable):
        store.read("MYSTRING[6]")  # beyond the text
    store.write("MYSTRING[1]", '"J"')
    store.write("MYSTRING[8]", '"!"')
    assert store.read("MYSTRING[]") == '"Jello  !"'
    for name, text in [
        ("MYSTRING[]", '"' + "x" * 33 + '"'),
        ("MYSTRING[2]", '"ab"'),
        ("MYSTRING[33]", '"a"'),
        ("MYSTRING", '"abc"'),
        ("MYSTRING[]", "abc"),
        ("MYSTRING[]", '"é€"'),
    ]:
        with pytest.raises(WriteRefused):
            store.write(name, text)
    assert store.read("MYSTRING[]") == '"Jello  !"'
    store.write("MYSTRING[]", '"' + "x" * 32 + '"')  # exactly the declared length


@pytest.mark.parametrize(
    ("name", "text", "reason"),
    [
        ("$AXIS_ACT", HOME_AXIS, "read-only"),
        ("$AXIS_ACT.A1", "1.0", "read-only"),
        ("$POS_ACT", "{X 1}", "read-only"),
        ("$OUT[1]", "TRUE", "read-only"),
        ("$IN[1]", "TRUE", "read-only"),
        ("$MODE_OP", "#T1", "read-only"),
        ("$TORQUE_AXIS_ACT[2]", "0.0", "read-only"),
        ("$ROBNAME[]", '"X"', "read-only"),
        ("@PROXY_TYPE", "x", "read-only"),
        ("NOPE", "1", "unknown variable"),
        ("MYINT", "TRUE", "expected an INT"),
        ("MYINT", "1.5", "expected an INT"),
        ("MYINT", "2147483648", "32-bit"),
        ("MYBOOL", "1", "BOOL"),
        ("MYREAL", '"x"', "REAL"),
        ("MYREAL", "1e39", "float32"),
        ("MYREAL", "", "empty"),
        ("MYAXIS", "{X 1}", "E6AXIS has no member X"),
        ("MYAXIS", "{A1 1, A2 TRUE}", "REAL"),
        ("MYAXIS", "{A1 1", "'}'"),
        ("MYAXIS.A1", "{A1 1}", "REAL"),
        ("MYAXIS.Q", "1", "no member Q"),
        ("MYAXIS.A1.B", "1", "no members"),
        ("MYE6ARRAY[1]", "1.0", "struct"),
        ("MYE6ARRAY[0]", "{A1 1}", "out of bounds"),
        ("MYE6ARRAY[513]", "{A1 1}", "out of bounds"),
        ("MYE6ARRAY[1,1]", "{A1 1}", "needs 1 indices"),
        ("MYE6ARRAY", "{A1 1}", "needs an index"),
        ("MYE6ARRAY[]", "{A1 1}", "whole-array"),
        ("MYINT[1]", "1", "not an array"),
        ("$OV_PRO", "101", "out of range 0..100"),
        ("$OV_PRO", "-1", "out of range"),
        ("$ADVANCE", "6", "out of range 0..5"),
        ("$VEL_AXIS[3]", "150", "out of range"),
        ("$OV_PRO", "50 50", "unexpected text"),
        ("$POS_ACT X", "1", "not a variable name"),
    ],
)
def test_refused_writes_change_nothing(
    pristine: VariableStore, store: VariableStore, name: str, text: str, reason: str
) -> None:
    before = store.snapshot()
    with pytest.raises(WriteRefused) as info:
        store.write(name, text)
    assert info.value.name == name
    assert reason in info.value.reason
    assert store.snapshot() == before
    assert store.read("MYAXIS") == pristine.read("MYAXIS")


def test_int_and_enum_ranges(store: VariableStore) -> None:
    store.write("$OV_PRO", "0")
    store.write("$OV_PRO", "100")
    store.write("$OV_PRO", "50.0")  # a KRC converts integral REAL text (JOpenShowVar sends it)
    assert store.read("$OV_PRO") == "50"
    store.write("MYINT", "-2147483648")
    store.declare("MYMODE", "MODE_OP", init="#T1")
    store.write("mymode", "#ex")
    assert store.read("MYMODE") == "#EX"
    with pytest.raises(WriteRefused, match="not a value of ENUM MODE_OP"):
        store.write("MYMODE", "#FAST")
    with pytest.raises(WriteRefused, match="ENUM"):
        store.write("MYMODE", "3")


def test_strict_store_wants_plain_int_text() -> None:
    strict = VariableStore(strict=True, default_config=False)
    with pytest.raises(WriteRefused, match="plain decimal"):
        strict.write("$OV_PRO", "50.0")
    strict.write("$OV_PRO", " 50 ")
    assert strict.read("$OV_PRO") == "50"


def test_ranges_on_members_and_two_dimensional_arrays(store: VariableStore) -> None:
    store.declare("SPEEDS", "CP", init="{CP 1.0, ORI1 10.0, ORI2 10.0}", ranges={"CP": (0, 3)})
    store.write("SPEEDS.CP", "2.5")
    with pytest.raises(WriteRefused, match=r"SPEEDS.CP 4.0 out of range"):
        store.write("SPEEDS", "{CP 4.0}")
    store.declare("GRID", "INT", (2, 3), init="0")
    store.write("GRID[2,3]", "7")
    assert store.read("GRID[2,3]") == "7" and store.read("GRID[1,3]") == "0"
    assert store.get("GRID") == [0, 0, 0, 0, 0, 7]
    with pytest.raises(UnknownVariable):
        store.read("GRID[]")  # only 1-D arrays print whole
    with pytest.raises(WriteRefused, match="out of bounds"):
        store.write("GRID[3,1]", "1")


def test_reads_are_cached_but_never_stale(store: VariableStore) -> None:
    assert store.read("MYINT") == "0"
    store.write("MYINT", "5")
    assert store.read("MYINT") == "5"
    store.set_system("$AXIS_ACT.A1", 12.5)
    assert store.read("$AXIS_ACT.A1") == "12.5000"
    assert store.read("$AXIS_ACT").startswith("{E6AXIS: A1 12.5000, A2 -90.0000,")


# --- typed interface ----------------------------------------------------------------------------
def test_set_system_bypasses_read_only_and_checks_types(store: VariableStore) -> None:
    store.set_system("$AXIS_ACT", E6Axis(a1=10.0, a2=-80.0, a3=100.0, a4=20.0, a5=30.0, a6=40.0))
    assert store.read("$AXIS_ACT") == (
        "{E6AXIS: A1 10.0000, A2 -80.0000, A3 100.000, A4 20.0000, A5 30.0000, A6 40.0000,"
        " E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
    )
    store.set_system("$TORQUE_AXIS_ACT", [np.float32(1.5)] * 6 + [0.0] * 6)
    assert store.read("$TORQUE_AXIS_ACT[1]") == "1.50000"
    store.set_system("$OUT[3]", True)
    store.set_system("$MODE_OP", KrlEnum("T1"))
    store.set_system("$ROBNAME[]", "KR6 #2")
    store.set_system("$POS_ACT", Struct(None, {"X": 551.972229, "S": 5}))
    store.set_system("$POS_ACT.S", np.int64(6))
    assert store.read("$POS_ACT.X") == "551.972229" and store.read("$POS_ACT.S") == "6"
    assert (store.read("$OUT[3]"), store.read("$MODE_OP")) == ("TRUE", "#T1")
    assert store.read("$ROBNAME[]") == '"KR6 #2"'
    bad: list[tuple[str, object]] = [
        ("$OUT[3]", 1),
        ("$OV_PRO", 1.0),
        ("$OV_PRO", 101),
        ("$MODE_OP", KrlEnum("FAST")),
        ("$TOOL", E6Axis(a1=1.0)),
        ("$TORQUE_AXIS_ACT", [0.0] * 11),
        ("$TORQUE_AXIS_ACT[1]", float("nan")),
        ("$ROBNAME[]", "x" * 33),
    ]
    before = store.snapshot()
    for name, value in bad:
        with pytest.raises(WriteRefused):
            store.set_system(name, value)
    assert store.snapshot() == before
    with pytest.raises(UnknownVariable):
        store.set_system("$NOPE", 1)


def test_get_returns_typed_values(pristine: VariableStore) -> None:
    assert pristine.get("$AXIS_ACT") == E6Axis(
        a1=0.0, a2=-90.0, a3=90.0, a4=0.0, a5=0.0, a6=0.0, e1=0, e2=0, e3=0, e4=0, e5=0, e6=0
    )
    assert pristine.get("$TOOL") == Frame(x=0, y=0, z=0, a=0, b=0, c=0)
    assert pristine.get("$VEL_AXIS") == [100] * 12
    assert pristine.get("$OV_PRO") == 100
    assert pristine.get("$ROBNAME[]") == "KR6-EMULATOR"
    with pytest.raises(UnknownVariable):
        pristine.get("MYE6ARRAY")  # elements never written


def test_names_overrides_info_and_declare() -> None:
    store = VariableStore(
        overrides={"$mode_op": "#T1", "$SOFTP_END": ["1.0"] * 12},
        info={"@PROXY_VERSION": "9.9"},
    )
    assert store.read("$MODE_OP") == "#T1"
    assert store.read("$SOFTP_END[12]") == "1.00000"
    assert store.read("@PROXY_VERSION") == "9.9"
    names = store.names()
    assert names == sorted(names)
    assert {"$AXIS_ACT", "MYAXIS", "MYE6ARRAY", "PATH_START", "@PROXY_TYPE"} <= set(names)
    assert store.is_read_only("$AXIS_ACT.A1") and not store.is_read_only("MYAXIS")
    with pytest.raises(KeyError):
        VariableStore(overrides={"$NOT_A_SYSVAR": "1"})
    with pytest.raises(ValueError, match="already declared"):
        store.declare("$AXIS_ACT", "E6AXIS")
    with pytest.raises(KrlValueError):
        store.declare("X1", "NO_SUCH_TYPE")
    with pytest.raises(ValueError, match="initial value"):
        store.declare("X2", "INT", init="TRUE")
    store.declare("C1", "CHAR", init='"a"')
    store.declare("TXT", "char[4]", init='"abcd"')
    assert (store.read("C1"), store.read("TXT[]")) == ('"a"', '"abcd"')
    with pytest.raises(WriteRefused, match="longer than 1"):
        store.write("C1", '"ab"')


def test_default_config_handshake_globals(pristine: VariableStore) -> None:
    for name in ("PATH_START", "PATH_BUSY", "PATH_DONE"):
        assert pristine.read(name) == "FALSE"
    assert pristine.read("PATH_COUNT") == "0" and pristine.read("PATH_INDEX") == "0"
    assert pristine.read("OUTPUT_VARS[]") == "FALSE " * 16
    assert pristine.read("MYPOS") == "{POS: X 0.0, Y 0.0, Z 0.0, A 0.0, B 0.0, C 0.0, S 2, T 2}"


# --- atomicity property ---------------------------------------------------------------------------
TARGETS = [
    "MYAXIS", "myaxis.a1", "MYPOS", "MYPOS.S", "MYE6POS", "MYE6ARRAY[2]", "MYE6ARRAY[2].A3",
    "MYPOSARRAY[1]", "$OV_PRO", "$ADVANCE", "$VEL", "$LOAD", "$LOAD.CM", "$LOAD.CM.X", "$APO",
    "$AXIS_ACT", "$OUT[5]", "MYSTRING[]", "MYSTRING[3]", "MYINT", "MYREAL", "MYBOOL",
    "$MODE_OP", "OUTPUT_VARS[16]", "OUTPUT_VARS[17]", "NOPE", "$TIMER[1]", "@PROXY_TYPE",
    "$TOOL", "$VEL_AXIS[12]",
]  # fmt: skip
FRAGMENTS = [
    "{", "}", ",", ":", " ", "X", "A1", "A3", "CM", "S", "CP", "M", "E6AXIS:", "POS:", "FRAME:",
    "1", "-2.5", "1e40", "7", "101", "99999999999", "TRUE", "#T1", "#AUT", '"ab"', '"', "[]",
]  # fmt: skip
krl_ish = st.lists(st.sampled_from(FRAGMENTS), max_size=12).map("".join)
numbers = st.one_of(
    st.integers(-200, 200).map(str),
    st.floats(-1e4, 1e4).map(repr),
    st.sampled_from(["2147483648", "1e39", "-0.0", "5E-07", "TRUE"]),
)


def aggregate(members: str, values: st.SearchStrategy[str] = numbers) -> st.SearchStrategy[str]:
    """Partial aggregates of the given members, sometimes typed, sometimes with a bad member."""
    names = st.sampled_from([*members.split(), "Q"])
    body = st.lists(st.tuples(names, values), max_size=5, unique_by=lambda kv: kv[0]).map(
        lambda kvs: ", ".join(f"{k} {v}" for k, v in kvs)
    )
    prefix = st.sampled_from(["", "", "E6AXIS: ", "POS: ", "FRAME: "])
    return st.builds("{{{}{}}}".format, prefix, body)


AXES = "A1 A2 A3 A4 A5 A6 E1 E2 E3 E4 E5 E6"
POSE = "X Y Z A B C S T E1"
LIKELY = {
    "MYAXIS": aggregate(AXES), "MYE6ARRAY[2]": aggregate(AXES), "$AXIS_ACT": aggregate(AXES),
    "MYPOS": aggregate(POSE), "MYE6POS": aggregate(POSE), "MYPOSARRAY[1]": aggregate(POSE),
    "$TOOL": aggregate(POSE), "$LOAD.CM": aggregate(POSE), "$VEL": aggregate("CP ORI1 ORI2"),
    "$APO": aggregate("CVEL CPTP CDIS CORI"),
    "$LOAD": aggregate("M CM J", st.one_of(numbers, aggregate("X Y Z A"))),
    "MYSTRING[]": st.text(max_size=40).map('"{}"'.format),
    "MYSTRING[3]": st.text(max_size=2).map('"{}"'.format),
    "MYBOOL": st.sampled_from(["TRUE", "FALSE", "true", "1"]),
    "$OUT[5]": st.sampled_from(["TRUE", "FALSE"]),
    "OUTPUT_VARS[16]": st.sampled_from(["TRUE", "FALSE"]),
    "$MODE_OP": st.sampled_from(["#T1", "#EX"]),
}  # fmt: skip
garbage = st.one_of(st.text(max_size=30), krl_ish)
# three in four texts are plausible for the target, so that accepted writes get checked too
cases = st.sampled_from(TARGETS).flatmap(
    lambda n: st.tuples(st.just(n), st.one_of(*[LIKELY.get(n, numbers)] * 3, garbage))
)


def _same(a: object, b: object) -> bool:
    if isinstance(a, int | float) and isinstance(b, int | float):
        return float(a) == float(b)
    return a == b


@settings(max_examples=300, deadline=None)
@given(case=cases)
def test_random_writes_are_all_or_nothing(case: tuple[str, str]) -> None:
    name, text = case
    store = VariableStore()
    before = store.snapshot()
    try:
        echo = store.write(name, text)
    except WriteRefused:
        assert store.snapshot() == before
        return
    assert echo == text
    after = store.snapshot()
    changed = {k for k in before if before[k] != after[k]}
    assert changed <= {name.split("[")[0].split(".")[0].upper()}
    store.read(name)  # the written value prints
    try:
        sent = parse_value(text)
    except KrlValueError:
        return
    value = store.get(name)
    if isinstance(sent, Struct) and isinstance(value, Struct):
        for member, member_value in sent.items():
            if not isinstance(member_value, Struct):
                assert _same(value[member], member_value)
