"""The C3 Bridge client operations, written once for the asyncio and the blocking client.

Each public function here is an operation (a generator of calls, see :mod:`pyopenshowvar.core`)
taking the client as its first argument; :mod:`pyopenshowvar.c3.api` turns them into methods
of both clients. The client offers ``endpoint``, ``read_many(names, timeout=)``,
``_request(label, frame, timeout)`` (send one whole frame, return the decoded
:class:`~pyopenshowvar.protocol.Reply`) and ``_c3_chunk`` (the largest file chunk it sends in
one message).

Every operation sends its first message through :func:`send`, which encodes it (names,
counts, sizes: :class:`RequestTooLargeError`) and then makes sure the server has it
(:meth:`~pyopenshowvar.c3.server.ServerInfo.require`), so a refusal never costs a request;
further messages of the same operation go through :func:`exchange`, exactly one per step. Program and file operations are in :mod:`pyopenshowvar.c3.ops_programs`.
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
from ..krl import KrlValue
from .constants import ErrorCode, Interpreter, KcpKey
from .errors import C3CommandError, MotionNotAllowedError, RequestTooLargeError
from .messages import (
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
    "kcp_key",
    "motion",
    "proxy_features",
    "proxy_info",
    "read_multiple",
    "read_utf16",
    "send",
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


def encode(message: Message) -> bytes:
    """The frame of ``message`` with tag 0, or :class:`RequestTooLargeError` (nothing sent)."""
    try:
        return message.frame(0)
    except ProtocolError as exc:  # PayloadError, or a frame over the 16-bit length
        raise RequestTooLargeError(f"{type(message).__name__}: {exc}") from None


def send(
    client: Any, message: Message, method: str, label: str, timeout: float | None
) -> Op[Outcome]:
    """The first message of operation ``method``: encoded, then checked against what the server
    offers (both raise before anything is sent, the identifying reads included), then sent."""
    frame = encode(message)
    info = yield from server_info(client, timeout=timeout)
    info.require(message.TYPE, method, client.endpoint)
    return (yield from _round_trip(client, frame, message.TYPE, label, timeout))


def exchange(client: Any, message: Message, label: str, timeout: float | None) -> Op[Outcome]:
    """A further message of an operation whose first one went through :func:`send`."""
    return (yield from _round_trip(client, encode(message), message.TYPE, label, timeout))


def _round_trip(
    client: Any, frame: bytes, msg_type: int, label: str, timeout: float | None
) -> Op[Outcome]:
    """Send one frame, return its reply's :class:`Outcome` (any footer)."""
    reply = yield ("_request", (label, frame, timeout), {})
    out = Outcome.of(reply)
    if out.type != msg_type:
        raise ProtocolError(
            f"{client.endpoint} answered {label} with message type {out.type}, not {msg_type}"
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
    out = yield from send(client, ReadVariable(name), "read_utf16", name, timeout)
    if not out.ok:
        raise _read_error(client, name, out.code)
    value: str = _parse(client, out, Value, "#4").value
    return value


def write_utf16(
    client: Any, name: str, value: KrlValue | str, *, timeout: float | None = None
) -> Op[str]:
    """Write one variable with message #5 (UTF-16); returns the server's echo."""
    text = client._text(value)
    out = yield from send(client, WriteVariable(name, text), "write_utf16", name, timeout)
    if not out.ok:
        raise WriteRefusedError(
            f"write refused, {error_name(out.code)}",
            name=name,
            endpoint=client.endpoint,
            value=text,
        )
    echo: str = _parse(client, out, Value, "#5").value
    return echo


def _multiple_reply(client: Any, out: Outcome, what: str, count: int) -> Multiple:
    multi: Multiple = _parse(client, out, Multiple, what)
    if not out.ok and out.code in (ErrorCode.PROTOCOL, ErrorCode.LONG_ANSWER) and not multi.items:
        hint = (
            "read fewer or shorter variables per message"
            if out.code == ErrorCode.LONG_ANSWER
            else ""
        )
        raise C3CommandError(what, out.code, endpoint=client.endpoint, detail=hint)
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
    message = ReadMultiple(names)
    out = yield from send(client, message, "read_multiple", f"{len(names)} variables", timeout)
    multi = _multiple_reply(client, out, "read_multiple", len(names))
    results: dict[str, Any] = {}
    for name, (code, text) in zip(names, multi.items, strict=True):
        if code != ErrorCode.SUCCESS:
            results[name] = ReadResult(name, error=_read_error(client, name, code))
            continue
        value = None
        if typed:
            try:
                value = client._parse(name, text, None)  # names it, as read_many does
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
    pairs = tuple((n, client._text(v)) for n, v in items)
    message = WriteMultiple(pairs)
    out = yield from send(client, message, "write_multiple", f"{len(pairs)} variables", timeout)
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
    text = client._text(position)
    _need_motion(allow_motion, f"a {kind.name} motion")
    out = yield from send(client, Motion(kind, text), "motion", f"{kind.name} {text}", timeout)
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
    message = KcpAction(kind, target, key_code, direction, released)
    out = yield from send(client, message, "kcp_key", f"{kind.name} key", timeout)
    check(client, out, f"{kind.name} key")


def confirm_all(client: Any, *, timeout: float | None = None) -> Op[None]:
    """Acknowledge every message on the controller (#63, the smartPAD's "Confirm all")."""
    out = yield from send(client, ConfirmAll(), "confirm_all", "confirm all", timeout)
    check(client, out, "confirm all")


# --------------------------------------------------------------------------- service


def proxy_info(client: Any, *, timeout: float | None = None) -> Op[ProxyInfoReply]:
    """Version, UTC clock and computer name of the C3 Bridge server (#13)."""
    out = yield from send(client, ProxyInfo(), "proxy_info", "proxy info", timeout)
    check(client, out, "proxy info")
    reply: ProxyInfoReply = _parse(client, out, ProxyInfoReply, "#13")
    return reply


def proxy_features(client: Any, *, timeout: float | None = None) -> Op[frozenset[int]]:
    """The message types the server handles, from its 256-bit map (#14)."""
    out = yield from send(client, ProxyFeatures(), "proxy_features", "proxy features", timeout)
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
    message = Benchmark(names, iterations, tuple(values) if values is not None else None)
    out = yield from send(client, message, "benchmark", "benchmark", timeout)
    check(client, out, "benchmark")
    reply: BenchmarkReply = _parse(client, out, BenchmarkReply, "#17")
    return reply
