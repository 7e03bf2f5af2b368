"""The KUKAVARPROXY 9.0 emulator server: asyncio TCP on port 7000, UDP discovery, idle timer.

Layers, top down:

* :class:`Emulator` — ``async with Emulator(config) as emu`` owns the listening socket, the
  variable store, the armed faults, the latency worker, the idle timer and the statistics,
  and serves the connections' backlogs in rounds (:meth:`Emulator.enqueue`: once per
  event-loop iteration, every connection with a backlog in turn, ``SLICE`` each and
  ``ROUND`` in all);
* one connection per client (:mod:`kukavarproxy_emu.connection_base`): the robust
  :class:`~kukavarproxy_emu.kvp_connection.KvpConnection` (frames reassembled across reads)
  or, with ``wire="kvp9"``, :class:`~kukavarproxy_emu.kvp9_connection.Kvp9Connection` (each
  2048-byte read parsed on its own, as KUKAVARPROXY 9.0 does);
* :class:`~kukavarproxy_emu.responder.Responder` — pure request → :class:`~pyopenshowvar.protocol.Reply`
  logic with KVP 9.0 semantics (reference §2.4, §4.1), no I/O.

:class:`~kukavarproxy_emu.emulator_thread.EmulatorThread` runs an Emulator in a daemon thread for
synchronous code.
"""

from __future__ import annotations

import asyncio
import logging
import random
import time
from collections import deque
from types import TracebackType
from typing import TYPE_CHECKING, Self

from .config import EmulatorConfig
from .connection_base import ROUND, SLICE, Connection, ConnectionInfo, Stats, limited_conn
from .faults import FaultSet
from .kvp9_connection import Kvp9Connection
from .kvp_connection import KvpConnection
from .kvp_discovery import DiscoveryProtocol, start_discovery
from .latency import ServiceQueue
from .responder import Responder, build_store
from .store import VariableStore

if TYPE_CHECKING:
    from collections.abc import Callable

    from .c3 import C3Server
    from .robot_task import Robot

__all__ = ["ConnectionInfo", "Emulator", "Stats"]

log = logging.getLogger(__name__)


class Emulator:
    """A running KUKAVARPROXY emulator: ``async with Emulator(EmulatorConfig(port=0)) as emu``."""

    def __init__(
        self, config: EmulatorConfig | None = None, *, store: VariableStore | None = None
    ) -> None:
        self.config = config if config is not None else EmulatorConfig()
        self.store = store if store is not None else build_store(self.config)
        self.faults = FaultSet(self.config.faults)
        self.stats = Stats()
        self.latency = self.config.latency_profile
        self.responder = Responder(
            self.store, strict=self.config.strict, ping="no-ping" not in self.config.quirks
        )
        self.legacy_ids = "legacy-ids" in self.config.quirks
        #: Only whole requests reset the idle timer (``idle_reset="requests"``), not any byte.
        self.idle_requests_only = self.config.idle_reset == "requests"
        self.service: ServiceQueue | None = None
        self.host = self.config.host
        self.port = self.config.port
        #: The bound UDP discovery port, or None when discovery is off.
        self.udp_port: int | None = None
        self._server: asyncio.Server | None = None
        self._connections: dict[int, Connection] = {}
        #: Connections with requests left to answer, served in rounds (see ROUND).
        self._ready: deque[Connection] = deque()
        self._round_pending = False
        self._last_index = 0
        self._idle_task: asyncio.Task[None] | None = None
        self._discovery: asyncio.DatagramTransport | None = None
        #: C3 Bridge's standard discovery listener (UDP on the TCP port), if any.
        self._c3_standard: asyncio.DatagramTransport | None = None
        self.udp_standard_port: int | None = None
        #: The UDP discovery listener (counters ``answered``, ``refused``), None when off.
        self.discovery: DiscoveryProtocol | None = None
        #: The simulated robot (motion kernel, program, IPO clock) while started with
        #: ``config.robot``; None otherwise.
        self.robot: Robot | None = None
        #: The C3 Bridge state (file system, program control) with ``proxy="c3bridge"``.
        self.c3: C3Server | None = None
        if self.config.proxy == "c3bridge":
            from .c3 import C3Server  # late: only C3 emulators need it

            self.c3 = C3Server(self.store, None, address=self.config.host, port=self.port)

    def new_responder(self) -> Responder:
        """The responder of a new connection: the shared one, or a C3 Bridge session."""
        return self.c3.session() if self.c3 is not None else self.responder

    @property
    def slow(self) -> bool:
        """True when replies must go through the per-connection worker (latency or faults)."""
        return self.service is not None or bool(self.faults)

    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port

    async def start(self) -> Self:
        if self._server is not None:
            return self
        loop = asyncio.get_running_loop()
        if self.latency is not None:
            self.service = ServiceQueue(self.latency, random.Random(self.config.seed))
        factory: Callable[[Emulator], Connection] = (
            Kvp9Connection if self.config.wire == "kvp9" else KvpConnection
        )
        # bound now (the port is known), served only once everything below is set up
        self._server = await loop.create_server(
            lambda: factory(self),
            self.config.host,
            self.config.port,
            reuse_address=True,
            start_serving=False,
        )
        self.host, self.port = self._server.sockets[0].getsockname()[:2]
        if self.c3 is not None:
            self.c3.port = self.port
        if self.config.idle_limit > 0:
            self._idle_task = loop.create_task(self._watch_idle())
        if self.config.discovery_enabled:
            await self._start_discovery()
        if self.config.robot:
            try:
                self._start_robot()
            except BaseException:  # KRL syntax error, missing program file: do not leak the port
                await self.close()
                raise
            if self.c3 is not None:
                self.c3.control.robot = self.robot
            await self._first_cycle()
        await self._server.start_serving()
        log.info("KUKAVARPROXY emulator listening on %s:%d", self.host, self.port)
        return self

    async def _first_cycle(self) -> None:
        """Wait for the robot's first IPO cycle: the first client, like one of a running KRC,
        sees variables the robot program and the SPS have set (an SPS snapshot is readable),
        however soon it connects (a script may start the emulator and read on its next line)."""
        robot = self.robot
        if robot is None:
            return
        clock, tick = robot.clock, robot.clock.callback
        ticked = asyncio.Event()

        def first() -> None:
            clock.callback = tick
            try:
                tick()
            finally:
                ticked.set()

        clock.callback = first
        try:
            # bounded: a clock held by a busy machine still lets the server start
            await asyncio.wait_for(ticked.wait(), 10 * clock.period + 1.0)
        except TimeoutError:
            log.warning("serving before the robot's first IPO cycle (the machine is too busy)")

    def _start_robot(self) -> None:
        from .robot_task import Robot  # imported late: numpy kinematics only when a robot runs
        from .robots import resolve_robot

        cfg = self.config
        arm = resolve_robot(cfg.arm)
        self.robot = Robot(
            self.store,
            model=arm.model,
            machine=arm.machine,
            plant_params=arm.plant_params if cfg.plant == "dynamic" else None,
            program=cfg.robot_program,
            sps=cfg.sps,
            ipo=cfg.ipo,
            speed=cfg.speed,
            phase=cfg.ipo_phase,
            noise=cfg.noise,
            seed=cfg.seed,
            plant=cfg.plant,
            calibration_error=cfg.calibration_error,
            torque_noise=cfg.torque_noise,
            obstacles=cfg.obstacles,
        )
        if self.latency is not None:
            # replies first: the robot's tick runs where it delays no reply (latency.tick_gate)
            from .latency import tick_gate

            self.robot.clock.gate = tick_gate(asyncio.get_running_loop())
        self.robot.start()

    async def _start_discovery(self) -> None:
        if self.c3 is not None:
            await self._start_c3_discovery(self.c3)
            return
        try:
            transport, self.discovery = await start_discovery(
                self.config.host, self.config.udp_port, self.config.udp_reply_port, self.identity
            )
        except OSError as exc:  # UDP 6999 taken: serve TCP anyway
            log.warning("UDP discovery on port %d unavailable: %s", self.config.udp_port, exc)
            return
        self._discovery = transport
        self.udp_port = transport.get_extra_info("sockname")[1]

    async def _start_c3_discovery(self, c3: C3Server) -> None:
        """C3 Bridge listens twice: legacy (like KVP) and standard (UDP on the TCP port,
        answering the sender's port); both also answer ``@PROXY_*`` queries."""
        from .c3.discovery import start_c3_discovery

        cfg = self.config
        for port, reply in ((cfg.udp_port, cfg.udp_reply_port), (self.port, 0)):
            try:
                transport, _ = await start_c3_discovery(
                    cfg.host, port, reply, self.identity, c3.internal
                )
            except OSError as exc:
                log.warning("UDP discovery on port %d unavailable: %s", port, exc)
                continue
            if self._discovery is None:
                self._discovery = transport
                self.udp_port = transport.get_extra_info("sockname")[1]
            else:
                self._c3_standard = transport
                self.udp_standard_port = transport.get_extra_info("sockname")[1]

    def identity(self) -> tuple[str, str]:
        """(model, serial) as announced by discovery: ``$MODEL_NAME[]`` unquoted, ``$KR_SERIALNO``."""
        model = self.responder._lookup("$MODEL_NAME[]") or ""
        serial = self.responder._lookup("$KR_SERIALNO") or ""
        return model.strip().strip('"'), serial.strip()

    async def close(self) -> None:
        server, self._server = self._server, None
        if server is None:
            return
        server.close()
        if self.robot is not None:
            await self.robot.stop()
        if self._idle_task is not None:
            self._idle_task.cancel()
            self._idle_task = None
        if self._discovery is not None:
            self._discovery.close()
            self._discovery = None
        if self._c3_standard is not None:
            self._c3_standard.close()
            self._c3_standard = None
        for conn in list(self._connections.values()):
            conn.drop()
        await server.wait_closed()
        await asyncio.sleep(0)  # the dropped transports report connection_lost
        log.info("emulator on %s:%d stopped", self.host, self.port)

    async def __aenter__(self) -> Self:
        return await self.start()

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()

    async def serve_forever(self) -> None:
        """Start if needed and serve until cancelled."""
        await self.start()
        assert self._server is not None
        await self._server.serve_forever()

    def connections(self) -> list[ConnectionInfo]:
        return [conn.info() for conn in self._connections.values()]

    # -- bookkeeping of the connections (their Host interface) -------------------------------

    def admit(self, conn: Connection) -> bool:
        """Give ``conn`` a slot and its index; False (counted as rejected) at the client limit
        or once the emulator is closing."""
        limit = self.config.client_limit
        if self._server is None or (limit and len(self._connections) >= limit):
            self.stats.rejected += 1
            log.info("refusing %s: %d clients connected", conn.peer, len(self._connections))
            return False
        self._last_index += 1
        conn.index = self._last_index
        self._connections[conn.index] = conn
        self.stats.connections += 1
        self.stats.clients = len(self._connections)
        return True

    def enqueue(self, conn: Connection) -> None:
        """Serve ``conn``'s backlog in the next round (once per round, in arrival order)."""
        if conn.scheduled:
            return
        conn.scheduled = True
        self._ready.append(conn)
        if not self._round_pending:
            self._round_pending = True
            asyncio.get_running_loop().call_soon(self._round)

    def _round(self) -> None:
        """One event-loop iteration's share of the backlogs: every waiting connection in turn,
        for ``ROUND`` seconds in all; those not reached go first in the next round."""
        self._round_pending = False
        ready = self._ready
        end = time.perf_counter() + ROUND
        for _ in range(len(ready)):
            conn = ready.popleft()
            conn.scheduled = False
            conn.serve(min(SLICE, end - time.perf_counter()))  # one request at least
            if time.perf_counter() >= end:
                break
        if ready and not self._round_pending:
            self._round_pending = True
            asyncio.get_running_loop().call_soon(self._round)

    def forget(self, conn: Connection) -> None:
        """Free ``conn``'s slot (as soon as it is closing, before the socket is gone)."""
        if self._connections.get(conn.index) is conn:
            del self._connections[conn.index]
            self.stats.clients = len(self._connections)

    async def _watch_idle(self) -> None:
        # KVP checks once a second; a finer tick keeps short test timeouts accurate.
        timeout = self.config.idle_limit
        interval = min(1.0, timeout / 4)
        while True:
            await asyncio.sleep(interval)
            limit = time.monotonic() - timeout
            for conn in list(self._connections.values()):
                if not conn.closed and conn.last_rx < limit:
                    limited_conn.info(
                        "client %d (%s) idle for %.1f s, dropped", conn.index, conn.peer, timeout
                    )
                    self.stats.idle_drops += 1
                    conn.drop()
