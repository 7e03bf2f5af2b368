"""Hypothesis properties of pyopenshowvar.krl: round-trips and a parser that only fails cleanly."""

from __future__ import annotations

import time
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st
from test_krl import f32

from pyopenshowvar.errors import KrlValueError
from pyopenshowvar.krl import (
    BUILTIN_TYPES,
    TYPED_STRUCTS,
    KrlEnum,
    KrlValue,
    Struct,
    format_krc4,
    format_real_krc4,
    format_value,
    parse_array,
    parse_value,
)
from pyopenshowvar.krl.parse import parse_number_list, parse_number_struct

identifiers = st.from_regex(r"[A-Za-z_$][A-Za-z0-9_$]{0,10}", fullmatch=True)
# a generic struct's type name must not be a declared type, or its members would be checked
user_type_names = identifiers.filter(lambda n: n.upper() not in BUILTIN_TYPES)
member_names = identifiers
reals = st.floats(allow_nan=False, allow_infinity=False)
reals32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
ints = st.integers(min_value=-(2**31), max_value=2**31 - 1)
texts = st.text(st.characters(max_codepoint=255, exclude_characters='"'), max_size=20)
enums = identifiers.map(KrlEnum)
scalars: st.SearchStrategy[KrlValue] = st.one_of(st.booleans(), ints, reals, texts, enums)


def typed_structs(real: st.SearchStrategy[float]) -> st.SearchStrategy[Struct]:
    """Any pose struct with any subset of its members."""

    def build(cls: Any) -> st.SearchStrategy[Struct]:
        fields = {m.lower(): (ints if m in cls.INT_MEMBERS else real) for m in cls.MEMBERS}
        return st.fixed_dictionaries({}, optional=fields).map(lambda kw: cls(**kw))

    return st.one_of([build(c) for c in TYPED_STRUCTS.values()])


def generic_structs(children: st.SearchStrategy[KrlValue]) -> st.SearchStrategy[Struct]:
    return st.builds(
        Struct,
        st.none() | user_type_names,
        st.dictionaries(member_names.map(str.upper), children, max_size=4),
    )


values: st.SearchStrategy[KrlValue] = st.recursive(
    scalars | typed_structs(reals),
    lambda children: generic_structs(children),
    max_leaves=12,
)


@given(values)
def test_format_value_roundtrips(v: KrlValue) -> None:
    assert parse_value(format_value(v)) == v


@given(st.lists(scalars | typed_structs(reals), min_size=2, max_size=8))
def test_lists_roundtrip(v: list[KrlValue]) -> None:
    assert parse_value(format_value(v)) == v
    # float-free arrays also survive the KRC4 form (a CHAR array is one text, so no str here)
    exact = [e for e in v if not isinstance(e, float | Struct | str)]
    if exact:
        assert parse_array(format_krc4(exact)) == exact


@given(st.lists(reals32, min_size=1, max_size=12))
def test_krc4_arrays_roundtrip_as_float32(v: list[float]) -> None:
    text = format_krc4(v)
    assert text.endswith(" ") and text.count(" ") == len(v)
    back = parse_array(text, "REAL")
    assert isinstance(back, list)
    assert [f32(x) for x in back if isinstance(x, float)] == [f32(x) for x in v]
    assert len(back) == len(v)


def _f32_struct(s: Struct) -> Struct:
    return s._with({k: f32(v) if isinstance(v, float) else v for k, v in s.items()})


@given(typed_structs(reals32))
def test_format_krc4_roundtrips_to_float32(v: Struct) -> None:
    back = parse_value(format_krc4(v))
    assert isinstance(back, Struct)
    assert _f32_struct(back) == _f32_struct(v)
    assert list(back.keys()) == list(v.keys())


@given(reals32)
def test_format_real_krc4_is_exact_for_float32(x: float) -> None:
    text = format_real_krc4(x)
    assert f32(float(text)) == f32(x)
    assert "." in text  # %#g always keeps the decimal point
    assert "e" not in text
    # the 6-digit form is preferred whenever it is exact
    digits = sum(c.isdigit() for c in text.split("E")[0].lstrip("-0."))
    assert text == "0.0" or digits <= 9


@given(reals)
def test_format_real_krc4_any_double_rounds_to_float32(x: float) -> None:
    try:
        text = format_real_krc4(x)
    except KrlValueError:
        assert abs(x) > 3.4e38
        return
    assert f32(float(text)) == f32(x)


@given(reals)
def test_write_literal_is_shortest_exact(x: float) -> None:
    text = format_value(x)
    assert float(text) == x
    assert "." in text and "e" not in text
    assert parse_value(text, "REAL") == x


@settings(max_examples=300)
@given(st.text())
def test_parser_only_raises_krl_value_error(text: str) -> None:
    for type_name in (None, "E6POS", "REAL[]"):
        try:
            parse_value(text, type_name)
        except KrlValueError:
            pass


_ALPHABET = st.sampled_from([*'{}:,# "\t.-+eE0123456789XYZAS_', "TRUE", "E6POS", "1.5"])


@settings(max_examples=300)
@given(st.lists(_ALPHABET, max_size=60).map("".join))
def test_parser_on_krl_like_garbage(text: str) -> None:
    try:
        parse_value(text)
    except KrlValueError:
        pass
    try:
        parse_array(text)
    except KrlValueError:
        pass


def test_parser_is_linear_on_pathological_input() -> None:
    # CPU time, not wall time: the property is the work done (no backtracking blow-up), and a
    # loaded machine stretches the wall clock without the parser doing more
    start = time.thread_time()
    for text in (
        "1" * 50_000 + "x",
        "1." + "0" * 50_000 + "e",
        "{A " * 20 + "1" * 10_000,
        "1" + " " * 100_000,
        '"' + "a" * 50_000,
        "1e" * 20_000,
        "-" * 50_000,
        "1 " * 20_000 + "#",
    ):
        try:
            parse_value(text)
        except KrlValueError:
            pass
    assert time.thread_time() - start < 1.0


def test_e6pos_parse_is_fast() -> None:
    """A guard against a parser many times slower, not a speed figure (bench/codec.py measures
    E6POS parsing): the CPU time this thread spent, which other processes on a loaded machine
    do not stretch as they do the wall clock."""
    text = (
        "{E6POS: X 284.994965, Y -694.394653, Z 41.2478294, A 131.430344, B -0.0191543195, "
        "C 179.992111, S 2, T 10, E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
    )
    n = 2000
    start = time.thread_time()
    for _ in range(n):
        parse_value(text)
    per_call = (time.thread_time() - start) / n
    assert per_call < 500e-6  # typically ~30 µs


# --- the fast paths (parse_number_list, parse_number_struct): they agree with parse_value ---
# wherever they answer, answer for the texts a KRC prints, and fall back (None) on the rest.

_numbers = st.one_of(ints, reals32, st.floats(-1e300, 1e300))
_blanks = st.sampled_from([" ", "  ", "\t", " \t"])


def _number_text(v: int | float, style: int) -> str:
    if isinstance(v, int):
        return str(v)
    if style == 0 and abs(v) <= 3.4e38:  # the KRC4's own format (float32 range)
        return format_real_krc4(v)
    return repr(v) if style == 1 else f"{v:.9E}"


@given(st.lists(st.tuples(_numbers, st.integers(0, 2)), min_size=1, max_size=14), _blanks)
def test_number_list_fast_path_agrees_with_parse_value(items: list[Any], sep: str) -> None:
    text = sep.join(_number_text(v, style) for v, style in items)
    fast = parse_number_list(text)
    slow = parse_value(text)
    assert fast == [float(x) for x in (slow if isinstance(slow, list) else [slow])]


@given(
    st.dictionaries(member_names.map(str.upper), st.tuples(_numbers, st.integers(0, 2)),
                    min_size=1, max_size=12),
    st.none() | user_type_names,
)  # fmt: skip
def test_number_struct_fast_path_agrees_with_parse_value(
    members: dict[str, Any], type_name: str | None
) -> None:
    body = ", ".join(f"{k} {_number_text(v, style)}" for k, (v, style) in members.items())
    text = "{" + (f"{type_name}: " if type_name else "") + body + "}"
    fast = parse_number_struct(text)
    slow = parse_value(text)
    assert isinstance(slow, Struct)
    assert fast == {k: float(v) for k, v in slow.members.items()}


@settings(max_examples=300)
@given(st.lists(_ALPHABET, max_size=60).map("".join))
def test_fast_paths_answer_only_what_parse_value_accepts(text: str) -> None:
    for fast in (parse_number_list, parse_number_struct):
        got = fast(text)
        if got is not None:  # then parse_value accepts it and means the same numbers
            slow = parse_value(text)
            if isinstance(got, dict):
                assert isinstance(slow, Struct)
                assert got == {k: float(v) for k, v in slow.members.items()}
            else:
                assert got == [float(x) for x in (slow if isinstance(slow, list) else [slow])]


def test_fast_paths_fall_back_on_anything_else() -> None:
    krc4 = (
        "{E6AXIS: A1 3.13784176E-06, A2 -90.0000381, A3 90.0000229, A4 0.0, A5 -1.3E-05, "
        "A6 0.0, E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
    )
    assert parse_number_struct(krc4) == {
        k.upper(): float(v)
        for k, v in parse_value(krc4).members.items()  # type: ignore[union-attr]
    }
    assert parse_number_list("-0.236844778 -24.7430096 0.0 300") == [
        -0.236844778, -24.7430096, 0.0, 300.0
    ]  # fmt: skip
    for text in ("", " ", "1e999 2", "1" * 400, "1.5x", "1..2", "TRUE", "#P_ACTIVE",
                 '"text"', "{X 1}", "1 {X 1}", "1,2"):  # fmt: skip
        assert parse_number_list(text) is None, text
    for text in ("{}", "{X 1, X 2}", "{X 1e999}", "{X TRUE}", "{X {A 1}}", "{X 1,}", "{X 1",
                 "{E6POS: X 1.5, S 'B010'}", " {X 1}", "{X: 1}", "1"):  # fmt: skip
        assert parse_number_struct(text) is None, text
