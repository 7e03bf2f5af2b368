"""The synchronous client: the asyncio client's API as blocking calls.

For plain scripts, Jupyter notebooks and users of py-openshowvar::

    from pyopenshowvar.sync import Client

    with Client("192.168.1.10", 7000, timeout=1.0) as kvp:
        print(kvp.read("$OV_PRO"))                  # raw text
        q = kvp.read_joint_angles()                 # numpy (6,)
        kvp.write("$OV_PRO", 50)
        results = kvp.read_many(["$OV_PRO", "$MODE_OP"])   # still pipelined

Same constructor, method names, exceptions and timeouts as :class:`pyopenshowvar.Client`; the
replies are interpreted by the same code (:mod:`pyopenshowvar.core`), ids are matched by the
same rules (:mod:`pyopenshowvar.session`) and the robot helpers are the same operations
(:mod:`pyopenshowvar.robot`). It runs on a blocking socket (:mod:`pyopenshowvar.blocking`), not
on an event loop in a thread, so it works inside a running loop (a notebook) too. One client
may be shared by threads: calls are serialised by a lock.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from types import TracebackType
from typing import Any

from .blocking import BlockingConnection
from .c3.api import SyncC3Methods
from .core import ClientCore, ReadResult
from .errors import KvpError, KvpStalledError
from .krl import KrlValue
from .protocol import Reply, encode_read, encode_read_array, encode_write, encode_write_array
from .robot import SyncRobotHelpers

__all__ = ["Client", "ReadResult", "connect"]

log = logging.getLogger(__name__)


class Client(SyncC3Methods, SyncRobotHelpers, ClientCore):
    """A blocking KUKAVARPROXY client. Use ``with Client(host) as kvp:``.

    Arguments are those of the asyncio :class:`pyopenshowvar.Client`: ``timeout`` is the
    default of every call (each takes ``timeout=``), ``auto_reconnect`` opens a new connection
    on the next call after a loss or a stall (a write in flight is never resent),
    ``keepalive`` pings an idle connection from a daemon thread, and ``max_in_flight``,
    ``pipeline_bytes`` and ``id_policy`` bound and match pipelined requests.
    """

    _conn: BlockingConnection | None = None

    # ------------------------------------------------------------------ connection

    @property
    def connected(self) -> bool:
        """True while the connection is open and healthy (not lost, dropped or stalled)."""
        return self._conn is not None and self._conn.is_open

    @property
    def connection(self) -> BlockingConnection | None:
        return self._conn

    def connect(self) -> None:
        with self._sync_lock:
            if self.connected:
                return
            was_connected = self._conn is not None
            conn = BlockingConnection(self.host, self.port, **self._conn_kw)
            conn.connect(self.connect_timeout)
            conn.use_stats(self._stats)  # one statistics object survives reconnects
            self._conn = conn
            if was_connected:
                self.reconnects += 1
                log.info("reconnected to %s", self.endpoint)

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()

    def __enter__(self) -> Client:
        self.connect()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _connection(self) -> BlockingConnection:
        conn = self._conn
        if conn is not None and conn.is_open:
            return conn
        if conn is None or self.auto_reconnect:
            self.connect()
            assert self._conn is not None
            return self._conn
        raise self._closed_error(conn.closed_reason)

    def _request(self, name: str, frame0: bytes, timeout: float | None) -> Reply:
        conn = self._conn
        if conn is None or not conn.is_open:
            conn = self._connection()
        try:
            return conn.request(name, frame0, timeout)
        except KvpStalledError as exc:
            self._may_retry(exc)  # nothing was sent: safe to send on a new connection
        return self._connection().request(name, frame0, timeout)

    def _request_many(
        self, items: list[tuple[str, bytes]], timeout: float | None
    ) -> list[Reply | KvpError]:
        try:
            return self._connection().request_many(items, timeout)
        except KvpStalledError as exc:
            self._may_retry(exc)
        return self._connection().request_many(items, timeout)

    # ------------------------------------------------------------------ raw access

    def read_reply(self, name: str, *, timeout: float | None = None) -> Reply:
        """The raw :class:`~pyopenshowvar.protocol.Reply` of a read, without interpretation."""
        return self._request(name, encode_read(0, name), timeout)

    def read(self, name: str, *, timeout: float | None = None) -> str:
        """Read ``name`` and return the proxy's text (raises ``UnknownVariableError`` for
        KVP's empty-value-with-success answer, ``ReadFailedError`` for a failure status)."""
        conn = self._conn
        if conn is not None:  # the serial fast path first, without the retry wrapper
            out = conn.idle_request(name, timeout)
            if isinstance(out, str):
                return out  # checked: success status, non-empty value
            if out is not None:
                return self._check_read(name, out)
        frame0 = self._read_frames.get(name) or self._read_frame(name)
        return self._check_read(name, self._request(name, frame0, timeout))

    def read_value(
        self, name: str, type_name: str | None = None, *, timeout: float | None = None
    ) -> KrlValue:
        """Read and parse ``name`` into a typed KRL value (``type_name`` coerces, e.g. "E6POS")."""
        return self._parse(name, self.read(name, timeout=timeout), type_name)

    def write(self, name: str, value: KrlValue | str, *, timeout: float | None = None) -> str:
        """Write ``value`` (typed, or a ``str`` sent as raw KRL text) and return the proxy's
        echo once it acknowledged; a failure status raises ``WriteRefusedError``."""
        text = self._text(value)
        reply = self._request(name, encode_write(0, name, text), timeout)
        return self._check_write(name, text, reply)

    def read_many(
        self, names: Iterable[str], *, typed: bool = False, timeout: float | None = None
    ) -> dict[str, ReadResult]:
        """Read many variables pipelined on the connection: one :class:`ReadResult` per name."""
        names = list(names)
        replies = self._request_many([(n, encode_read(0, n)) for n in names], timeout)
        return self._read_results(names, replies, typed)

    def write_many(
        self, items: Sequence[tuple[str, KrlValue | str]], *, timeout: float | None = None
    ) -> None:
        """Write several variables pipelined, in order; raises the first failure after all answered."""
        texts = [(n, self._text(v)) for n, v in items]
        frames = [(n, encode_write(0, n, t)) for n, t in texts]
        self._check_writes(texts, self._request_many(frames, timeout))

    # ------------------------------------------------------------------ PLC array modes

    def read_array_words(self, name: str, *, timeout: float | None = None) -> list[int]:
        """KVP mode 2: the whole array as 16-bit words (KVP packs each value token)."""
        return self._check_array_read(
            name, self._request(name, encode_read_array(0, name), timeout)
        )

    def write_array_words(
        self, name: str, words: Sequence[int], *, timeout: float | None = None
    ) -> None:
        """KVP mode 3: write ``words`` to NAME[1..k]; the status covers the last element only."""
        reply = self._request(name, encode_write_array(0, name, words), timeout)
        self._check_array_write(name, reply)

    # ------------------------------------------------------------------ misc

    def ping(self, *, timeout: float | None = None) -> float:
        """One keep-alive round trip (``PING``/``PONG`` on KVP 9.0), in seconds."""
        return self._connection().ping(timeout)

    def proxy_type(self) -> str | None:
        """``@PROXY_TYPE`` (C3 Bridge and our emulator answer it; KVP gives None)."""
        try:
            return self._proxy_type(self.read("@PROXY_TYPE"))
        except KvpError as exc:
            return self._proxy_type(exc)


def connect(host: str = "127.0.0.1", port: int = 7000, **kw: Any) -> Client:
    """Shorthand: ``with connect(host) as kvp:``."""
    return Client(host, port, **kw)
