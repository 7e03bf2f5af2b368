"""The robust KVP connection: frames reassembled across reads, answered in bounded slices.

:class:`KvpConnection` is one :class:`asyncio.BufferedProtocol` per client (the default,
``wire="robust"``): it reads at most ``FRAMED_READ_BYTES`` at a time into its own buffer,
reassembles frames with :class:`~pyopenshowvar.protocol.RequestDecoder` and answers them in
order. Its wire-faithful sibling is :mod:`kukavarproxy_emu.kvp9_connection`.

Each connection has two paths. The fast path (no latency, no armed faults, nothing queued)
answers what one TCP read delivered at once, for up to ``IMMEDIATE`` seconds, and sends the
replies with one ``transport.write``; a bigger batch waits in the connection's backlog for the
emulator's rounds (``Emulator.enqueue``: once per event-loop iteration, every connection with a
backlog in turn, ``SLICE`` each and ``ROUND`` in all). The socket is not read while a backlog
waits, nor while ``OUTPUT_LIMIT`` reply bytes wait unsent (the client is not reading), so
memory and work per connection stay bounded whatever it sends (docs/emulator.md, "Bounds").
The queued path hands requests to a per-connection worker task that waits for the global
:class:`~kukavarproxy_emu.latency.ServiceQueue` and applies faults; the socket stops being read
while ``max_pending`` requests wait or while the client is not reading its replies, so one
connection holds at most ``max_pending`` + one read's worth of requests.
"""

from __future__ import annotations

import asyncio
import logging
import struct
import time
from collections import deque
from functools import partial

from pyopenshowvar.errors import ProtocolError
from pyopenshowvar.protocol import FramingError, Reply, Request, RequestDecoder, encode_reply

from .connection_base import IMMEDIATE, SLICE, Connection, ConnectionInfo, Host, limited_conn
from .faults import send_reply
from .logsafe import clip
from .responder import Deferred

__all__ = ["FRAMED_READ_BYTES", "OUTPUT_LIMIT", "KvpConnection"]

log = logging.getLogger(__name__)

_U16 = struct.Struct(">H")
#: Bytes read from a socket per event: bounds the requests one read can queue, and the work
#: of framing them (~0.2 ms for 8 KiB of the smallest requests). The wire-faithful mode reads
#: what KUKAVARPROXY itself reads instead (``kvp9.KVP_READ_BYTES``).
FRAMED_READ_BYTES = 8 * 1024
#: Reply bytes a connection may hold unsent: beyond it the connection stops answering and
#: reading until the client has taken its replies (output backpressure). A connection's unsent
#: output therefore never exceeds OUTPUT_LIMIT plus one reply (< 64 KiB).
OUTPUT_LIMIT = 64 * 1024
#: Seconds a closing connection may take to flush its last replies before it is aborted.
CLOSE_GRACE = 2.0
#: Seconds a connection that sent garbage has to take the replies owed before the garbage.
ERROR_GRACE = 10.0
#: Worker queue: (request, reply id, its number on the connection, when its bytes arrived);
#: None = close here.
_Item = tuple[Request, int, int, float] | None
#: Fast-path backlog: a frame, or (frame, id) with the legacy-ids quirk; None = close here.
#: Plain frames keep a big backlog free of per-request objects for the garbage collector.
_Frame = bytes | tuple[bytes, int] | None


class KvpConnection(Connection):
    """One client. Everything it sends is contained here: errors close only this connection."""

    def __init__(self, emu: Host) -> None:
        super().__init__(emu, FRAMED_READ_BYTES)
        self.decoder = RequestDecoder(max_frame=emu.config.max_frame)
        #: Answers this connection's requests (C3 Bridge: one per connection, its file buffers).
        self.responder = emu.new_responder()
        #: Fast path: frames of the last read not answered yet (None: close after the rest).
        self.backlog: deque[_Frame] = deque()
        #: Queued path: decoded requests for the worker (None: close after the rest).
        self.queue: deque[_Item] = deque()
        self.worker: asyncio.Task[None] | None = None
        self.received = 0
        #: No more input is taken (after a protocol error or EOF); what came before is answered.
        self.input_done = False
        self.lost = False
        self._write_paused = False
        self._drained: asyncio.Future[None] | None = None

    # -- asyncio callbacks ----------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        if not self._accept(transport):
            return
        assert self.transport is not None
        # pause_writing() comes once OUTPUT_LIMIT reply bytes wait unsent (backpressure).
        self.transport.set_write_buffer_limits(high=OUTPUT_LIMIT)
        limited_conn.info("client %d connected from %s", self.index, self.peer)

    def connection_lost(self, exc: Exception | None) -> None:
        self.closed = self.lost = True
        self.backlog.clear()
        self.queue.clear()
        if self.index:
            self.emu.forget(self)
            limited_conn.info("client %d (%s) disconnected", self.index, self.peer)
        if self.worker is not None:
            self.worker.cancel()

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
            limited_conn.info("client %d (%s): EOF inside a frame", self.index, self.peer)
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
        if self.backlog and not self.scheduled:
            self.emu.enqueue(self)
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
            if not self.scheduled:
                self.serve(IMMEDIATE)
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

    def serve(self, budget: float) -> None:
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
            emu.enqueue(self)
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
            self.serve(IMMEDIATE)
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
            limited_conn.warning(
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
        limited_conn.warning("client %d (%s): %s; closing", self.index, self.peer, clip(str(exc)))
        self.input_done = True
        self._update_reading()
        # It is owed the replies before the garbage; if it does not take them, cut it off.
        asyncio.get_running_loop().call_later(ERROR_GRACE, self.abort)

    def _finish(self) -> None:
        """Close after the replies already written: the slot is free at once, and a peer that
        does not take its last replies within ``CLOSE_GRACE`` seconds is cut off."""
        self.closed = True
        self.emu.forget(self)
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
        self.emu.forget(self)
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
        self.emu.forget(self)
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
