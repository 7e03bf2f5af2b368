"""What every KVP client connection of the emulator shares: its budgets, its host, its socket.

Both connection classes (the robust :class:`~kukavarproxy_emu.kvp_connection.KvpConnection`
and the wire-faithful :class:`~kukavarproxy_emu.kvp9_connection.Kvp9Connection`) are served
by an :class:`~kukavarproxy_emu.server.Emulator`, which they see only through :class:`Host`:
the emulator admits a connection (or refuses it: the client limit), forgets it when it
closes, and serves the backlogs of those it has enqueued in rounds (``SLICE`` each,
``ROUND`` in all per event-loop iteration). :class:`Connection` is the socket plumbing both
share: the peer's address, the admission, ``TCP_NODELAY``, one fixed read buffer.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from .logsafe import RateLimitedLog

if TYPE_CHECKING:
    from .config import EmulatorConfig
    from .faults import FaultSet
    from .latency import ServiceQueue
    from .responder import Responder
    from .robot_task import Robot

__all__ = [
    "IMMEDIATE",
    "ROUND",
    "SLICE",
    "Connection",
    "ConnectionInfo",
    "Host",
    "Stats",
]

log = logging.getLogger(__name__)
#: Connection lines any client can provoke at will (connect, garbage, EOF): rate-limited.
limited_conn = RateLimitedLog(log, burst=20)

#: Seconds of request handling a connection gets right away when a read arrives: a client
#: with a few requests is answered at once, a big batch goes on in the rounds below.
IMMEDIATE = 0.0003
#: Seconds of request handling one connection gets per round at most ...
SLICE = 0.001
#: ... and all connections with work left together, per event-loop iteration (a round):
#: however many clients flood the emulator, one iteration answers for at most this long, so
#: other clients and the IPO clock get their turn.
ROUND = 0.002


@dataclass
class Stats:
    """Counters of one emulator (plain ints: read them from the loop thread or accept a race)."""

    #: Replies sent (including dropped-by-fault ones that were computed).
    requests: int = 0
    #: Clients connected now.
    clients: int = 0
    #: Connections served since start (not counting rejected ones).
    connections: int = 0
    #: Connections closed at once because max_clients were connected.
    rejected: int = 0
    protocol_errors: int = 0
    idle_drops: int = 0


@dataclass(frozen=True, slots=True)
class ConnectionInfo:
    """A snapshot of one connection, for tests and diagnostics."""

    index: int
    peer: str
    received: int
    #: Bytes of an incomplete request held by the decoder.
    buffered: int
    #: Requests decoded but not yet answered.
    pending: int
    #: Reply bytes the kernel has not accepted yet.
    write_buffer: int
    reading_paused: bool


class Host(Protocol):
    """What a connection needs of the emulator serving it (an ``Emulator`` is one)."""

    @property
    def config(self) -> EmulatorConfig: ...
    @property
    def stats(self) -> Stats: ...
    @property
    def robot(self) -> Robot | None: ...
    @property
    def responder(self) -> Responder: ...
    @property
    def service(self) -> ServiceQueue | None: ...
    @property
    def faults(self) -> FaultSet: ...
    @property
    def legacy_ids(self) -> bool: ...
    @property
    def idle_requests_only(self) -> bool: ...
    @property
    def slow(self) -> bool: ...
    def new_responder(self) -> Responder: ...
    def admit(self, conn: Connection) -> bool: ...
    def forget(self, conn: Connection) -> None: ...
    def enqueue(self, conn: Connection) -> None: ...


class Connection(asyncio.BufferedProtocol):
    """One client's socket: ``index`` (from 1) once admitted, ``peer`` for the logs, the
    idle timer's ``last_rx``, and a fixed buffer of ``read_size`` bytes each read fills."""

    def __init__(self, emu: Host, read_size: int) -> None:
        self.emu = emu
        self.transport: asyncio.Transport | None = None
        self.index = 0
        self.peer = "?"
        self.last_rx = time.monotonic()
        #: Closing, dropped or gone (its slot is free again).
        self.closed = False
        #: Waiting in the emulator's round (:meth:`Host.enqueue`).
        self.scheduled = False
        self._reading_paused = False
        self._rbuf = memoryview(bytearray(read_size))

    def _accept(self, transport: asyncio.BaseTransport) -> bool:
        """``connection_made``'s common part: note the peer and ask the emulator for a slot.
        Refused (the client limit): closed at once, no bytes at all (KVP accepts the 11th
        client and closes it in the Connect event). Admitted: ``TCP_NODELAY`` set."""
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        peer = transport.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if peer else "?"
        if not self.emu.admit(self):
            self.closed = True
            transport.close()
            return False
        sock = transport.get_extra_info("socket")
        if sock is not None:
            try:  # replies are small and latency-bound; never wait for Nagle
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            except OSError:
                pass
        return True

    def get_buffer(self, sizehint: int) -> memoryview:
        return self._rbuf

    # -- used by the Emulator -------------------------------------------------------------

    def serve(self, budget: float) -> None:
        """The emulator's round: answer what waits for at most ``budget`` seconds."""
        raise NotImplementedError

    def drop(self) -> None:
        """Close now, discarding what is queued or unsent (idle timer, shutdown)."""
        raise NotImplementedError

    def abort(self) -> None:
        """Close at once, discarding everything."""
        raise NotImplementedError

    def info(self) -> ConnectionInfo:
        raise NotImplementedError
