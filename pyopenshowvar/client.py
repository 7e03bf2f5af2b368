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
import importlib
import logging
from collections.abc import Coroutine, Iterable, Sequence
from types import TracebackType
from typing import Any, TypeVar

from .c3.api import C3Methods
from .connection import Connection
from .core import ClientCore, ReadResult
from .errors import KvpError, KvpStalledError
from .krl import KrlValue
from .protocol import Reply, encode_read, encode_read_array, encode_write, encode_write_array
from .robot import RobotHelpers

__all__ = ["Client", "ReadResult", "connect", "run"]

log = logging.getLogger(__name__)
T = TypeVar("T")


class Client(C3Methods, RobotHelpers, ClientCore):
    """An asyncio KUKAVARPROXY client. Use ``async with Client(host) as kvp:``.

    ``timeout`` is the default for every call (each method takes ``timeout=`` to override).
    ``auto_reconnect`` opens a new connection on the next call after the old one was lost or
    found stalled; calls in flight when it was lost fail (a write is never resent, so it is
    never applied twice). See :class:`~pyopenshowvar.connection.Connection` for
    ``max_in_flight``, ``pipeline_bytes`` and ``keepalive``, and :mod:`pyopenshowvar.session`
    for ``id_policy``. The C3 Bridge methods (``read_multiple``, ``program_start``,
    ``file_write``, ...) come from :class:`~pyopenshowvar.c3.api.C3Methods` and refuse, before
    sending, what the server does not offer (docs/c3bridge.md).
    """

    _conn: Connection | None = None
    _lock: asyncio.Lock | None = None

    # ------------------------------------------------------------------ connection

    @property
    def connected(self) -> bool:
        """True while the connection is open and healthy (not lost, dropped or stalled)."""
        return self._conn is not None and self._conn.is_open

    @property
    def connection(self) -> Connection | None:
        return self._conn

    async def connect(self) -> None:
        if self._lock is None:
            self._lock = asyncio.Lock()
        async with self._lock:
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
        conn = self._conn
        if conn is not None and conn.is_open:
            return conn
        if conn is None or self.auto_reconnect:
            await self.connect()
            assert self._conn is not None
            return self._conn
        raise self._closed_error(conn.closed_reason)

    async def _request(self, name: str, frame0: bytes, timeout: float | None) -> Reply:
        conn = self._conn
        if conn is None or not conn.is_open:
            conn = await self._connection()
        try:
            return await conn._request(name, frame0, timeout)
        except KvpStalledError as exc:
            self._may_retry(exc)  # nothing was sent: safe to send on a new connection
        return await (await self._connection())._request(name, frame0, timeout)

    async def _request_many(
        self, items: list[tuple[str, bytes]], timeout: float | None
    ) -> list[Reply | KvpError]:
        conn = await self._connection()
        try:
            return await conn._request_many(items, timeout)
        except KvpStalledError as exc:
            self._may_retry(exc)
        return await (await self._connection())._request_many(items, timeout)

    # ------------------------------------------------------------------ raw access

    async def read_reply(self, name: str, *, timeout: float | None = None) -> Reply:
        """The raw :class:`~pyopenshowvar.protocol.Reply` of a read, without interpretation."""
        return await self._request(name, encode_read(0, name), timeout)

    async def read(self, name: str, *, timeout: float | None = None) -> str:
        """Read ``name`` and return the proxy's text (JOpenShowVar's ``simpleRead``).

        Raises :class:`UnknownVariableError` for KVP's empty-value-with-success answer and
        :class:`ReadFailedError` for a failure status.
        """
        frame0 = self._read_frames.get(name) or self._read_frame(name)
        conn = self._conn
        if conn is not None and conn.is_open:  # the hot path, without the retry wrapper
            try:
                return self._check_read(name, await conn._request(name, frame0, timeout))
            except KvpStalledError as exc:
                self._may_retry(exc)
        return self._check_read(name, await self._request(name, frame0, timeout))

    async def read_value(
        self, name: str, type_name: str | None = None, *, timeout: float | None = None
    ) -> KrlValue:
        """Read and parse ``name`` into a typed KRL value (see :mod:`pyopenshowvar.krl`).

        ``type_name`` ("INT", "E6POS", "REAL[]", ...) coerces and validates; without it the type
        is inferred from the text.
        """
        return self._parse(name, await self.read(name, timeout=timeout), type_name)

    async def write(self, name: str, value: KrlValue | str, *, timeout: float | None = None) -> str:
        """Write ``value`` to ``name`` and return the proxy's echo once it acknowledged.

        A ``str`` is sent as raw KRL text (JOpenShowVar's ``simpleWrite``: ``"50"``,
        ``"{X 1.5, Y 2.0}"``, ``'"text"'`` for a CHAR array). Any other value is formatted as a
        KRL literal (ints, floats, bools, :class:`KrlEnum`, structs, lists). A failure status
        raises :class:`WriteRefusedError`; the call never returns before the proxy answered.
        """
        text = self._text(value)
        reply = await self._request(name, encode_write(0, name, text), timeout)
        return self._check_write(name, text, reply)

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
        frames = self._read_frames  # a poller asks for the same names again and again
        items = [(n, frames.get(n) or self._read_frame(n)) for n in names]
        replies = await self._request_many(items, timeout)
        return self._read_results(names, replies, typed)

    async def write_many(
        self, items: Sequence[tuple[str, KrlValue | str]], *, timeout: float | None = None
    ) -> None:
        """Write several variables pipelined, in order; raises the first failure after all answered."""
        texts = [(n, self._text(v)) for n, v in items]
        frames = [(n, encode_write(0, n, t)) for n, t in texts]
        self._check_writes(texts, await self._request_many(frames, timeout))

    # ------------------------------------------------------------------ PLC array modes

    async def read_array_words(self, name: str, *, timeout: float | None = None) -> list[int]:
        """KVP mode 2: the whole array as 16-bit words (KVP packs each value token)."""
        reply = await self._request(name, encode_read_array(0, name), timeout)
        return self._check_array_read(name, reply)

    async def write_array_words(
        self, name: str, words: Sequence[int], *, timeout: float | None = None
    ) -> None:
        """KVP mode 3: write ``words`` to NAME[1..k]; the status covers the last element only."""
        reply = await self._request(name, encode_write_array(0, name, words), timeout)
        self._check_array_write(name, reply)

    # ------------------------------------------------------------------ misc

    async def ping(self, *, timeout: float | None = None) -> float:
        """One keep-alive round trip (``PING``/``PONG`` on KVP 9.0), in seconds."""
        conn = await self._connection()
        return await conn.ping(timeout=timeout)

    async def proxy_type(self) -> str | None:
        """``@PROXY_TYPE`` (C3 Bridge and our emulator answer it; KVP gives None)."""
        try:
            return self._proxy_type(await self.read("@PROXY_TYPE"))
        except KvpError as exc:
            return self._proxy_type(exc)


def run(main: Coroutine[Any, Any, T]) -> T:
    """``asyncio.run(main)``, on uvloop when it is installed.

    uvloop's event loop cuts the client's share of a serial round trip roughly in half (see
    docs/BENCHMARKS.md); it is optional, and the client works the same on either loop.
    """
    try:
        uvloop = importlib.import_module("uvloop")
    except ImportError:
        return asyncio.run(main)
    result: T = uvloop.run(main)
    return result


def connect(host: str = "127.0.0.1", port: int = 7000, **kw: Any) -> Client:
    """Shorthand: ``async with connect(host) as kvp:``."""
    return Client(host, port, **kw)
