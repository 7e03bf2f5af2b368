"""The high-level asyncio client: raw and typed reads/writes, pipelined multi-reads.

``Client`` is JOpenShowVar's CrossComClient done right::

    async with Client("192.168.1.10", timeout=1.0) as kvp:
        text = await kvp.read("$OV_PRO")                 # simpleRead: raw text "100"
        axes = await kvp.read_value("$AXIS_ACT")          # typed: E6Axis
        await kvp.write("$OV_PRO", 50)                    # typed value or raw KRL text
        results = await kvp.read_many(["$OV_PRO", "$POS_ACT"])

Robot helpers (joint angles, torques, pose, paths, outputs) live in :mod:`pyopenshowvar.robot`
and are mixed in here, so a user needs one object only.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from .connection import Connection, IdPolicy
from .errors import (
    KrlValueError,
    KvpConnectionError,
    KvpError,
    ReadFailedError,
    UnknownVariableError,
    WriteRefusedError,
)
from .krl import KrlValue, format_value, parse_value
from .protocol import Reply, encode_read, encode_read_array, encode_write, encode_write_array
from .robot import RobotHelpers
from .stats import AccessStats

__all__ = ["Client", "ReadResult", "connect"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class ReadResult:
    """The outcome for one name of :meth:`Client.read_many`: a value or the error."""

    name: str
    text: str | None = None
    value: Any = None
    error: KvpError | None = None

    @property
    def ok(self) -> bool:
        return self.error is None

    def unwrap(self) -> Any:
        """The typed value if parsed, else the text; raises the stored error."""
        if self.error is not None:
            raise self.error
        return self.value if self.value is not None else self.text


class Client(RobotHelpers):
    """An asyncio KUKAVARPROXY client. Use ``async with Client(host) as kvp:``.

    ``timeout`` is the default for every call (each method takes ``timeout=`` to override).
    ``auto_reconnect`` opens a new connection on the next call after the old one was lost; calls
    in flight when it was lost fail (a write is never resent, so it is never applied twice).
    See :class:`~pyopenshowvar.connection.Connection` for ``max_in_flight``, ``pipeline_bytes``,
    ``id_policy`` and ``keepalive``.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 7000,
        *,
        timeout: float = 2.0,
        connect_timeout: float | None = None,
        auto_reconnect: bool = False,
        keepalive: float | None = 10.0,
        max_in_flight: int = 64,
        pipeline_bytes: int = 2048,
        id_policy: IdPolicy = "auto",
    ) -> None:
        self.host = host
        self.port = port
        self.timeout = timeout
        self.connect_timeout = connect_timeout if connect_timeout is not None else max(timeout, 1.0)
        self.auto_reconnect = auto_reconnect
        self._conn_kw: dict[str, Any] = {
            "timeout": timeout,
            "keepalive": keepalive,
            "max_in_flight": max_in_flight,
            "pipeline_bytes": pipeline_bytes,
            "id_policy": id_policy,
        }
        self._conn: Connection | None = None
        self._stats = AccessStats()
        self._connect_lock = asyncio.Lock()
        self.reconnects = 0

    # ------------------------------------------------------------------ connection

    @property
    def endpoint(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def connected(self) -> bool:
        return self._conn is not None and self._conn.is_open

    @property
    def stats(self) -> AccessStats:
        """Access times of every request made through this client (across reconnects)."""
        return self._stats

    @property
    def connection(self) -> Connection | None:
        return self._conn

    async def connect(self) -> None:
        async with self._connect_lock:
            if self.connected:
                return
            was_connected = self._conn is not None
            conn = await Connection.open(
                self.host, self.port, connect_timeout=self.connect_timeout, **self._conn_kw
            )
            conn.use_stats(self._stats)  # one statistics object survives reconnects
            self._conn = conn
            if was_connected:
                self.reconnects += 1
                log.info("reconnected to %s", self.endpoint)

    async def close(self) -> None:
        if self._conn is not None:
            await self._conn.close()

    async def __aenter__(self) -> Client:
        await self.connect()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()

    async def _connection(self) -> Connection:
        if self._conn is not None and self._conn.is_open:
            return self._conn
        if self._conn is None or self.auto_reconnect:
            await self.connect()
            assert self._conn is not None
            return self._conn
        raise KvpConnectionError(f"connection to {self.endpoint} is closed (auto_reconnect is off)")

    # ------------------------------------------------------------------ raw access

    async def read_reply(self, name: str, *, timeout: float | None = None) -> Reply:
        """The raw :class:`~pyopenshowvar.protocol.Reply` of a read, without interpretation."""
        conn = await self._connection()
        return await conn.read(name, timeout=timeout)

    async def read(self, name: str, *, timeout: float | None = None) -> str:
        """Read ``name`` and return the proxy's text (JOpenShowVar's ``simpleRead``).

        Raises :class:`UnknownVariableError` for KVP's empty-value-with-success answer and
        :class:`ReadFailedError` for a failure status.
        """
        return self._check_read(name, await self.read_reply(name, timeout=timeout))

    def _check_read(self, name: str, reply: Reply) -> str:
        if not reply.ok:
            if reply.mode is None:
                raise ReadFailedError(
                    "proxy does not support this request mode", name=name, endpoint=self.endpoint
                )
            raise ReadFailedError("read failed", name=name, endpoint=self.endpoint)
        if not reply.value:
            raise UnknownVariableError(
                "unknown or unreadable variable", name=name, endpoint=self.endpoint
            )
        return reply.text

    async def read_value(
        self, name: str, type_name: str | None = None, *, timeout: float | None = None
    ) -> KrlValue:
        """Read and parse ``name`` into a typed KRL value (see :mod:`pyopenshowvar.krl`).

        ``type_name`` ("INT", "E6POS", "REAL[]", ...) coerces and validates; without it the type
        is inferred from the text.
        """
        text = await self.read(name, timeout=timeout)
        return self._parse(name, text, type_name)

    def _parse(self, name: str, text: str, type_name: str | None) -> KrlValue:
        try:
            return parse_value(text, type_name)
        except KrlValueError as exc:
            raise KrlValueError(f"{name!r} on {self.endpoint}: {exc}") from exc

    async def write(self, name: str, value: KrlValue | str, *, timeout: float | None = None) -> str:
        """Write ``value`` to ``name`` and return the proxy's echo once it acknowledged.

        A ``str`` is sent as raw KRL text (JOpenShowVar's ``simpleWrite``: ``"50"``,
        ``"{X 1.5, Y 2.0}"``, ``'"text"'`` for a CHAR array). Any other value is formatted as a
        KRL literal (ints, floats, bools, :class:`KrlEnum`, structs, lists). A failure status
        raises :class:`WriteRefusedError`; the call never returns before the proxy answered.
        """
        text = value if isinstance(value, str) else format_value(value)
        conn = await self._connection()
        reply = await conn.write(name, text, timeout=timeout)
        if not reply.ok:
            raise WriteRefusedError(
                "write refused (read-only, unknown variable or wrong type)",
                name=name,
                endpoint=self.endpoint,
                value=text,
            )
        return reply.text

    async def read_many(
        self,
        names: Iterable[str],
        *,
        typed: bool = False,
        timeout: float | None = None,
    ) -> dict[str, ReadResult]:
        """Read many variables in one await, pipelined on the connection.

        Returns one :class:`ReadResult` per name (in the order given); an unknown variable or
        a parse failure of one name does not fail the others. A lost connection or a timeout
        of the whole batch still raises.
        """
        names = list(names)
        conn = await self._connection()
        replies = await conn.request_many([(n, _reader(n)) for n in names], timeout=timeout)
        out: dict[str, ReadResult] = {}
        for name, reply in zip(names, replies, strict=True):
            if isinstance(reply, KvpError):
                out[name] = ReadResult(name, error=reply)
                continue
            try:
                text = self._check_read(name, reply)
                value = self._parse(name, text, None) if typed else None
            except KvpError as exc:
                out[name] = ReadResult(name, text=reply.text or None, error=exc)
                continue
            out[name] = ReadResult(name, text=text, value=value)
        return out

    async def write_many(
        self, items: Sequence[tuple[str, KrlValue | str]], *, timeout: float | None = None
    ) -> None:
        """Write several variables pipelined, in order; raises the first failure after all answered."""
        texts = [(n, v if isinstance(v, str) else format_value(v)) for n, v in items]
        conn = await self._connection()
        replies = await conn.request_many([(n, _writer(n, t)) for n, t in texts], timeout=timeout)
        for (name, text), reply in zip(texts, replies, strict=True):
            if isinstance(reply, KvpError):
                raise reply
            if not reply.ok:
                raise WriteRefusedError(
                    "write refused (read-only, unknown variable or wrong type)",
                    name=name,
                    endpoint=self.endpoint,
                    value=text,
                )

    # ------------------------------------------------------------------ PLC array modes

    async def read_array_words(self, name: str, *, timeout: float | None = None) -> list[int]:
        """KVP mode 2: the whole array as 16-bit words (KVP packs each value token)."""
        conn = await self._connection()
        reply = await conn.request_frame(
            name, lambda i: encode_read_array(i, name), timeout=timeout
        )
        if not reply.ok:
            what = (
                "proxy does not support array mode 2" if reply.mode is None else "array read failed"
            )
            raise ReadFailedError(what, name=name, endpoint=self.endpoint)
        return reply.words()

    async def write_array_words(
        self, name: str, words: Sequence[int], *, timeout: float | None = None
    ) -> None:
        """KVP mode 3: write ``words`` to NAME[1..k]; the status covers the last element only."""
        conn = await self._connection()
        reply = await conn.request_frame(
            name, lambda i: encode_write_array(i, name, words), timeout=timeout
        )
        if not reply.ok:
            raise WriteRefusedError("array write refused", name=name, endpoint=self.endpoint)

    # ------------------------------------------------------------------ misc

    async def ping(self, *, timeout: float | None = None) -> float:
        """One keep-alive round trip (``PING``/``PONG`` on KVP 9.0), in seconds."""
        conn = await self._connection()
        return await conn.ping(timeout=timeout)

    async def proxy_type(self) -> str | None:
        """``@PROXY_TYPE`` (C3 Bridge and our emulator answer it; KVP gives None)."""
        try:
            return await self.read("@PROXY_TYPE")
        except (UnknownVariableError, ReadFailedError):
            return None


def _reader(name: str) -> Callable[[int], bytes]:
    return lambda msg_id: encode_read(msg_id, name)


def _writer(name: str, text: str) -> Callable[[int], bytes]:
    return lambda msg_id: encode_write(msg_id, name, text)


def connect(host: str = "127.0.0.1", port: int = 7000, **kw: Any) -> Client:
    """Shorthand: ``async with connect(host) as kvp:``."""
    return Client(host, port, **kw)
