"""The fast path for plain option values gives typer's own results, or leaves the value to typer."""

from __future__ import annotations

from typing import Any

import pytest
import typer
from hypothesis import given, settings
from hypothesis import strategies as st
from pyopenshowvar_apps.cli import app
from pyopenshowvar_apps.fastparams import DECLINE, FastCoercion, fast_value
from typer.main import get_command

pydantic = pytest.importorskip("pydantic")
adapters = pytest.importorskip("typer._adapters")  # typer's pydantic conversion (typer 0.2x)
from typer.models import OptionInfo  # noqa: E402

KINDS: list[Any] = [str, int, float, bool, list[str], list[int]]
_TYPER = {repr(kind): adapters.try_build_adapter(kind, OptionInfo()) for kind in KINDS}

numbers = st.from_regex(r"\A[-+ ]?[0-9_]{1,20}(\.[0-9]{0,17})?([eE][-+]?[0-9]{1,3})?\Z")
values = st.one_of(
    numbers,
    st.text(max_size=12),
    st.integers(),
    st.floats(allow_nan=False),
    st.booleans(),
    st.none(),
    st.lists(st.one_of(numbers, st.text(max_size=6)), max_size=3).map(tuple),
)


def _typer_result(kind: Any, value: Any) -> Any:
    try:
        return _TYPER[repr(kind)].validate_python(value)
    except pydantic.ValidationError:
        return "<refused>"


@settings(max_examples=300, deadline=None)
@given(kind=st.sampled_from(KINDS), value=values)
def test_the_fast_path_agrees_with_typer(kind: Any, value: Any) -> None:
    fast = fast_value(kind, value)
    if fast is DECLINE:
        return
    expected = _typer_result(kind, value)
    assert fast == expected and type(fast) is type(expected), (kind, value)
    if isinstance(fast, float):
        assert repr(fast) == repr(expected)  # -0.0 stays -0.0


def test_the_common_values_take_the_fast_path() -> None:
    assert fast_value(int, "7001") == 7001 and fast_value(int, 7000) == 7000
    assert fast_value(float, "0.5") == 0.5 and fast_value(float, 2) == 2.0
    assert fast_value(str, "$OV_PRO") == "$OV_PRO"
    assert fast_value(list[str], ("$OV_PRO", "$AXIS_ACT")) == ["$OV_PRO", "$AXIS_ACT"]
    for odd in ("7_000", " 7000", "+7", "1e3", "0x10", "٣"):
        assert fast_value(int, odd) is DECLINE, odd


def test_what_the_fast_path_declines_typer_converts_or_refuses() -> None:
    group: Any = get_command(app)
    port = next(p for p in group.params if p.name == "port")
    assert isinstance(port._runtime_param, FastCoercion)
    ctx = group.make_context("kvp", ["read", "x"], resilient_parsing=True)
    assert port._runtime_param.coerce(" 7001", port, ctx) == 7001  # pydantic's lax rules
    with pytest.raises(typer.BadParameter, match="valid integer"):
        port._runtime_param.coerce("seven", port, ctx)
