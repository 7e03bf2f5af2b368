"""``WriteVariable``: the one way to change a controller through the gateway.

Every variable node the gateway serves is read-only (a Write service call gets
BadNotWritable). A client that may change something calls the controller's ``WriteVariable``
method (in our namespace) with the variable's name and a KRL literal, and gets the proxy's
echo back, plus the program stop the write caused, if any. The rules are ``kvp write``'s own
(:mod:`pyopenshowvar_apps.writecheck`, shared with the REPL and the monitor):

* the name must be listed in the robot's ``writable`` (the cell file; a motion variable needs
  ``allow_motion_writes`` too, the cell file's equivalent of the monitor's confirmation),
  case-insensitively but otherwise as a whole (:meth:`~.cell.RobotConfig.writable_name`:
  ``$OV _PRO`` or ``$OV_PRO[]`` is not ``$OV_PRO``) — anything else is BadUserAccessDenied and
  nothing is sent; the name sent is the cell file's;
* the literal must parse as a KRL value (BadInvalidArgument, with the parser's reason);
* a write the controller refuses is BadTypeMismatch when the value does not fit the variable's
  type, else BadNotWritable, the likely reason logged as ``kvp write`` prints it;
* while the robot program runs, ``$PRO_STATE1``/``$STOPMESS`` are watched for a short window
  after the write: a write that stops the program (e.g. beyond a software limit) still
  returns its echo, with the stop described in the second output (``kvp write``'s exit 7);
* a robot that is not connected is BadNoCommunication. Nothing is retried, so a write is never
  applied twice. Each accepted and refused write is logged.
"""

from __future__ import annotations

import logging
from typing import Any

from pyopenshowvar import KvpError
from pyopenshowvar_apps.writecheck import RefusedWrite, check_literal, checked_write

from . import ua
from .poller import RobotPoller

__all__ = ["WRITE_METHOD", "WriteError", "add_write_method", "write_variable"]

log = logging.getLogger(__name__)

WRITE_METHOD = "WriteVariable"
_MAX_LITERAL = 1024


class WriteError(Exception):
    """A refused WriteVariable call: the status code the client gets, and why (logged)."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


def _fail(code: int, message: str) -> WriteError:
    log.warning("WriteVariable refused: %s", message)
    return WriteError(code, message)


async def write_variable(poller: RobotPoller, name: Any, literal: Any) -> tuple[str, str]:
    """Apply the rules above and write; (echo, program stop or "") or a :class:`WriteError`."""
    cfg = poller.cfg
    if not isinstance(name, str) or not isinstance(literal, str) or len(literal) > _MAX_LITERAL:
        raise _fail(ua.StatusCodes.BadInvalidArgument, f"{cfg.name}: bad arguments")
    listed = cfg.writable_name(name)
    if listed is None:
        raise _fail(
            ua.StatusCodes.BadUserAccessDenied,
            f"{cfg.name}: {name!r} is not listed writable in the cell file",
        )
    name = listed  # what is written is exactly what the cell file lists
    problem = check_literal(literal)
    if problem is not None:
        raise _fail(
            ua.StatusCodes.BadInvalidArgument,
            f"{cfg.name}: {literal!r} is not a KRL literal: {problem.reason}",
        )
    client = poller.client
    if client is None or not poller.connected:
        raise _fail(ua.StatusCodes.BadNoCommunication, f"{cfg.name} is not connected")
    try:
        outcome = await checked_write(client, name, literal)
    except RefusedWrite as exc:
        code = (
            ua.StatusCodes.BadTypeMismatch
            if exc.reason.startswith("wrong type")
            else ua.StatusCodes.BadNotWritable
        )
        raise _fail(code, f"{cfg.name}: {exc}") from None
    except KvpError as exc:
        raise _fail(ua.StatusCodes.BadCommunicationError, f"{cfg.name}: {exc}") from None
    stop = outcome.stop.describe() if outcome.stop is not None else ""
    log.info("WriteVariable %s: %s = %s (echo %s)%s", cfg.name, name, literal, outcome.echo,
             f"; the program stopped: {stop}" if stop else "")  # fmt: skip
    return outcome.echo, stop


async def add_write_method(node: Any, method_id: ua.NodeId, ns: int, poller: RobotPoller) -> None:
    """Add ``WriteVariable(Variable, Value) -> (Echo, ProgramStop)`` to a controller object."""

    async def handler(
        parent: ua.NodeId, variable: ua.Variant, value: ua.Variant
    ) -> list[ua.Variant] | ua.StatusCode:
        try:
            echo, stop = await write_variable(poller, variable.Value, value.Value)
        except WriteError as exc:
            return ua.status_code(exc.code)
        return [ua.Variant(echo, ua.VariantType.String), ua.Variant(stop, ua.VariantType.String)]

    def arg(name: str, text: str) -> ua.Argument:
        a = ua.Argument()
        a.Name, a.DataType, a.ValueRank = name, ua.node_id(ua.ObjectIds.String), -1
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
        [
            arg("Echo", "the value as the controller answered it"),
            arg("ProgramStop", "empty, or how the robot program stopped right after the write"),
        ],
    )
