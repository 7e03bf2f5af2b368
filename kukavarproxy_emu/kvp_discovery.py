"""UDP discovery, as KUKAVARPROXY answers it (reference §2.7).

KVP listens on UDP 6999 for the 12-byte text ``WHEREAREYOU?`` and answers
``KUKA|<$MODEL_NAME[] without quotes>|<$KR_SERIALNO>`` to the asker's IP on UDP 7000 (not to
the source port; OpenShowVar listens on 7000). Both ports are configurable; a reply port of 0
answers to the sender's own port, which is handy for tests and is what C3 Bridge's "standard"
mode does.

Answers are rate-limited (a token bucket, ``RATE`` answers a second with bursts of ``BURST``):
a discovery answer goes to whatever address the datagram claims to come from, so without a
limit anyone could aim a stream of answers at a third host through the emulator.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import cast

from .logsafe import clip

__all__ = ["BURST", "QUERY", "RATE", "DiscoveryProtocol", "start_discovery"]

log = logging.getLogger(__name__)

QUERY = b"WHEREAREYOU?"
#: Discovery answers per second at most, on average, and in one burst.
RATE = 10.0
BURST = 20


class DiscoveryProtocol(asyncio.DatagramProtocol):
    """Answers discovery queries; ``identity()`` returns (model, serial) at the time of asking."""

    def __init__(
        self,
        identity: Callable[[], tuple[str, str]],
        reply_port: int,
        *,
        rate: float = RATE,
        burst: int = BURST,
    ) -> None:
        self._identity = identity
        self._reply_port = reply_port
        self._transport: asyncio.DatagramTransport | None = None
        self.answered = 0
        #: Queries left unanswered because of the rate limit.
        self.refused = 0
        self._rate = rate
        self._burst = float(burst)
        self._tokens = float(burst)
        self._refill = time.monotonic()

    def _allow(self) -> bool:
        now = time.monotonic()
        self._tokens = min(self._burst, self._tokens + (now - self._refill) * self._rate)
        self._refill = now
        if self._tokens < 1.0:
            return False
        self._tokens -= 1.0
        return True

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # The selector loop's datagram transport does not subclass DatagramTransport in 3.11.
        self._transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str | int, ...]) -> None:
        # Tolerate a trailing newline or NUL from hand-written tools; anything else is ignored,
        # as KVP ignores it.
        if data.rstrip(b"\r\n\x00") != QUERY or self._transport is None:
            return
        if not self._allow():
            self.refused += 1
            if self.refused == 1 or not self.refused % 1000:
                log.warning("discovery: rate limit, %d queries left unanswered", self.refused)
            return
        try:
            model, serial = self._identity()
            answer = f"KUKA|{model}|{serial}".encode("latin-1", errors="replace")
            host = addr[0]
            port = self._reply_port or addr[1]
            self._transport.sendto(answer, (host, port))
            self.answered += 1
            log.debug("discovery: answered %s:%s", clip(str(host)), port)
        except Exception:  # a bad datagram or store must never stop the listener
            log.exception("discovery: could not answer %s", clip(str(addr)))

    def error_received(self, exc: Exception) -> None:
        # ICMP "port unreachable" after answering a host without a listener: harmless.
        log.debug("discovery: %s", exc)


async def start_discovery(
    host: str, port: int, reply_port: int, identity: Callable[[], tuple[str, str]]
) -> tuple[asyncio.DatagramTransport, DiscoveryProtocol]:
    """Bind the UDP listener; raises OSError when the port is taken."""
    loop = asyncio.get_running_loop()
    transport, protocol = await loop.create_datagram_endpoint(
        lambda: DiscoveryProtocol(identity, reply_port), local_addr=(host, port)
    )
    return transport, protocol
