"""Snapshots without I/O: layout within KRL's limits, refusals, the KRL text, parsing replies.

The round-trip property puts random values (extremes included) into the generated structures
in the emulator's own variable store, formats them as a KRC4 would and parses them back with
the snapshot: every value comes back under its original name, and the reply never exceeds the
layout's size estimate.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kukavarproxy_emu.store import VariableStore
from pyopenshowvar import (
    E6Axis,
    KrlEnum,
    KrlValueError,
    Snapshot,
    SnapshotLimits,
    SnapshotTornError,
    Struct,
    UnknownVariableError,
)
from pyopenshowvar.core import ReadResult
from pyopenshowvar.krl import BUILTIN_TYPES, Kind, TypeRegistry
from pyopenshowvar.krl.datfile import parse_dat
from pyopenshowvar.krl.systypes import SYSTEM_TYPES
from pyopenshowvar.snapshot import KRL_KEYWORDS, read_snapshot, struc_line
from pyopenshowvar.sysvars import SYSTEM_VARIABLES

_NAME = re.compile(r"[A-Z_][A-Z0-9_]*")


def _all_names(snap: Snapshot) -> set[str]:
    names = {f"{snap.name}_SPS"}
    for part in snap.parts:
        names |= {part.variable, part.work, *(t.name for t in part.types)}
        names |= {m for t in part.types for m, _ in t.members}
    return names


def test_layout_of_system_and_user_variables() -> None:
    snap = Snapshot(
        "cell",
        ["$AXIS_ACT", "$TORQUE_AXIS_ACT[]", "$MODE_OP", "$IN[3]", "$POS_ACT.X", ("IN", "BOOL")],
    )
    assert snap.name == "CELL" and snap.read_names == ("CELL",)
    (part,) = snap.parts
    members = dict(part.types[-1].members)
    assert members["CYCLE"] == "INT" and members["AXIS_ACT"] == "E6AXIS"
    assert [members[f"TORQUE_AXIS_ACT_{i}"] for i in range(1, 13)] == ["REAL"] * 12
    # a member never takes a keyword's or a type's name
    assert members["V_MODE_OP"] == "MODE_OP" and members["V_IN"] == "BOOL"
    assert members["IN_3"] == "BOOL" and members["POS_ACT_X"] == "REAL"
    assert snap.names == (
        "$AXIS_ACT",
        "$TORQUE_AXIS_ACT[]",
        "$MODE_OP",
        "$IN[3]",
        "$POS_ACT.X",
        "IN",
    )
    dat, sub = snap.krl_dat(), snap.krl_sub()
    assert "DECL CELL_T CELL\n" in dat and "DECL CELL_T CELL_W={CYCLE 0}" in dat
    assert "    CELL_W.TORQUE_AXIS_ACT_12 = $TORQUE_AXIS_ACT[12]" in sub
    assert sub.index("CELL_W.CYCLE = CELL_W.CYCLE + 1") < sub.index("CELL = CELL_W")
    # the generated data list is valid for the emulator's parser, strictly
    store = VariableStore(strict=True)
    store.load_dat(dat)
    assert store.declaration("CELL_W") is not None


def test_long_names_stay_within_24_characters_and_unique() -> None:
    long = "A_VERY_LONG_VARIABLE_NAME_OF_A_CELL"
    snap = Snapshot("S", [(f"{long}1", "REAL"), (f"{long}2", "REAL"), (f"{long}[3]", "INT")])
    members = [m for m, _ in snap.parts[0].types[-1].members]
    assert len(set(members)) == len(members)
    assert all(len(n) <= 24 and _NAME.fullmatch(n) for n in _all_names(snap))
    with pytest.raises(ValueError, match="24"):
        Snapshot("NAME_OF_TWENTYTWO_CHAR", ["$OV_PRO"])  # NAME_OF_TWENTYTWO_CHAR_SPS: 26


@pytest.mark.parametrize(
    ("variables", "message"),
    [
        (["MYVAR"], "type of 'MYVAR' is unknown"),
        (["$PRO_NAME1[]"], "CHAR text"),
        (["$TORQUE_AXIS_ACT"], r"read it whole as '\$TORQUE_AXIS_ACT\[\]'"),
        (["$TORQUE_AXIS_ACT[13]"], "out of range"),
        (["$IN[]"], "4096 elements"),
        ([("MYARR[]", "REAL")], "give its length"),
        (["$OV_PRO", "$ov_pro"], "twice"),
        (["1ABC"], "not a KRL variable name"),
        (["$AXIS_ACT.Q"], "no member Q"),
        ([("X", "REAL[")], "not a KRL type"),
        ([], "at least one"),
    ],
)
def test_refusals_say_why(variables: list[Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Snapshot("S", variables)


def test_refuses_bad_snapshot_names_and_structures_holding_arrays() -> None:
    for bad in ("$S", "LOOP", "A-B", ""):
        with pytest.raises(ValueError, match="not a KRL name"):
            Snapshot(bad, ["$OV_PRO"])
    reg = BUILTIN_TYPES.copy()
    reg.add_struct("HOLDER", (("V", "REAL[3]"),))
    with pytest.raises(ValueError, match="only CHAR arrays"):
        Snapshot("S", [("H", "HOLDER")], registry=reg)


def test_small_limits_nest_groups_then_split_into_parts() -> None:
    names = ["$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[]", "$OV_PRO", "$VEL_ACT"]
    nested = Snapshot("N", names, limits=SnapshotLimits(struc_line=120))
    assert nested.read_names == ("N",)
    top = nested.parts[0].types[-1]
    assert top.name == "N_T" and [m for m, _ in top.members][:2] == ["CYCLE", "G1"]
    assert all(len(struc_line(t)) <= 120 for t in nested.parts[0].types)
    split = Snapshot("P", names, limits=SnapshotLimits(struc_line=120, max_text=700))
    assert split.read_names[:2] == ("P", "P2")
    assert "split by the size limits" in split.krl_dat()
    assert all(sum(slot.text_max for _, slot in p.paths) <= 700 for p in split.parts)
    with pytest.raises(ValueError, match="alone does not fit"):
        Snapshot("T", ["$LOAD"], limits=SnapshotLimits(max_text=100))


def test_parse_rejects_other_krl_and_torn_parts() -> None:
    snap = Snapshot("S", ["$OV_PRO", "$VEL_ACT"], limits=SnapshotLimits(max_text=64))
    assert snap.read_names == ("S", "S2")
    good = ["{S_T: CYCLE 7, OV_PRO 100}", "{S2_T: CYCLE 7, VEL_ACT 0.5}"]
    reading = snap.parse(good)
    assert reading.cycle == 7 and dict(reading) == {"$OV_PRO": 100, "$VEL_ACT": 0.5}
    with pytest.raises(SnapshotTornError, match=r"passes \[7, 8\]"):
        snap.parse([good[0], "{S2_T: CYCLE 8, VEL_ACT 0.5}"])
    with pytest.raises(KrlValueError, match="does not match this definition"):
        snap.parse(["{S_T: CYCLE 7, OTHER 1}", good[1]])
    with pytest.raises(KrlValueError, match="no INT CYCLE"):
        snap.parse(["{S_T: OV_PRO 100}", good[1]])


def test_read_operation_retries_torn_parts_then_gives_up() -> None:
    """The operation both clients run: driven here with the replies a controller would send."""

    class Io:
        endpoint = "robot:7000"

    snap = Snapshot("S", ["$OV_PRO", "$VEL_ACT"], limits=SnapshotLimits(max_text=64))

    def replies(c1: int, c2: int) -> dict[str, ReadResult]:
        return {
            "S": ReadResult("S", text=f"{{S_T: CYCLE {c1}, OV_PRO 50}}"),
            "S2": ReadResult("S2", text=f"{{S2_T: CYCLE {c2}, VEL_ACT 1.0}}"),
        }

    op = read_snapshot(Io(), snap, retries=2)
    call = next(op)
    assert call[0] == "read_many" and call[1] == (("S", "S2"),)
    op.send(replies(3, 4))  # torn: read again
    with pytest.raises(StopIteration) as done:
        op.send(replies(4, 4))
    assert done.value.value.cycle == 4 and done.value.value["$OV_PRO"] == 50
    op = read_snapshot(Io(), snap, retries=1)
    next(op)
    op.send(replies(1, 2))
    with pytest.raises(SnapshotTornError):
        op.send(replies(2, 3))
    single = read_snapshot(Io(), Snapshot("ONE", ["$OV_PRO"]))
    assert next(single)[0] == "read"
    with pytest.raises(UnknownVariableError, match="install its KRL"):
        single.throw(UnknownVariableError("unknown", name="ONE", endpoint="robot:7000"))


# --------------------------------------------------------------------------- round trip

_POOL: list[str | tuple[str, str]] = [
    "$AXIS_ACT", "$POS_ACT", "$POS_ACT_MES", "$VEL_ACT", "$OV_PRO", "$MODE_OP", "$PRO_STATE1",
    "$TORQUE_AXIS_ACT[]", "$TORQUE_AXIS_ACT[2]", "$MOT_TEMP[3]", "$TOOL", "$LOAD", "$APO",
    "$VEL", "$IN[7]", "$OUT[]".replace("[]", "[1]"), "$TIMER[4]", "$POS_ACT.C", "$LOAD.CM",
    ("MYPOS", "POS"), ("MYE6ARRAY[3]", "E6AXIS"), ("A_RATHER_LONG_USER_VARIABLE", "REAL"),
    ("A_RATHER_LONG_USER_VARIABLE_2", "INT"), ("FLAGS[]", "BOOL[5]"), ("STATE", "MODE_OP"),
]  # fmt: skip

_F32 = float(np.finfo(np.float32).max)
_reals = st.one_of(
    st.sampled_from([0.0, -0.0, _F32, -_F32, 1.17549435e-38, -123456.789]),
    st.floats(-_F32, _F32, allow_nan=False, width=32),
)


def _value(draw: Any, type_name: str, reg: TypeRegistry) -> Any:
    spec = reg.resolve(type_name)
    if spec.kind is Kind.REAL:
        return draw(_reals)
    if spec.kind is Kind.INT:
        return draw(st.integers(-(2**31), 2**31 - 1))
    if spec.kind is Kind.BOOL:
        return draw(st.booleans())
    if spec.kind is Kind.ENUM:
        assert spec.enum is not None
        return KrlEnum(draw(st.sampled_from(spec.enum.values)))
    assert spec.struct is not None
    members = {m: _value(draw, t, reg) for m, t in spec.struct.members}
    return Struct(spec.name, members)


def _close(a: Any, b: Any) -> bool:
    """Equal, REALs compared as the float32 a KRC holds."""
    if isinstance(a, Struct) and isinstance(b, Struct):
        return list(a.keys()) == list(b.keys()) and all(_close(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(map(_close, a, b))
    if isinstance(a, float) or isinstance(b, float):
        return bool(np.float32(a) == np.float32(b))
    return bool(a == b)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.sampled_from(_POOL), min_size=1, max_size=12, unique=True),
    st.sampled_from([(480, 4096), (120, 4096), (100, 600), (200, 300)]),
    st.data(),
)
def test_round_trip_through_the_emulator_store(
    variables: list[Any], limits: tuple[int, int], data: Any
) -> None:
    lim = SnapshotLimits(struc_line=limits[0], max_text=limits[1])
    try:
        snap = Snapshot("RT", variables, limits=lim)
    except ValueError as exc:
        assert "alone does not fit" in str(exc)  # an E6POS needs more than 300 characters
        return
    for name in _all_names(snap):
        assert len(name) <= 24 and _NAME.fullmatch(name) and name not in KRL_KEYWORDS
    store = VariableStore(strict=True, system=False, default_config=False)
    assert parse_dat(snap.krl_dat()).structs  # the emulator's parser takes it ...
    store.load_dat(snap.krl_dat())  # ... and so does its store, strictly
    reg, texts, expected = snap.registry, [], {}
    for part in snap.parts:
        values = {path: _value(data.draw, slot.type_name, reg) for path, slot in part.paths}
        groups: dict[str, dict[str, Any]] = {}
        for path, value in values.items():
            head, _, tail = path.rpartition(".")
            groups.setdefault(head, {})[tail] = value
        top = groups.pop("", {})
        for t in part.types[:-1]:
            group = next(m for m, tn in part.types[-1].members if tn == t.name)
            top[group] = Struct(t.name, groups[group])
        store.set_system(part.variable, Struct(part.type_name, {"CYCLE": 5, **top}))
        text = store.read(part.variable)
        groups_text = sum(len(t.name) + 12 for t in part.types[:-1])
        estimate = sum(s.text_max for _, s in part.paths) + len(part.type_name) + 24 + groups_text
        assert len(text) <= min(estimate, lim.max_text)
        texts.append(text)
        for path, slot in part.paths:
            expected[id(slot)] = values[path]
    reading = snap.parse(texts)
    assert reading.cycle == 5 and tuple(reading) == snap.names
    for var in snap.variables:
        want = [expected[id(s)] for s in var.slots]
        got = reading[var.name]
        assert _close(got, want if var.whole_array else want[0]), var.name
        if var.type_name == "E6AXIS":
            assert isinstance(got, E6Axis)  # typed, like read_value


def test_system_types_agree_with_the_emulator() -> None:
    shared = [sv for sv in SYSTEM_VARIABLES if sv.name in SYSTEM_TYPES]
    assert len(shared) >= 40
    for sv in shared:
        declared = sv.type_name + "".join(f"[{d}]" for d in sv.dims)
        assert SYSTEM_TYPES[sv.name] == declared, sv.name
