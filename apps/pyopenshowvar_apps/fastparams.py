"""A fast path for typer's conversion of plain command-line values (``kvp read`` start-up).

typer (0.2x) converts every option and argument through a pydantic ``TypeAdapter``: the first
conversion imports pydantic and building the adapters of ``kvp read``'s few parameters takes
about 100 ms, a third of the command's start-up. Nearly every value a shell passes is plain
text for a ``str``, digits for an ``int``, a decimal for a ``float``, or a default that already
has its type (a flag's bool, the ``--help`` flag's None); for those the result is known
without pydantic. :class:`FastCoercion` converts
exactly those and hands anything else (``7_000``, `` 7000``, ``1e3``, bytes, a parser, a range,
a path...) to typer's own conversion, built on first need, so results, error messages and
exit codes stay typer's (tests/test_cli_fastparams.py compares the two on random input).

It plugs into typer's per-parameter hook (``_runtime_param``, which typer fills lazily); a
typer without that hook (older versions convert with click types, no pydantic) is left alone.
"""

from __future__ import annotations

import re
from typing import Any, get_args, get_origin

__all__ = ["DECLINE", "FastCoercion", "fast_value", "speed_up"]

#: :func:`fast_value` leaves this value to typer.
DECLINE: Any = object()

_INT = re.compile(r"-?[0-9]{1,18}\Z", re.ASCII)
_FLOAT = re.compile(r"-?[0-9]{1,15}(\.[0-9]{1,15})?\Z", re.ASCII)


def _plain(kind: type, value: Any) -> Any:
    if kind is str:
        return value if type(value) is str else DECLINE
    if kind is bool:  # flags (--help, --json) arrive as bools; text ("yes") is typer's
        return value if type(value) is bool else DECLINE
    if kind is int:
        if type(value) is int:
            return value
        return int(value) if type(value) is str and _INT.match(value) else DECLINE
    if kind is float:
        if type(value) is float:
            return value
        if type(value) is int:
            return float(value)
        return float(value) if type(value) is str and _FLOAT.match(value) else DECLINE
    return DECLINE


def fast_value(annotation: Any, value: Any) -> Any:
    """``value`` converted for ``annotation`` (str, int, float, bool or a list of one), or DECLINE."""
    if get_origin(annotation) is list:
        (item,) = get_args(annotation) or (None,)
        if not isinstance(value, list | tuple):
            return DECLINE
        items = [_plain(item, v) for v in value]
        return DECLINE if any(v is DECLINE for v in items) else items
    return _plain(annotation, value)


def _eligible(param: Any) -> bool:
    descriptor = getattr(param, "type_descriptor", None)
    info = getattr(descriptor, "parameter_info", None)
    if descriptor is None or info is None or getattr(param, "_runtime_param", 1) is not None:
        return False
    annotation = descriptor.annotation
    kinds = get_args(annotation) if get_origin(annotation) is list else (annotation,)
    plain = len(kinds) == 1 and kinds[0] in (str, int, float, bool)
    limits = (getattr(info, name, None) for name in ("parser", "min", "max", "clamp"))
    return plain and not any(limits) and getattr(descriptor, "file_annotation", None) is None


class FastCoercion:
    """Stands in for typer's converter of one parameter: plain values here, the rest typer's."""

    def __init__(self, annotation: Any) -> None:
        self._annotation = annotation
        self._typer: Any = None

    def coerce(self, value: Any, param: Any, ctx: Any) -> Any:
        multi = param.multiple or param.nargs == -1
        if value is None:  # as typer: a missing value stays None (or empty for a list)
            return () if multi else None
        result = (
            DECLINE if multi and isinstance(value, str) else fast_value(self._annotation, value)
        )
        if result is not DECLINE:
            return result
        if self._typer is None:
            from typer._coercion import build_runtime_param

            self._typer = build_runtime_param(param.type_descriptor)
        return self._typer.coerce(value, param=param, ctx=ctx)


def _fast(param: Any) -> None:
    if _eligible(param):
        param._runtime_param = FastCoercion(param.type_descriptor.annotation)


def speed_up(command: Any) -> Any:
    """Give ``command``'s plain parameters the fast path (idempotent); returns ``command``.

    The ``--help`` option is made by the command on first use, so ``get_params`` is wrapped
    to cover it too.
    """
    for param in getattr(command, "params", ()):
        _fast(param)
    plain_get_params = getattr(command, "get_params", None)
    if plain_get_params is not None and "get_params" not in vars(command):

        def get_params(ctx: Any) -> Any:
            params = plain_get_params(ctx)
            for param in params:
                _fast(param)
            return params

        command.get_params = get_params
    return command
