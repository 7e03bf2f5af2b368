"""What the asyncio and the blocking connection have in common, without any I/O.

:class:`LinkBase` holds one connection's configuration, its :class:`~.session.Session`, its
reply decoder, statistics and life-cycle state, and the decisions both transports make the
same way: how a failed connect is reported, and which keep-alive request an old proxy gets.
"""

from __future__ import annotations

import logging
import socket
import time
from typing import Generic, TypeVar

from .errors import KvpConnectionError, KvpError, KvpTimeoutError
from .protocol import Reply, ReplyDecoder, encode_read
from .session import IdPolicy, Session
from .stats import AccessStats

__all__ = ["LinkBase"]

log = logging.getLogger(__name__)

W = TypeVar("W")

_PING = encode_read(0, "PING")
_OV_PRO = encode_read(0, "$OV_PRO")


class LinkBase(Generic[W]):
    """State shared by :class:`~.connection.Connection` and :class:`~.blocking.BlockingConnection`."""

    def __init__(
        self,
        host: str,
        port: int,
        *,
        timeout: float = 2.0,
        max_in_flight: int = 64,
        pipeline_bytes: int = 2048,
        id_policy: IdPolicy = "auto",
        keepalive: float | None = 10.0,
    ) -> None:
        self.host = host
        self.port = port
        self.timeout = timeout
        self.keepalive = keepalive
        self.session: Session[W] = Session(
            self.endpoint,
            max_in_flight=max_in_flight,
            pipeline_bytes=pipeline_bytes,
            id_policy=id_policy,
        )
        self.stats = AccessStats()
        self._decoder = ReplyDecoder()
        self._closed_reason: str | None = None
        self._last_activity = time.perf_counter()
        self._ping_supported: bool | None = None

    @property
    def endpoint(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def id_policy(self) -> IdPolicy:
        return self.session.id_policy

    @property
    def mislabeled_replies(self) -> int:
        """Replies matched in order because they repeated their batch's id (pre-9.0 proxies)."""
        return self.session.mislabeled_replies

    @property
    def dropped_requests(self) -> int:
        """Requests the server never answered (detected when a later reply arrived)."""
        return self.session.dropped_requests

    @property
    def closed_reason(self) -> str | None:
        """Why the connection was closed, lost or dropped (None while open)."""
        return self._closed_reason

    @property
    def in_flight(self) -> int:
        return len(self.session.queue)

    def use_stats(self, stats: AccessStats) -> None:
        """Record into ``stats`` (the client keeps one object across reconnects)."""
        self.stats = stats

    def _connected(self, sock: socket.socket | None) -> None:
        """Socket options and the segment bound of a new connection (both transports)."""
        if sock is None:
            return
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        try:
            mss = sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_MAXSEG)
        except (OSError, AttributeError):
            mss = 1460  # Ethernet, a KRC's KLI, where the OS does not tell
        self.session.limit_to_segment(mss)

    def _connect_error(self, exc: OSError, timeout: float) -> KvpError:
        if isinstance(exc, TimeoutError):
            return KvpTimeoutError(f"connecting to {self.endpoint} timed out after {timeout:g} s")
        return KvpConnectionError(f"cannot connect to {self.endpoint}: {exc.strerror or exc}")

    def _check_open(self) -> None:
        if self._closed_reason is not None:
            raise KvpConnectionError(
                f"connection to {self.endpoint} is closed: {self._closed_reason}"
            )

    def _eof_reason(self, exc: BaseException | None = None) -> str:
        """Why the peer's close ended the connection (mid-reply or not)."""
        try:
            self._decoder.eof()
        except KvpError:
            return f"{self.endpoint} closed the connection in the middle of a reply"
        return f"{self.endpoint} closed the connection" + (f": {exc}" if exc else "")

    # keep-alive: PING on KVP 9.0; an older proxy answers it with an empty value, and from then
    # on a cheap read of $OV_PRO keeps its idle timer from closing the connection

    def _keepalive_frame(self) -> tuple[str, bytes]:
        return ("$OV_PRO", _OV_PRO) if self._ping_supported is False else ("PING", _PING)

    def _keepalive_answered(self, name: str, reply: Reply) -> bool:
        """Record what the keep-alive reply says; True when no second request is needed."""
        if name != "PING":
            return True
        self._ping_supported = reply.ok and reply.value == b"PONG"
        if not self._ping_supported:
            log.info(
                "%s does not answer PING (pre-9.0 proxy); keeping alive with $OV_PRO", self.endpoint
            )
        return self._ping_supported
