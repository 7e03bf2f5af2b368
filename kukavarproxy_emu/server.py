"""The KUKAVARPROXY 9.0 emulator server: asyncio TCP on port 7000, UDP discovery, idle timer.

Layers, top down:

* :class:`Emulator` — ``async with Emulator(config) as emu`` owns the listening socket, the
  variable store, the armed faults, the latency worker, the idle timer and the statistics;
* ``_Connection`` — one :class:`asyncio.BufferedProtocol` per client: reads at most
  ``READ_SIZE`` bytes at a time into its own buffer, reassembles frames with
  :class:`~pyopenshowvar.protocol.RequestDecoder` and answers them in order;
* ``Kvp9Connection`` (:mod:`kukavarproxy_emu.kvp9_connection`) takes ``_Connection``'s place with
  ``wire="kvp9"``: each 2048-byte read parsed on its own, as KUKAVARPROXY 9.0 does;
* :class:`~kukavarproxy_emu.handler.Responder` — pure request → :class:`~pyopenshowvar.protocol.Reply` logic with KVP 9.0
  semantics (reference §2.4, §4.1), no I/O.

Each connection has two paths. The fast path (no latency, no armed faults, nothing queued)
answers what one TCP read delivered at once, for up to ``IMMEDIATE`` seconds, and sends the
replies with one ``transport.write``; a bigger batch waits in the connection's backlog for the
emulator's rounds (``Emulator._round``: once per event-loop iteration, every connection with a
backlog in turn, ``SLICE`` each and ``ROUND`` in all). The socket is not read while a backlog
waits, nor while ``OUTPUT_LIMIT`` reply bytes wait unsent (the client is not reading), so
memory and work per connection stay bounded whatever it sends (docs/emulator.md, "Bounds").
The queued path hands requests to a per-connection worker task that waits for the global
:class:`~kukavarproxy_emu.latency.ServiceQueue` and applies faults; the socket stops being read
while ``max_pending`` requests wait or while the client is not reading its replies, so one
connection holds at most ``max_pending`` + one read's worth of requests.
:class:`~kukavarproxy_emu.threaded.EmulatorThread` runs an Emulator in a daemon thread for synchronous code.
"""

from __future__ import annotations

import asyncio
import logging
import random
import socket
import struct
import time
from collections import deque
from dataclasses import dataclass
from functools import partial
from types import TracebackType
from typing import TYPE_CHECKING, Self

from pyopenshowvar.errors import ProtocolError
from pyopenshowvar.protocol import (
    FramingError,
    Reply,
    Request,
    RequestDecoder,
    encode_reply,
)

from .config import EmulatorConfig
from .discovery import DiscoveryProtocol, start_discovery
from .faults import FaultSet, send_reply
from .handler import Deferred, Responder, build_store
from .latency import ServiceQueue
from .logsafe import RateLimitedLog, clip
from .store import VariableStore

if TYPE_CHECKING:
    from collections.abc import Callable

    from .c3 import C3Server
    from .kvp9_connection import Kvp9Connection
    from .robot_task import Robot

__all__ = ["ConnectionInfo", "Emulator", "Stats"]

log = logging.getLogger(__name__)
#: Connection lines any client can provoke at will (connect, garbage, EOF): rate-limited.
_limited_conn = RateLimitedLog(log, burst=20)

_U16 = struct.Struct(">H")
#: Bytes read from a socket per event: bounds the requests one read can queue, and the work
#: of framing them (~0.2 ms for 8 KiB of the smallest requests).
READ_SIZE = 8 * 1024
#: Reply bytes a connection may hold unsent: beyond it the connection stops answering and
#: reading until the client has taken its replies (output backpressure). A connection's unsent
#: output therefore never exceeds OUTPUT_LIMIT plus one reply (< 64 KiB).
OUTPUT_LIMIT = 64 * 1024
#: Seconds of request handling a connection gets right away when a read arrives: a client
#: with a few requests is answered at once, a big batch goes on in the rounds below.
IMMEDIATE = 0.0003
#: Seconds of request handling one connection gets per round at most ...
SLICE = 0.001
#: ... and all connections with work left together, per event-loop iteration (a round):
#: however many clients flood the emulator, one iteration answers for at most this long, so
#: other clients and the IPO clock get their turn.
ROUND = 0.002
#: Seconds a closing connection may take to flush its last replies before it is aborted.
CLOSE_GRACE = 2.0
#: Seconds a connection that sent garbage has to take the replies owed before the garbage.
ERROR_GRACE = 10.0
#: Worker queue: (request, id the reply carries, request number on its connection); None =
#: close here.
#: (request, reply id, its number on the connection, when its bytes arrived) or the end mark
_Item = tuple[Request, int, int, float] | None
#: Fast-path backlog: a frame, or (frame, id) with the legacy-ids quirk; None = close here.
#: Plain frames keep a big backlog free of per-request objects for the garbage collector.
_Frame = bytes | tuple[bytes, int] | None


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


class _Connection(asyncio.BufferedProtocol):
    """One client. Everything it sends is contained here: errors close only this connection."""

    def __init__(self, emu: Emulator) -> None:
        self.emu = emu
        self.transport: asyncio.Transport | None = None
        self.index = 0
        self.peer = "?"
        self.decoder = RequestDecoder(max_frame=emu.config.max_frame)
        #: Answers this connection's requests (C3 Bridge: one per connection, its file buffers).
        self.responder = emu.new_responder()
        #: Fast path: frames of the last read not answered yet (None: close after the rest).
        self.backlog: deque[_Frame] = deque()
        #: Queued path: decoded requests for the worker (None: close after the rest).
        self.queue: deque[_Item] = deque()
        self.worker: asyncio.Task[None] | None = None
        self.received = 0
        self.last_rx = time.monotonic()
        #: Closing, dropped or gone (its slot is free again).
        self.closed = False
        #: No more input is taken (after a protocol error or EOF); what came before is answered.
        self.input_done = False
        self.lost = False
        self._write_paused = False
        self._reading_paused = False
        #: Waiting in the emulator's round (``Emulator._enqueue``).
        self._scheduled = False
        self._drained: asyncio.Future[None] | None = None
        self._rbuf = memoryview(bytearray(READ_SIZE))

    # -- asyncio callbacks ----------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        peer = transport.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if peer else "?"
        if not self.emu._admit(self):
            # KVP accepts the 11th client and closes it in the Connect event: no bytes at all.
            self.closed = True
            transport.close()
            return
        # pause_writing() comes once OUTPUT_LIMIT reply bytes wait unsent (backpressure).
        transport.set_write_buffer_limits(high=OUTPUT_LIMIT)
        sock = transport.get_extra_info("socket")
        if sock is not None:
            try:  # replies are small and latency-bound; never wait for Nagle
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            except OSError:
                pass
        _limited_conn.info("client %d connected from %s", self.index, self.peer)

    def connection_lost(self, exc: Exception | None) -> None:
        self.closed = self.lost = True
        self.backlog.clear()
        self.queue.clear()
        if self.index:
            self.emu._forget(self)
            _limited_conn.info("client %d (%s) disconnected", self.index, self.peer)
        if self.worker is not None:
            self.worker.cancel()

    def get_buffer(self, sizehint: int) -> memoryview:
        return self._rbuf

    def buffer_updated(self, nbytes: int) -> None:
        if self.closed or self.input_done:
            return
        now = time.monotonic()
        if not self.emu.idle_requests_only:
            self.last_rx = now  # KVP: any received bytes reset the idle timer
        robot = self.emu.robot
        if robot is not None:
            robot.clock.poll()  # a due IPO tick goes before this batch (bounded jitter)
        error: ProtocolError | None = None
        try:
            frames = self.decoder.feed(self._rbuf[:nbytes])
        except FramingError as exc:  # answer the whole requests before the bad header
            frames, error = exc.frames, exc
        if frames:
            self.last_rx = now
        try:
            self._dispatch(frames, error, now)
        except Exception:
            log.exception("client %d (%s): internal error, closing", self.index, self.peer)
            self.abort()

    def eof_received(self) -> bool:
        # A client that half-closes after its last request still gets every reply: keep the
        # transport open until what is queued is answered, then close.
        if self.decoder.buffered:
            _limited_conn.info("client %d (%s): EOF inside a frame", self.index, self.peer)
        self.input_done = True
        if self.worker is not None:
            self.queue.append(None)
        elif self.backlog:
            self.backlog.append(None)
        else:
            self._finish()
        return True

    def pause_writing(self) -> None:
        self._write_paused = True
        self._update_reading()

    def resume_writing(self) -> None:
        self._write_paused = False
        if self._drained is not None and not self._drained.done():
            self._drained.set_result(None)
        if self.backlog and not self._scheduled:
            self.emu._enqueue(self)
        self._update_reading()

    # -- request handling -----------------------------------------------------------------

    def _dispatch(self, frames: list[bytes], error: ProtocolError | None, arrival: float) -> None:
        emu = self.emu
        # Pre-9.0 bug: every reply to one TCP read carried the first request's id.
        legacy_id = _U16.unpack_from(frames[0])[0] if frames and emu.legacy_ids else None
        if error is not None:
            self._protocol_error(error)
        if self.worker is None and not emu.slow:
            if legacy_id is None:
                self.backlog.extend(frames)
            else:
                self.backlog.extend([(frame, legacy_id) for frame in frames])
            if error is not None:
                self.backlog.append(None)
            if not self._scheduled:
                self._serve(IMMEDIATE)
            return
        for frame in frames:
            try:
                request = self.responder.decode(frame)
            except ProtocolError as exc:
                self._protocol_error(exc)
                error = exc
                break
            self.received += 1
            msg_id = request.msg_id if legacy_id is None else legacy_id
            self.queue.append((request, msg_id, self.received, arrival))
        if error is not None:
            self.queue.append(None)  # answer what came before, then close
        self._update_reading()
        if self.worker is None and self.queue:
            self.worker = asyncio.get_running_loop().create_task(self._work())

    def _serve(self, budget: float) -> None:
        """Answer backlog frames for at most ``budget`` seconds (one at least) and until
        ``OUTPUT_LIMIT`` reply bytes wait unsent; the rest waits for the emulator's next round
        or for the client to read (reading stays paused meanwhile, so the backlog never grows
        beyond one read)."""
        transport = self.transport
        backlog = self.backlog
        if transport is None or self.lost or self._write_paused or self.worker is not None:
            return  # a deferred answer is pending (_deferred): what follows it waits
        emu = self.emu
        if emu.robot is not None:
            emu.robot.clock.poll()
        answer = self.responder.answer
        decode = self.responder.decode
        room = OUTPUT_LIMIT - transport.get_write_buffer_size()
        deadline = time.perf_counter() + budget
        out: list[bytes] = []
        size = 0
        deferred: Deferred | None = None
        try:
            while backlog and (size < room or not out):
                item = backlog[0]
                if item is None:
                    break
                backlog.popleft()
                if isinstance(item, tuple):
                    request = decode(item[0])
                    msg_id = item[1]
                else:
                    request = decode(item)
                    msg_id = request.msg_id
                try:
                    reply = encode_reply(answer(request, msg_id))
                except Deferred as later:  # its answer is sent by a task, the rest after it
                    deferred = later
                    break
                out.append(reply)
                size += len(reply)
                if time.perf_counter() > deadline:
                    break
        except ProtocolError as exc:  # the good requests before it are answered below
            backlog.clear()
            backlog.append(None)
            self._protocol_error(exc)
        except Exception:
            log.exception("client %d (%s): internal error, closing", self.index, self.peer)
            self.abort()
            return
        if out:
            self.received += len(out)
            emu.stats.requests += len(out)
            transport.write(out[0] if len(out) == 1 else b"".join(out))
        if deferred is not None:
            self.worker = asyncio.get_running_loop().create_task(self._deferred(deferred))
            self._update_reading()
            return
        if backlog and backlog[0] is None:
            backlog.clear()
            self._finish()
            return
        if backlog and not self._write_paused:
            emu._enqueue(self)
        self._update_reading()

    async def _deferred(self, later: Deferred) -> None:
        """Send a deferred answer once it is ready, then go on with what waited behind it:
        the rest of the backlog, then what arrived meanwhile (queued, see ``_dispatch``)."""
        try:
            reply = encode_reply(await later.reply())
        except asyncio.CancelledError:
            raise
        except Exception:
            log.exception("client %d (%s): internal error, closing", self.index, self.peer)
            self.worker = None
            self.abort()
            return
        self.worker = None
        transport = self.transport
        if transport is None or self.lost:
            return
        self.received += 1
        self.emu.stats.requests += 1
        if not transport.is_closing():
            transport.write(reply)
        if self.backlog:
            self._serve(IMMEDIATE)
        elif self.queue:
            self.worker = asyncio.get_running_loop().create_task(self._work())
        self._update_reading()

    def _answer(self, request: Request, msg_id: int) -> Reply:
        """The reply, computed now: a robot coasting since the request arrived (see
        :mod:`.motion.clock`) first runs its due ticks, so the reply shows this moment."""
        robot = self.emu.robot
        if robot is not None:
            robot.clock.settle()
        return self.responder.answer(request, msg_id)

    async def _work(self) -> None:
        emu = self.emu
        transport = self.transport
        assert transport is not None
        deadline = time.perf_counter() + SLICE
        try:
            while self.queue:
                item = self.queue.popleft()
                self._update_reading()
                if item is None:
                    self._finish()
                    return
                request, msg_id, nth, arrival = item
                responder = self.responder
                kind = responder.kind(request)
                try:
                    if emu.service is not None and kind is not None:
                        compute = partial(self._answer, request, msg_id)
                        reply = await emu.service.run(
                            kind, compute, responder.weight(request), arrival=arrival
                        )
                    else:
                        reply = self._answer(request, msg_id)
                except Deferred as later:  # after its service time, the work in slices
                    reply = await later.reply()
                frame = encode_reply(reply)
                emu.stats.requests += 1
                faults = emu.faults.match(self.index, nth) if emu.faults else []
                if faults:
                    if not await send_reply(transport, frame, faults):
                        return
                elif not transport.is_closing():
                    transport.write(frame)
                if self._write_paused:
                    self._drained = asyncio.get_running_loop().create_future()
                    await self._drained
                if time.perf_counter() > deadline:
                    await asyncio.sleep(0)  # one slice per loop iteration, as on the fast path
                    deadline = time.perf_counter() + SLICE
        except asyncio.CancelledError:
            raise
        except ProtocolError as exc:  # C3 Bridge: a message type it does not handle
            self.emu.stats.protocol_errors += 1
            _limited_conn.warning(
                "client %d (%s): %s; closing", self.index, self.peer, clip(str(exc))
            )
            self._finish()
        except Exception:
            log.exception("client %d (%s): internal error, closing", self.index, self.peer)
            transport.abort()
        finally:
            self.worker = None

    def _update_reading(self) -> None:
        """Stop reading the socket while replies pile up: bounded memory per connection."""
        transport = self.transport
        if transport is None or transport.is_closing():
            return
        pause = (
            self.input_done
            or self._write_paused
            or bool(self.backlog)
            or len(self.queue) >= self.emu.config.max_pending
        )
        if pause != self._reading_paused:
            self._reading_paused = pause
            if pause:
                transport.pause_reading()
            else:
                transport.resume_reading()

    def _protocol_error(self, exc: ProtocolError) -> None:
        self.emu.stats.protocol_errors += 1
        _limited_conn.warning("client %d (%s): %s; closing", self.index, self.peer, clip(str(exc)))
        self.input_done = True
        self._update_reading()
        # It is owed the replies before the garbage; if it does not take them, cut it off.
        asyncio.get_running_loop().call_later(ERROR_GRACE, self.abort)

    def _finish(self) -> None:
        """Close after the replies already written: the slot is free at once, and a peer that
        does not take its last replies within ``CLOSE_GRACE`` seconds is cut off."""
        self.closed = True
        self.emu._forget(self)
        transport = self.transport
        if transport is None or self.lost:
            return
        pending = transport.get_write_buffer_size()
        transport.close()
        if pending:
            asyncio.get_running_loop().call_later(CLOSE_GRACE, self.abort)

    def drop(self) -> None:
        """Close now (idle timer, shutdown): replies the peer has not read are discarded, so
        a client that does not read cannot keep its slot or its buffers."""
        self.closed = True
        self.backlog.clear()
        self.queue.clear()
        self.emu._forget(self)
        transport = self.transport
        if transport is None or self.lost:
            return
        if transport.get_write_buffer_size() or self.worker is not None:
            transport.abort()
        else:
            transport.close()

    def abort(self) -> None:
        """Close at once, discarding everything (idempotent: timers call it late)."""
        self.closed = True
        self.emu._forget(self)
        if self.transport is not None and not self.lost:
            self.transport.abort()

    def info(self) -> ConnectionInfo:
        transport = self.transport
        return ConnectionInfo(
            index=self.index,
            peer=self.peer,
            received=self.received,
            buffered=self.decoder.buffered,
            pending=len(self.queue) + len(self.backlog),
            write_buffer=transport.get_write_buffer_size() if transport else 0,
            reading_paused=self._reading_paused,
        )


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
        self._connections: dict[int, _Connection | Kvp9Connection] = {}
        #: Connections with requests left to answer, served in rounds (see ROUND).
        self._ready: deque[_Connection | Kvp9Connection] = deque()
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
        factory: Callable[[Emulator], asyncio.BaseProtocol] = _Connection
        if self.config.wire == "kvp9":
            from .kvp9_connection import Kvp9Connection  # late: it imports this module

            factory = Kvp9Connection
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

    # -- bookkeeping used by _Connection -------------------------------------------------

    def _admit(self, conn: _Connection | Kvp9Connection) -> bool:
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

    def _enqueue(self, conn: _Connection | Kvp9Connection) -> None:
        """Serve ``conn``'s backlog in the next round (once per round, in arrival order)."""
        if conn._scheduled:
            return
        conn._scheduled = True
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
            conn._scheduled = False
            conn._serve(min(SLICE, end - time.perf_counter()))  # one request at least
            if time.perf_counter() >= end:
                break
        if ready and not self._round_pending:
            self._round_pending = True
            asyncio.get_running_loop().call_soon(self._round)

    def _forget(self, conn: _Connection | Kvp9Connection) -> None:
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
                    _limited_conn.info(
                        "client %d (%s) idle for %.1f s, dropped", conn.index, conn.peer, timeout
                    )
                    self.stats.idle_drops += 1
                    conn.drop()
