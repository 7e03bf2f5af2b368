"""C3 Bridge's UDP discovery: ``WHEREAREYOU?`` plus ``@PROXY_*`` queries, legacy and standard.

The server (``source/udpserver.cpp``) answers a datagram that is exactly ``WHEREAREYOU?`` with
``KUKA|<model>|<serial>``, and one that starts with ``@`` with that internal variable's value
(``@PROXY_TYPE`` → ``C3 BRIDGE INTERFACE``; nothing for an unknown name). It listens twice
(spec §1.2): in *legacy* mode on UDP 6999 answering to port 7000, as KUKAVARPROXY does, and in
*standard* mode on UDP 7000 answering to the sender's port.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

from ..kvp_discovery import DiscoveryProtocol

__all__ = ["C3DiscoveryProtocol", "start_c3_discovery"]

log = logging.getLogger(__name__)

#: The server reads datagrams into a 32-byte buffer (31 usable characters).
_MAX_QUERY = 31


class C3DiscoveryProtocol(DiscoveryProtocol):
    """Discovery plus ``@`` queries answered from ``internal(name)``."""

    def __init__(
        self,
        identity: Callable[[], tuple[str, str]],
        reply_port: int,
        internal: Callable[[str], str | None],
    ) -> None:
        super().__init__(identity, reply_port)
        self._internal = internal

    def datagram_received(self, data: bytes, addr: tuple[str | int, ...]) -> None:
        if not data.startswith(b"@"):
            super().datagram_received(data, addr)
            return
        transport = self._transport
        if transport is None:
            return
        name = data[:_MAX_QUERY].split(b"\x00", 1)[0].decode("latin-1")
        try:
            value = self._internal(name)
        except Exception:  # a bad query must never stop the listener
            log.exception("discovery: could not answer %r", name)
            return
        if value:
            transport.sendto(
                value.encode("latin-1", "replace"), (addr[0], self._reply_port or addr[1])
            )


async def start_c3_discovery(
    host: str,
    port: int,
    reply_port: int,
    identity: Callable[[], tuple[str, str]],
    internal: Callable[[str], str | None],
) -> tuple[asyncio.DatagramTransport, C3DiscoveryProtocol]:
    """Bind one C3 discovery listener; raises OSError when the port is taken."""
    loop = asyncio.get_running_loop()
    transport, protocol = await loop.create_datagram_endpoint(
        lambda: C3DiscoveryProtocol(identity, reply_port, internal), local_addr=(host, port)
    )
    return transport, protocol
