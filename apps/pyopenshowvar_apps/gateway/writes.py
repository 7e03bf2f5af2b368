"""``WriteVariable``: the one way to change a controller through the gateway.

Every variable node the gateway serves is read-only (a Write service call gets
BadNotWritable). A client that may change something calls the controller's ``WriteVariable``
method (in our namespace) with the variable's name and a KRL literal, and gets the proxy's
echo back. The rules are the ``kvp`` tools' own:

* the name must be listed in the robot's ``writable`` (the cell file; a motion variable needs
  ``allow_motion_writes`` too) — anything else is BadUserAccessDenied, nothing is sent;
* the literal must parse as a KRL value (BadInvalidArgument, with the parser's reason);
* it must fit the variable's current type (an INT stays an INT, a struct only gets members it
  has), checked against a fresh read before writing (BadTypeMismatch);
* a refused write is BadNotWritable with the likely reason; a robot that is not connected is
  BadNoCommunication. Nothing is retried, so a write is never applied twice.

Each accepted and refused write is logged.
"""

from __future__ import annotations

import logging
from typing import Any

from asyncua import ua

from pyopenshowvar import KrlEnum, KvpError, Struct, WriteRefusedError, parse_value
from pyopenshowvar.errors import KrlValueError

from .poller import RobotPoller

__all__ = ["WRITE_METHOD", "WriteError", "add_write_method", "type_mismatch", "write_variable"]

log = logging.getLogger(__name__)

WRITE_METHOD = "WriteVariable"
_MAX_LITERAL = 1024


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return "BOOL"
    if isinstance(value, int):
        return "INT"
    if isinstance(value, float):
        return "REAL"
    if isinstance(value, KrlEnum):
        return "ENUM"
    if isinstance(value, str):
        return "CHAR[]"
    if isinstance(value, Struct):
        return value.type_name or "STRUC"
    return "array"


def type_mismatch(current: Any, new: Any) -> str | None:
    """Why ``new`` cannot be written over ``current`` (both parsed), or None when it can."""
    if isinstance(current, float) and isinstance(new, int) and not isinstance(new, bool):
        return None  # a REAL takes an integer literal
    if isinstance(current, Struct) and isinstance(new, Struct):
        unknown = [m for m in new.members if m.upper() not in {k.upper() for k in current.members}]
        return f"{_kind(current)} has no member {', '.join(unknown)}" if unknown else None
    if _kind(current) in ("INT", "REAL", "BOOL", "ENUM", "CHAR[]") or isinstance(current, Struct):
        if _kind(new) != _kind(current) and not (
            isinstance(new, Struct) and isinstance(current, Struct)
        ):
            return f"the variable is {_kind(current)}, the value is {_kind(new)}"
    return None


class WriteError(Exception):
    """A refused WriteVariable call: the status code the client gets, and why (logged)."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


def _fail(code: int, message: str) -> WriteError:
    log.warning("WriteVariable refused: %s", message)
    return WriteError(code, message)


async def write_variable(poller: RobotPoller, name: str, literal: str) -> str:
    """Apply the rules above and write; returns the proxy's echo or raises a status error."""
    cfg = poller.cfg
    if not isinstance(name, str) or not isinstance(literal, str) or len(literal) > _MAX_LITERAL:
        raise _fail(ua.StatusCodes.BadInvalidArgument, f"{cfg.name}: bad arguments")
    if not cfg.is_writable(name):
        raise _fail(
            ua.StatusCodes.BadUserAccessDenied,
            f"{cfg.name}: {name!r} is not listed writable in the cell file",
        )
    try:
        new = parse_value(literal)
    except KrlValueError as exc:
        raise _fail(ua.StatusCodes.BadInvalidArgument, f"{cfg.name}: {literal!r}: {exc}") from None
    client = poller.client
    if client is None or not poller.connected:
        raise _fail(ua.StatusCodes.BadNoCommunication, f"{cfg.name} is not connected")
    try:
        current_text = await client.read(name)
        try:
            current = parse_value(current_text)
        except KrlValueError:
            current = None
        problem = type_mismatch(current, new) if current is not None else None
        if problem:
            raise _fail(
                ua.StatusCodes.BadTypeMismatch, f"{cfg.name}: {name} = {literal}: {problem}"
            )
        echo = await client.write(name, literal)
    except WriteRefusedError:
        raise _fail(
            ua.StatusCodes.BadNotWritable,
            f"{cfg.name}: the controller refused {name} = {literal} (read-only or out of range)",
        ) from None
    except KvpError as exc:
        raise _fail(ua.StatusCodes.BadCommunicationError, f"{cfg.name}: {exc}") from None
    log.info("WriteVariable %s: %s = %s (echo %s)", cfg.name, name, literal, echo)
    return echo


async def add_write_method(node: Any, method_id: ua.NodeId, ns: int, poller: RobotPoller) -> None:
    """Add ``WriteVariable(Variable, Value) -> Echo`` to a controller object."""

    async def handler(
        parent: ua.NodeId, variable: ua.Variant, value: ua.Variant
    ) -> list[ua.Variant] | ua.StatusCode:
        try:
            echo = await write_variable(poller, variable.Value, value.Value)
        except WriteError as exc:
            return ua.StatusCode(exc.code)
        return [ua.Variant(echo, ua.VariantType.String)]

    def arg(name: str, text: str) -> ua.Argument:
        a = ua.Argument()
        a.Name, a.DataType, a.ValueRank = name, ua.NodeId(ua.ObjectIds.String), -1
        a.Description = ua.LocalizedText(text)
        return a

    await node.add_method(
        method_id,
        ua.QualifiedName(WRITE_METHOD, ns),
        handler,
        [
            arg("Variable", "KRL variable listed writable in the cell file, e.g. $OV_PRO"),
            arg("Value", "KRL literal, e.g. 50 or {A1 10.0}"),
        ],
        [arg("Echo", "the value as the controller answered it")],
    )
