"""What the tools add around a write: a literal checked before it is sent, the likely reason
for a refusal, and a robot program that stops right after the write.

KUKAVARPROXY answers a refused write with a bare failure flag: read-only, unknown, wrong type
and out of range all look the same on the wire (reference §2.3). So the tools

* parse the literal before sending it, and point at the character where it goes wrong;
* after a refusal, read the variable and compare: unknown name, a value of the wrong type
  (checked with the type the controller prints), a KRC4 system variable that is read-only or
  has a range (:data:`pyopenshowvar.sysvars.SYSTEM_VARIABLES`, the KRC4 facts the emulator
  is built from);
* around a write while the robot program runs, read ``$PRO_STATE1`` and ``$STOPMESS`` (and the
  emulator's ``$EMU_MESSAGE[]``, which a real KRC does not have) for a short window, because a
  write can be accepted and still stop the program (``MYAXIS {A1 9999}``: software limit
  switch). Writes while no program runs are not watched, so they cost one extra round trip.

Used by ``kvp write``, the REPL and the monitor, so all three say the same.
"""

from __future__ import annotations

import asyncio
import re
import time
from dataclasses import dataclass
from typing import Any

from pyopenshowvar import (
    Client,
    KrlEnum,
    KvpError,
    Struct,
    UnknownVariableError,
    WriteRefusedError,
    parse_value,
)
from pyopenshowvar.errors import KrlValueError
from pyopenshowvar.krl import BUILTIN_TYPES
from pyopenshowvar_apps.common import STOP_WINDOW, STOP_WINDOW_HELP

__all__ = [
    "STOP_WINDOW",
    "STOP_WINDOW_HELP",
    "LiteralProblem",
    "ProgramState",
    "RefusedWrite",
    "WriteOutcome",
    "WriteProgress",
    "check_literal",
    "checked_write",
    "explain_refusal",
    "read_program_state",
]

#: Poll period of that watch: one interpolation cycle.
STOP_POLL = 0.012
STATE_NAMES = ("$PRO_STATE1", "$STOPMESS", "$EMU_MESSAGE[]")
_AT = re.compile(r" at (\d+)$")


@dataclass(frozen=True)
class LiteralProblem:
    """Why a literal is not KRL, and where (0-based character index, when known)."""

    reason: str
    position: int | None

    def lines(self, literal: str) -> list[str]:
        """The reason, the literal and a caret under the offending character."""
        out = [self.reason]
        if self.position is not None and "\n" not in literal and len(literal) <= 200:
            out += [f"  {literal}", "  " + " " * self.position + "^"]
        return out


def check_literal(text: str) -> LiteralProblem | None:
    """None when ``text`` parses as a KRL value, else what is wrong and where."""
    try:
        parse_value(text)
    except KrlValueError as exc:
        return _problem(str(exc))
    return None


def _problem(message: str) -> LiteralProblem:
    # The parser names the offset at the end of its message ("... got 'x' at 4").
    m = _AT.search(message)
    reason = message
    if reason.startswith("invalid KRL value "):
        reason = reason.split(": ", 1)[-1]
    if m:
        reason = reason[: -len(m.group(0))] if reason.endswith(m.group(0)) else reason
        return LiteralProblem(reason, int(m.group(1)))
    return LiteralProblem(reason, None)


class RefusedWrite(WriteRefusedError):
    """A refused write with the likely ``reason`` (a :class:`WriteRefusedError`)."""

    def __init__(self, name: str, endpoint: str, value: str, reason: str) -> None:
        super().__init__("write refused", name=name, endpoint=endpoint, value=value)
        self.reason = reason
        where = f" on {endpoint}" if endpoint else ""
        self.args = (f"write refused: {name!r}{where}: {reason}",)


def _kind(value: Any) -> tuple[str, str | None]:
    """A description of a typed value's type and the type name to check a literal against."""
    if isinstance(value, bool):
        return "BOOL", "BOOL"
    if isinstance(value, int):
        return "INT", "INT"
    if isinstance(value, float):
        return "REAL", "REAL"
    if isinstance(value, KrlEnum):
        return "an ENUM", None
    if isinstance(value, str):
        return "a CHAR array (text)", None
    if isinstance(value, Struct):
        return (value.type_name or "a struct"), value.type_name
    return "an array", None


def _short(text: str, width: int = 60) -> str:
    return text if len(text) <= width else text[: width - 1] + "…"


def _type_mismatch(current: Any, literal: str) -> str | None:
    """Why ``literal`` cannot be a value of ``current``'s type, or None when it can."""
    what, type_name = _kind(current)
    try:
        value = parse_value(literal)
    except KrlValueError:
        return None  # checked before sending; nothing to add here
    if type_name is not None and _known_type(type_name):
        try:
            parse_value(literal, type_name)
        except KrlValueError as exc:
            return f"{_problem(str(exc)).reason}"
    if isinstance(current, Struct) and isinstance(value, Struct):
        unknown = [m for m in value.members if m not in current.members]
        if unknown:
            return f"{what} has no member {', '.join(unknown)}"
        return None
    if isinstance(current, Struct) != isinstance(value, Struct):
        return (
            "the value is not a struct" if isinstance(current, Struct) else "the value is a struct"
        )
    if isinstance(current, KrlEnum) and not isinstance(value, KrlEnum):
        return "the value is not an ENUM value #NAME"
    if isinstance(current, str) and not isinstance(value, str):
        return 'the value is not a text "..."'
    return None


def _known_type(type_name: str) -> bool:
    """Whether the library knows ``type_name``; a user STRUC of the controller's data lists
    it does not, and is compared by its members instead (an unknown type is no reason)."""
    try:
        BUILTIN_TYPES.resolve(type_name)
    except KrlValueError:
        return False
    return True


def _system_variable(name: str) -> Any:
    from pyopenshowvar.sysvars import SYSTEM_VARIABLES
    from pyopenshowvar_apps.names import base_name

    base = base_name(name)
    return next((v for v in SYSTEM_VARIABLES if v.name == base), None)


async def explain_refusal(client: Client, name: str, value: str) -> str:
    """The most likely reason the controller refused ``name = value`` (one clause)."""
    try:
        current_text = await client.read(name)
    except UnknownVariableError:
        return (
            "the variable reads as unknown: not declared, an index or member that does not"
            " exist, or never initialised (and the value does not fit its type)"
        )
    except KvpError:
        return "the controller gives no reason"
    try:
        current = parse_value(current_text)
    except KrlValueError:
        current = None
    if current is not None:
        mismatch = _type_mismatch(current, value)
        if mismatch:
            what = _kind(current)[0]
            return f"wrong type: the variable is {what} (now {_short(current_text)}); {mismatch}"
    sysvar = _system_variable(name)
    if sysvar is not None and sysvar.read_only:
        return "read-only: a KRC lets no client write this system variable"
    if sysvar is not None and sysvar.value_range is not None:
        low, high = sysvar.value_range
        try:
            number = parse_value(value)
        except KrlValueError:
            number = None
        if isinstance(number, int | float) and not low <= number <= high:
            return f"out of range {low}..{high}"
    return (
        f"the controller gives no reason; the value fits its type (now {_short(current_text)}),"
        " so it is probably read-only or out of range"
    )


@dataclass(frozen=True)
class ProgramState:
    """The robot interpreter as the controller reports it (None: could not be read)."""

    state: str | None
    stopmess: bool | None
    message: str | None

    @property
    def running(self) -> bool:
        return self.state == "#P_ACTIVE"

    def stopped_since(self, before: ProgramState) -> bool:
        """The program ran before and does not now, or a stop message appeared."""
        ended = before.running and self.state is not None and not self.running
        return ended or (before.stopmess is False and self.stopmess is True)

    def describe(self) -> str:
        parts = [f"$PRO_STATE1 {self.state}"] if self.state else []
        if self.stopmess is not None:
            parts.append(f"$STOPMESS {'TRUE' if self.stopmess else 'FALSE'}")
        text = ", ".join(parts)
        return f"{text}: {self.message}" if self.message else text


async def read_program_state(client: Client) -> ProgramState:
    """One pipelined read of the program state (unknown variables give None fields)."""
    results = await client.read_many(STATE_NAMES)
    texts = {n: (r.text if r.ok else None) for n, r in results.items()}
    message = texts["$EMU_MESSAGE[]"]
    message = message.strip().strip('"').strip() if message else None
    stopmess = texts["$STOPMESS"]
    return ProgramState(
        texts["$PRO_STATE1"],
        None if stopmess is None else stopmess.strip().upper() == "TRUE",
        message or None,
    )


@dataclass(frozen=True)
class WriteOutcome:
    """A write the controller accepted: its echo, the write request's round trip (seconds;
    not the stop window after it), and the program stop it caused, if any."""

    echo: str
    seconds: float
    stop: ProgramState | None = None


class WriteProgress:
    """How far a :func:`checked_write` got, for a caller that was interrupted (Ctrl-C).

    ``sent``: the write request was handed to the connection (it may have reached the
    controller even if no answer came); ``answer``: ``"acknowledged"`` or ``"refused"`` once
    the proxy answered; ``echo``: its echo of an acknowledged write.
    """

    def __init__(self) -> None:
        self.sent = False
        self.answer: str | None = None
        self.echo = ""

    def describe(self, name: str) -> str:
        """What an interruption now means for the variable, in one clause."""
        if self.answer == "acknowledged":
            return (
                f"the write was sent and acknowledged: {name!r} = {self.echo} was written"
                " (the robot program was no longer watched for a stop)"
            )
        if self.answer == "refused":
            return f"the write was sent and refused: {name!r} was not written"
        if self.sent:
            return (
                f"the write was sent but not answered: {name!r} may or may not have been"
                " written (read it to know)"
            )
        return f"the write was not sent: {name!r} was not written"


async def checked_write(
    client: Client,
    name: str,
    value: str,
    *,
    window: float = STOP_WINDOW,
    progress: WriteProgress | None = None,
) -> WriteOutcome:
    """Write ``value`` (KRL text) to ``name`` and watch ``window`` seconds for a program stop.

    A refusal raises :class:`WriteRefusedError` whose message says the likely reason.
    ``window=0`` writes without watching. ``progress`` (optional) is kept up to date, so a
    caller interrupted meanwhile can say whether the write was sent and answered.
    """
    progress = progress if progress is not None else WriteProgress()
    before = await read_program_state(client) if window > 0 else None
    # On an open connection the request goes to the socket before the call first awaits
    # anything, so from here an interruption cannot come before it was sent; on a lost one
    # the client reconnects first, and an interruption then means "not sent".
    progress.sent = client.connected
    t0 = time.perf_counter()
    try:
        echo = await client.write(name, value)
    except WriteRefusedError as exc:
        progress.sent, progress.answer = True, "refused"
        reason = await explain_refusal(client, name, value)
        raise RefusedWrite(name, exc.endpoint, value, reason) from None
    seconds = time.perf_counter() - t0
    progress.sent, progress.answer, progress.echo = True, "acknowledged", echo
    if before is None or not before.running:
        return WriteOutcome(echo, seconds)
    deadline = time.monotonic() + window
    while True:
        now = await read_program_state(client)
        if now.stopped_since(before):
            return WriteOutcome(echo, seconds, now)
        if time.monotonic() >= deadline:
            return WriteOutcome(echo, seconds)
        await asyncio.sleep(STOP_POLL)
