"""What a robot's KRL texts become in the gateway: typed values, then OPC UA variants.

The moving robot's texts come in the fixed format a KRC prints and are parsed by the parser's
fast paths (a tenth of ``parse_value``'s time); anything else by ``parse_value``, and a text it
cannot parse stays a text. An extra variable of the cell file is published typed when it is a
scalar, as its KRL text otherwise.
"""

from __future__ import annotations

from typing import Any

from pyopenshowvar import KrlEnum, parse_value
from pyopenshowvar.errors import KrlValueError
from pyopenshowvar.krl.parse import parse_number_list, parse_number_struct

from . import ua

__all__ = ["SCALAR_TYPES", "parse_text", "variant_of"]

_V = ua.VariantType
#: The moving robot's texts, in the fixed format a KRC prints: parsed by the fast paths (a
#: tenth of parse_value's time), anything unexpected by parse_value.
_FAST_PARSE = {
    "$AXIS_ACT": parse_number_struct,
    "$VEL_AXIS_ACT[]": parse_number_list,
    "$TORQUE_AXIS_ACT[]": parse_number_list,
    "$CURR_ACT[]": parse_number_list,
    "$MOT_TEMP[]": parse_number_list,
}

#: The MotionDevice's scalar nodes and their OPC UA types.
SCALAR_TYPES = (
    ("override", _V.Double),
    ("in_control", _V.Boolean),
    ("mode", _V.Int32),
    ("estop", _V.Boolean),
    ("pstop", _V.Boolean),
    ("estop_fn_active", _V.Boolean),
    ("opsafe_fn_active", _V.Boolean),
    ("opsafe_fn_enabled", _V.Boolean),
    ("stopmess_fn_active", _V.Boolean),
    ("stopmess_fn_enabled", _V.Boolean),
)


def parse_text(name: str, text: str) -> Any:
    """The value of variable ``name``'s reply ``text`` (fast path first, then the parser)."""
    fast = _FAST_PARSE.get(name)
    value = fast(text) if fast is not None else None
    return _parse(text) if value is None else value


def _parse(text: str) -> Any:
    try:
        return parse_value(text)
    except (KrlValueError, ValueError):
        return text


def variant_of(value: Any, text: str) -> ua.Variant:
    """An extra variable's value: scalars typed, anything else as its KRL text."""
    if isinstance(value, bool):
        return ua.Variant(value, _V.Boolean)
    if isinstance(value, int):
        return ua.Variant(value, _V.Int32)
    if isinstance(value, float):
        return ua.Variant(value, _V.Double)
    if isinstance(value, KrlEnum):
        return ua.Variant(str(value), _V.String)
    if isinstance(value, str):
        return ua.Variant(value, _V.String)
    return ua.Variant(text, _V.String)
