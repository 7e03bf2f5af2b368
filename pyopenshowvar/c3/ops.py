"""The C3 Bridge client operations, written once for the asyncio and the blocking client.

Each public function here is an operation (a generator of calls, see :mod:`pyopenshowvar.core`)
taking the client as its first argument; :mod:`pyopenshowvar.c3.api` turns them into methods
of both clients. The client offers ``endpoint``, ``read_many(names, timeout=)``,
``_request(label, frame, timeout)`` (send one whole frame, return the decoded
:class:`~pyopenshowvar.protocol.Reply`) and ``_c3_chunk`` (the largest file chunk it sends in
one message).

Every operation first makes sure the server has the message it is about to send
(:meth:`~pyopenshowvar.c3.server.ServerInfo.require`) and that the message can be encoded
(names, counts, sizes), so a refusal never costs a request, and then sends exactly one message
per step. Program and file operations are in :mod:`pyopenshowvar.c3.ops_programs`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from ..core import Op, ReadResult
from ..errors import (
    KvpError,
    ProtocolError,
    ReadFailedError,
    UnknownVariableError,
    WriteRefusedError,
)
from ..krl import KrlValue, format_value, parse_value
from .constants import Command, ErrorCode, Interpreter, KcpKey
from .errors import C3CommandError, MotionNotAllowedError, RequestTooLargeError
from .messages import (
    MAX_COUNT,
    Benchmark,
    ConfirmAll,
    KcpAction,
    Message,
    Motion,
    ProxyFeatures,
    ProxyInfo,
    ReadMultiple,
    ReadVariable,
    WriteMultiple,
    WriteVariable,
    key_type,
    names_tuple,
)
from .messages import motion_type as motion_type_of  # the parameter of motion() is motion_type
from .replies import (
    BenchmarkReply,
    FeatureMap,
    Multiple,
    Outcome,
    ProxyInfoReply,
    Value,
    error_name,
)
from .server import PROBES, ServerInfo, identify
from .wire import PayloadError

__all__ = [
    "benchmark",
    "check",
    "confirm_all",
    "exchange",
    "guard",
    "kcp_key",
    "motion",
    "proxy_features",
    "proxy_info",
    "read_multiple",
    "read_utf16",
    "server_info",
    "write_multiple",
    "write_utf16",
]


# --------------------------------------------------------------------------- plumbing


def server_info(
    client: Any, *, refresh: bool = False, timeout: float | None = None
) -> Op[ServerInfo]:
    """What the server is (KUKAVARPROXY or C3 Bridge, version, messages); asked once.

    Three pipelined ASCII reads (``@PROXY_TYPE``, ``@PROXY_VERSION``, ``@PROXY_FEATURES``) that
    every proxy answers, so identifying never upsets a KVP. Cached on the client;
    ``refresh=True`` asks again (e.g. after the controller was switched to another proxy).
    """
    cached: ServerInfo | None = getattr(client, "_c3_info", None)
    if cached is not None and not refresh:
        return cached
    results = yield ("read_many", (list(PROBES),), {"timeout": timeout})
    values = [results[n].text if results[n].ok else None for n in PROBES]
    info = identify(*values)
    client._c3_info = info
    return info


def guard(client: Any, command: int, what: str, timeout: float | None) -> Op[ServerInfo]:
    info = yield from server_info(client, timeout=timeout)
    info.require(command, what, client.endpoint)
    return info


def encode(message: Message) -> bytes:
    """The frame of ``message`` with tag 0, or :class:`RequestTooLargeError` (nothing sent)."""
    try:
        return message.frame(0)
    except ProtocolError as exc:  # PayloadError, or a frame over the 16-bit length
        raise RequestTooLargeError(f"{type(message).__name__}: {exc}") from None


def exchange(client: Any, message: Message, label: str, timeout: float | None) -> Op[Outcome]:
    """Send one message, return its reply's :class:`Outcome` (any footer)."""
    frame = encode(message)
    reply = yield ("_request", (label, frame, timeout), {})
    out = Outcome.of(reply)
    if out.type != message.TYPE:
        raise ProtocolError(
            f"{client.endpoint} answered {label} with message type {out.type}, "
            f"not {int(message.TYPE)}"
        )
    return out


def check(client: Any, out: Outcome, what: str, detail: str = "") -> Outcome:
    """``out`` if it succeeded, else :class:`C3CommandError` with its code."""
    if not out.ok:
        raise C3CommandError(what, out.code, endpoint=client.endpoint, detail=detail)
    return out


def _parse(client: Any, out: Outcome, kind: Any, what: str) -> Any:
    try:
        return kind.parse(out.reader())
    except PayloadError as exc:
        raise ProtocolError(f"{client.endpoint}: malformed {what} reply: {exc}") from None


# --------------------------------------------------------------------------- variables


def _read_error(client: Any, name: str, code: int) -> KvpError:
    if code == ErrorCode.GENERAL:
        # C3 Bridge's answer for a name CrossComm cannot show (KVP's is an empty success)
        return UnknownVariableError(
            "unknown or unreadable variable", name=name, endpoint=client.endpoint
        )
    return ReadFailedError(f"read failed, {error_name(code)}", name=name, endpoint=client.endpoint)


def read_utf16(client: Any, name: str, *, timeout: float | None = None) -> Op[str]:
    """Read one variable with message #4 (name and value travel as UTF-16)."""
    yield from guard(client, Command.READ_VARIABLE, "read_utf16", timeout)
    out = yield from exchange(client, ReadVariable(name), name, timeout)
    if not out.ok:
        raise _read_error(client, name, out.code)
    value: str = _parse(client, out, Value, "#4").value
    return value


def write_utf16(
    client: Any, name: str, value: KrlValue | str, *, timeout: float | None = None
) -> Op[str]:
    """Write one variable with message #5 (UTF-16); returns the server's echo."""
    text = value if isinstance(value, str) else format_value(value)
    yield from guard(client, Command.WRITE_VARIABLE, "write_utf16", timeout)
    out = yield from exchange(client, WriteVariable(name, text), name, timeout)
    if not out.ok:
        raise WriteRefusedError(
            f"write refused, {error_name(out.code)}",
            name=name,
            endpoint=client.endpoint,
            value=text,
        )
    echo: str = _parse(client, out, Value, "#5").value
    return echo


def _limit(count: int) -> None:
    if count > MAX_COUNT:
        raise RequestTooLargeError(
            f"{count} variables in one message; C3 Bridge takes at most {MAX_COUNT} "
            "(split the list: each message is one consistent snapshot)"
        )


def _multiple_reply(client: Any, out: Outcome, what: str, count: int) -> Multiple:
    multi: Multiple = _parse(client, out, Multiple, what)
    if not out.ok and out.code in (ErrorCode.PROTOCOL, ErrorCode.LONG_ANSWER) and not multi.items:
        hint = " (read fewer or shorter variables per message)" if out.code == 10 else ""
        raise C3CommandError(what, out.code, endpoint=client.endpoint, detail=hint.strip(" ()"))
    if len(multi.items) != count:
        raise ProtocolError(
            f"{client.endpoint} answered {what} with {len(multi.items)} values for {count} names"
        )
    return multi


def read_multiple(
    client: Any, names: Sequence[str], *, typed: bool = False, timeout: float | None = None
) -> Op[dict[str, Any]]:
    """Read up to 255 variables in ONE message (#6): one request, one reply.

    Returns ``{name: ReadResult}`` in request order (like ``read_many``); an unknown name fails
    alone. On our emulator the values come from one interpolation cycle; a real C3 Bridge
    reads them one after the other through CrossComm (docs/c3bridge.md).
    """
    names = names_tuple(names)
    _limit(len(names))
    message = ReadMultiple(names)
    encode(message)  # too long a name or list: refused before the server is even asked
    yield from guard(client, Command.READ_MULTIPLE, "read_multiple", timeout)
    out = yield from exchange(client, message, f"{len(names)} variables", timeout)
    multi = _multiple_reply(client, out, "read_multiple", len(names))
    results: dict[str, Any] = {}
    for name, (code, text) in zip(names, multi.items, strict=True):
        if code != ErrorCode.SUCCESS:
            results[name] = ReadResult(name, error=_read_error(client, name, code))
            continue
        value = None
        if typed:
            try:
                value = parse_value(text)
            except KvpError as exc:
                results[name] = ReadResult(name, text=text, error=exc)
                continue
        results[name] = ReadResult(name, text=text, value=value)
    return results


def write_multiple(
    client: Any,
    items: Iterable[tuple[str, KrlValue | str]],
    *,
    check_all: bool = True,
    timeout: float | None = None,
) -> Op[dict[str, Any]]:
    """Write up to 255 variables in ONE message (#7); returns ``{name: ReadResult}`` of the
    values the server read back after writing.

    C3 Bridge writes them in order and goes on after a refusal, so the others are applied.
    With ``check_all`` (default) any refusal then raises :class:`WriteRefusedError` naming every
    refused variable; its ``results`` attribute holds all outcomes.
    """
    pairs = tuple((n, v if isinstance(v, str) else format_value(v)) for n, v in items)
    _limit(len(pairs))
    message = WriteMultiple(pairs)
    encode(message)
    yield from guard(client, Command.WRITE_MULTIPLE, "write_multiple", timeout)
    out = yield from exchange(client, message, f"{len(pairs)} variables", timeout)
    multi = _multiple_reply(client, out, "write_multiple", len(pairs))
    results: dict[str, Any] = {}
    refused: list[str] = []
    for (name, text), (code, echo) in zip(pairs, multi.items, strict=True):
        if code == ErrorCode.SUCCESS:
            results[name] = ReadResult(name, text=echo)
            continue
        refused.append(f"{name}={text} ({error_name(code)})")
        results[name] = ReadResult(
            name,
            error=WriteRefusedError(
                f"write refused, {error_name(code)}",
                name=name,
                endpoint=client.endpoint,
                value=text,
            ),
        )
    if refused and check_all:
        error = WriteRefusedError(
            f"{len(refused)} of {len(pairs)} writes refused: {'; '.join(refused)}",
            endpoint=client.endpoint,
        )
        error.results = results  # type: ignore[attr-defined]
        raise error
    return results


# --------------------------------------------------------------------------- motion, keys


def _need_motion(allow_motion: bool, what: str) -> None:
    if not allow_motion:
        raise MotionNotAllowedError(
            f"{what} moves the robot: pass allow_motion=True (CLI: --allow-motion) once the "
            "cell is safe — nothing was sent"
        )


def motion(
    client: Any,
    position: KrlValue | str,
    motion_type: int | str = "PTP",
    *,
    allow_motion: bool = False,
    timeout: float | None = None,
) -> Op[None]:
    """Start a PTP, LIN, PTP_REL or LIN_REL motion (#11) to a KRL position literal, e.g.
    ``{POS: X 500, Y 0, Z 800, A 0, B 90, C 0}`` or ``{A6 10}`` (relative)."""
    kind = motion_type_of(motion_type)
    text = position if isinstance(position, str) else format_value(position)
    _need_motion(allow_motion, f"a {kind.name} motion")
    message = Motion(kind, text)
    encode(message)
    yield from guard(client, Command.MOTION, "motion", timeout)
    out = yield from exchange(client, message, f"{kind.name} {text}", timeout)
    check(client, out, f"{kind.name} {text}")


def kcp_key(
    client: Any,
    key: int | str,
    *,
    target: int = Interpreter.ROBOT,
    key_code: int = 0,
    direction: bool = False,
    released: bool = False,
    allow_motion: bool = False,
    timeout: float | None = None,
) -> Op[None]:
    """Press (or release) a smartPAD key (#12): START, STOP, JOG (``target`` = axis) or
    MOUSE_6D. Pressing START or a jog key moves the robot: ``allow_motion=True``."""
    kind = key_type(key)
    if kind in (KcpKey.START, KcpKey.JOG, KcpKey.MOUSE_6D) and not released:
        _need_motion(allow_motion, f"the {kind.name} key")
    yield from guard(client, Command.KCP_ACTION, "kcp_key", timeout)
    message = KcpAction(kind, target, key_code, direction, released)
    out = yield from exchange(client, message, f"{kind.name} key", timeout)
    check(client, out, f"{kind.name} key")


def confirm_all(client: Any, *, timeout: float | None = None) -> Op[None]:
    """Acknowledge every message on the controller (#63, the smartPAD's "Confirm all")."""
    yield from guard(client, Command.CROSS_CONFIRM_ALL, "confirm_all", timeout)
    out = yield from exchange(client, ConfirmAll(), "confirm all", timeout)
    check(client, out, "confirm all")


# --------------------------------------------------------------------------- service


def proxy_info(client: Any, *, timeout: float | None = None) -> Op[ProxyInfoReply]:
    """Version, UTC clock and computer name of the C3 Bridge server (#13)."""
    yield from guard(client, Command.PROXY_INFO, "proxy_info", timeout)
    out = yield from exchange(client, ProxyInfo(), "proxy info", timeout)
    check(client, out, "proxy info")
    reply: ProxyInfoReply = _parse(client, out, ProxyInfoReply, "#13")
    return reply


def proxy_features(client: Any, *, timeout: float | None = None) -> Op[frozenset[int]]:
    """The message types the server handles, from its 256-bit map (#14)."""
    yield from guard(client, Command.PROXY_FEATURES, "proxy_features", timeout)
    out = yield from exchange(client, ProxyFeatures(), "proxy features", timeout)
    check(client, out, "proxy features")
    features: FeatureMap = _parse(client, out, FeatureMap, "#14")
    return features.types


def benchmark(
    client: Any,
    names: Sequence[str],
    iterations: int,
    values: Sequence[str] | None = None,
    *,
    timeout: float | None = None,
) -> Op[BenchmarkReply]:
    """Let the server time ``iterations`` reads (or writes of ``values``) of ``names`` (#17).

    C3 Bridge itself takes at most 10 names; the reply says how many it used.
    """
    names = names_tuple(names)
    _limit(len(names))
    message = Benchmark(names, iterations, tuple(values) if values is not None else None)
    encode(message)
    yield from guard(client, Command.PROXY_BENCHMARK, "benchmark", timeout)
    out = yield from exchange(client, message, "benchmark", timeout)
    check(client, out, "benchmark")
    reply: BenchmarkReply = _parse(client, out, BenchmarkReply, "#17")
    return reply
