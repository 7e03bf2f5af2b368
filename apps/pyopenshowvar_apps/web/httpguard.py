"""Slow and greedy HTTP clients: a request-head timeout and connection caps for uvicorn.

uvicorn waits for a request head as long as the client keeps sending bytes (every byte resets
its keep-alive timer), and answers every request with 503 once ``limit_concurrency``
connections are open, so 80 sockets sending a header byte every 2 s (slowloris) once kept the
page from loading for as long as they kept going. :func:`guarded_protocols` gives uvicorn's
own HTTP and WebSocket protocols (``uvicorn.Config(http=..., ws=...)``) a shared
:class:`ConnectionGuard`:

* a connection must deliver a whole request head within :data:`HEAD_TIMEOUT` seconds of
  connecting, or of its previous response (so an idle keep-alive connection is closed after
  the same time); otherwise it gets ``408`` and is closed, however many bytes it trickles;
* at most :data:`PER_ADDRESS` connections per client address and :data:`TOTAL` in all
  (WebSockets included): a connection beyond either gets ``503`` and is closed at once,
  before it costs a parser.

One attacking address can therefore hold at most :data:`PER_ADDRESS` connections, each for
at most :data:`HEAD_TIMEOUT`, and a page from any other address still loads at once.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable
from typing import Any

from uvicorn.protocols.http.h11_impl import H11Protocol
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

__all__ = [
    "HEAD_TIMEOUT",
    "PER_ADDRESS",
    "TOTAL",
    "ConnectionGuard",
    "LogLimit",
    "guarded_protocols",
]

log = logging.getLogger(__name__)

#: Seconds a client has to send a whole request head (a browser sends it in one packet).
HEAD_TIMEOUT = 2.0
#: Connections per client address: a browser opens up to 6 to a host, plus the WebSocket,
#: so two tabs of one phone fit.
PER_ADDRESS = 16
#: Connections in all (``limit_concurrency`` of uvicorn is the same number).
TOTAL = 64

_TIMEOUT = b"HTTP/1.1 408 Request Timeout\r\nConnection: close\r\nContent-Length: 0\r\n\r\n"
_BUSY = b"HTTP/1.1 503 Service Unavailable\r\nConnection: close\r\nContent-Length: 0\r\n\r\n"


class LogLimit:
    """At most one log line per key every ``period`` seconds; the next one says how many were
    left out. An attacker must not be able to fill the log (or spend the server's time on it)."""

    def __init__(
        self,
        logger: logging.Logger,
        period: float = 10.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.logger, self.period, self.clock = logger, period, clock
        self._last: dict[str, tuple[float, int]] = {}

    def warning(self, key: str, message: str, *args: object) -> None:
        now = self.clock()
        last, skipped = self._last.get(key, (-math.inf, 0))
        if now - last < self.period:
            self._last[key] = (last, skipped + 1)
            return
        if len(self._last) > 1000:  # bounded: forget the quiet keys
            self._last = {k: v for k, v in self._last.items() if now - v[0] < self.period}
        self._last[key] = (now, 0)
        more = f" (and {skipped} more like it)" if skipped else ""
        self.logger.warning(message + more, *args)


class ConnectionGuard:
    """The open connections per client address, and what was refused (counters)."""

    def __init__(
        self,
        *,
        per_address: int = PER_ADDRESS,
        total: int = TOTAL,
        head_timeout: float = HEAD_TIMEOUT,
    ) -> None:
        self.per_address, self.total, self.head_timeout = per_address, total, head_timeout
        self.open: dict[str, set[asyncio.BaseTransport]] = {}
        self.count = 0
        #: Connections refused for a cap, and closed for a late request head.
        self.refused = 0
        self.timed_out = 0
        self.log = LogLimit(log)

    @staticmethod
    def address(transport: asyncio.BaseTransport) -> str:
        peer = transport.get_extra_info("peername")
        return str(peer[0]) if isinstance(peer, tuple) and peer else "?"

    def admit(self, transport: asyncio.BaseTransport) -> bool:
        """Count a new connection in; False (and nothing counted) when a cap is reached."""
        address = self.address(transport)
        conns = self.open.get(address, set())
        if transport in conns:
            return True  # an upgrade to a WebSocket: the same connection
        if len(conns) >= self.per_address or self.count >= self.total:
            self.refused += 1
            return False
        conns.add(transport)
        self.open[address] = conns
        self.count += 1
        return True

    def release(self, transport: asyncio.BaseTransport) -> None:
        address = self.address(transport)
        conns = self.open.get(address)
        if conns is None or transport not in conns:
            return
        conns.discard(transport)
        self.count -= 1
        if not conns:
            del self.open[address]


def guarded_protocols(
    guard: ConnectionGuard,
) -> tuple[type[H11Protocol], type[WebSocketsSansIOProtocol]]:
    """uvicorn's h11 and websockets-sansio protocols, bound to ``guard``."""

    class GuardedHttp(H11Protocol):
        _refused = False
        _head_timer: asyncio.TimerHandle | None = None

        def connection_made(self, transport: Any) -> None:
            if not guard.admit(transport):
                self._refused = True
                self.transport = transport
                address = guard.address(transport)
                guard.log.warning(address, "refused connections from %s: too many", address)
                transport.write(_BUSY)
                transport.close()
                return
            super().connection_made(transport)
            self._arm()

        def data_received(self, data: bytes) -> None:
            if not self._refused:
                super().data_received(data)

        def on_response_complete(self) -> None:
            super().on_response_complete()
            self._arm()  # the next request head (keep-alive) has the same time

        def handle_websocket_upgrade(self, event: Any) -> None:
            self._disarm()  # the WebSocket protocol owns the connection from here on
            super().handle_websocket_upgrade(event)

        def connection_lost(self, exc: Exception | None) -> None:
            self._disarm()
            guard.release(self.transport)
            if not self._refused:
                super().connection_lost(exc)

        def _arm(self) -> None:
            self._disarm()
            if not self.transport.is_closing():
                self._head_timer = self.loop.call_later(guard.head_timeout, self._late_head)

        def _disarm(self) -> None:
            if self._head_timer is not None:
                self._head_timer.cancel()
                self._head_timer = None

        def _late_head(self) -> None:
            self._head_timer = None
            serving = self.cycle is not None and not self.cycle.response_complete
            if serving or self.transport.is_closing():
                return  # a whole request arrived: the response is on its way
            guard.timed_out += 1
            log.info("closed a connection from %s: no request head within %.3g s",
                     guard.address(self.transport), guard.head_timeout)  # fmt: skip
            self.transport.write(_TIMEOUT)
            self.transport.close()

    class GuardedWebSocket(WebSocketsSansIOProtocol):
        def connection_made(self, transport: Any) -> None:
            guard.admit(transport)  # counted already as the HTTP connection it upgrades
            super().connection_made(transport)

        def connection_lost(self, exc: Exception | None) -> None:
            guard.release(self.transport)
            super().connection_lost(exc)

    return GuardedHttp, GuardedWebSocket
