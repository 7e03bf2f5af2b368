"""The jog pad's security rules, without I/O: who may connect, what a page may send and write.

:mod:`.server` applies them to every WebSocket; they are pure so their tests can pin each rule
exactly (docs/web.md, "Threat model", says the same in prose).

* **Connecting** (:func:`refuse_connection`): the Origin must be this server; with a token,
  ``?token=`` must match it (compared in constant time).
* **Messages** (:func:`parse_message`): a text frame of strict JSON — an object, nested at
  most :data:`MAX_DEPTH` deep, only finite numbers (no ``NaN``, ``Infinity`` or ``1e999``).
  Anything else is not a page's message: the server closes the connection with
  :class:`Violation`'s code and reason. :class:`TokenBucket` bounds the messages a second.
* **Jog presses** (:func:`jog_request`): exact types; the jog override is clamped to
  1–100 %, so no page can ask for more than the configured jog speeds (:mod:`.jogplan`).
* **Writes from the watch list** (:func:`write_refusal`): the jog program's own variables
  (:data:`JOG_VARIABLES`) are written only by the server's jog logic, never from a page;
  ``EMU_RESTART`` only by the Restart button; a variable whose write can move the robot or
  change how it moves (the CLI's motion variables, every ``$`` system variable and the
  emulator's ``EMU_`` controls: :data:`MOTION_PREFIXES`) only when
  the server was started with ``--allow-motion-writes``. The rest goes through the same checks
  as ``kvp write`` (:mod:`pyopenshowvar_apps.writecheck`).
"""

from __future__ import annotations

import hmac
import json
import math
import re
from typing import Any

from pyopenshowvar_apps.names import base_name, is_motion_variable

from .jogplan import JogRequest

__all__ = [
    "BURST",
    "JOG_VARIABLES",
    "MAX_DEPTH",
    "MAX_NAME",
    "MAX_PRESS",
    "MOTION_PREFIXES",
    "RATE",
    "RESTART_VARIABLE",
    "TokenBucket",
    "Violation",
    "jog_request",
    "json_depth",
    "parse_message",
    "refuse_connection",
    "variable_name",
    "write_refusal",
]

#: Messages a second a page may send on average, and in a burst (a held button sends 40/s).
RATE = 100.0
BURST = 200.0
#: The deepest nesting a page's message has is 2 (``{"names": [...]}``).
MAX_DEPTH = 4
MAX_NAME = 64
#: Press numbers count up from 1 in a page; anything beyond this is not a page.
MAX_PRESS = 2**31 - 1
#: The KVP_JOG protocol (``krl/kvp_jog_config.dat``): written by the server's jog logic only.
JOG_VARIABLES = frozenset(
    {"JOG_MODE", "JOG_UNTIL", "JOG_COUNT", "JOG_AX", "JOG_FR", "JOG_ACC", "JOG_ACC_CP",
     "JOG_ACC_ORI"}
)  # fmt: skip
RESTART_VARIABLE = "EMU_RESTART"
#: Besides the CLI's motion variables: system variables (``$OV_PRO``, ``$OUT``, the software
#: limits, ...) and the proxy's (``@``), and the emulator's own controls (``EMU_WRENCH`` pushes
#: the simulated arm). A page cannot know which of them are harmless, so none is written
#: without ``--allow-motion-writes``.
MOTION_PREFIXES = ("$", "@", "EMU_")

#: A KRL variable as KUKAVARPROXY takes it: a name, an optional index (``[]`` for a whole
#: array) and members, nothing else (no expressions, no spaces).
_NAME = re.compile(
    r"[$@]?[A-Za-z_][\w$]*(\[(\d+(,\d+){0,2})?\])?(\.[A-Za-z_][\w$]*(\[\d+(,\d+){0,2}\])?)*",
    re.ASCII,
)

# WebSocket close codes (RFC 6455 §7.4.1)
INVALID_DATA = 1007
UNSUPPORTED = 1003


class Violation(Exception):
    """A message no page sends: the server closes with ``code`` and ``reason``."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


def refuse_connection(
    origin: str | None, host: str, given: str | None, token: str | None
) -> str | None:
    """Why a WebSocket is refused (its ``Origin`` and ``Host`` headers, the ``?token=`` it
    gave, the token required), or None."""
    if origin is not None and origin not in (f"http://{host}", f"https://{host}"):
        return "wrong origin"
    if token is not None and not hmac.compare_digest((given or "").encode(), token.encode()):
        return "token missing or wrong"
    return None


class TokenBucket:
    """At most :data:`RATE` messages a second on average, :data:`BURST` at once."""

    def __init__(self, now: float, rate: float = RATE, burst: float = BURST) -> None:
        self.rate, self.burst = rate, burst
        self.tokens = burst
        self.stamp = now

    def allow(self, now: float) -> bool:
        self.tokens = min(self.burst, self.tokens + (now - self.stamp) * self.rate)
        self.stamp = now
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True


def json_depth(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` in ``text``, brackets inside strings ignored."""
    depth = deepest = 0
    in_string = escaped = False
    for c in text:
        if in_string:
            if escaped:
                escaped = False
            elif c == "\\":
                escaped = True
            elif c == '"':
                in_string = False
        elif c == '"':
            in_string = True
        elif c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth -= 1
    return deepest


def _no_constant(name: str) -> Any:
    raise Violation(INVALID_DATA, f"not a JSON number: {name}")


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise Violation(INVALID_DATA, f"number out of range: {text[:20]}")
    return value


def parse_message(data: str | bytes | None) -> dict[str, Any]:
    """One WebSocket message as a page sends it, or :class:`Violation`."""
    if not isinstance(data, str):
        raise Violation(UNSUPPORTED, "binary frames are not accepted: send JSON text")
    if data.count("[") + data.count("{") > MAX_DEPTH and json_depth(data) > MAX_DEPTH:
        raise Violation(INVALID_DATA, f"JSON nested deeper than {MAX_DEPTH}")
    try:
        msg = json.loads(data, parse_constant=_no_constant, parse_float=_finite)
    except ValueError as exc:  # JSONDecodeError, and integers beyond Python's digit limit
        raise Violation(INVALID_DATA, f"not JSON: {str(exc)[:80]}") from None
    if not isinstance(msg, dict):
        raise Violation(INVALID_DATA, "a message is a JSON object")
    return msg


def variable_name(value: object) -> str:
    """A variable name as a page may read, watch or write it; ValueError otherwise."""
    if not isinstance(value, str):
        raise ValueError("a variable name is a string")
    name = value.strip()
    if len(name) > MAX_NAME or not _NAME.fullmatch(name):
        raise ValueError(f"bad variable name {name[:MAX_NAME]!r}")
    return name


def write_refusal(name: str, *, allow_motion: bool) -> str | None:
    """Why a page may not write ``name`` (already a :func:`variable_name`), or None."""
    base = base_name(name)
    if base in JOG_VARIABLES:
        return f"{base} belongs to the jog program: only the server's jog logic writes it"
    if base == RESTART_VARIABLE:
        return "use the Restart program button"
    if not allow_motion and (is_motion_variable(name) or base.startswith(MOTION_PREFIXES)):
        return (
            f"writing {base} can move the robot or change how it moves: refused unless kvp web"
            " runs with --allow-motion-writes"
        )
    return None


def _integer(msg: dict[str, Any], key: str, lo: int, hi: int) -> int:
    value = msg.get(key)
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ValueError(f"{key} must be an integer in {lo}..{hi}")
    return value


def _number(value: object, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{key} must be a number")
    return float(value)


def jog_request(msg: dict[str, Any]) -> tuple[int, JogRequest]:
    """(press number, request) of a ``jog`` message; ValueError when it is malformed. The jog
    override is clamped to 1..100 %."""
    press = _integer(msg, "press", 0, MAX_PRESS)
    direction = _integer(msg, "dir", -1, 1)
    frame, key = msg.get("frame"), msg.get("key")
    if not isinstance(frame, str) or not isinstance(key, str):
        raise ValueError("frame and key must be strings")
    step = msg.get("step")
    override = min(100.0, max(1.0, _number(msg.get("ov", 50), "ov")))
    return press, JogRequest(
        frame=frame,  # type: ignore[arg-type]  # JogRequest checks it
        key=key,
        direction=direction,
        step=_number(step, "step") if step else None,
        override=override,
    )
