"""The ``--wire kvp9`` connection: every socket read parsed on its own, as KUKAVARPROXY 9.0 does.

:class:`Kvp9Connection` is the wire-faithful sibling of the robust
:class:`~kukavarproxy_emu.kvp_connection.KvpConnection`. It
reads at most 2048 bytes per event (``sockServer(Index).Read(strBuffer, 2048)``), hands them to
:func:`~kukavarproxy_emu.kvp9.sock_server_read` and keeps nothing for the next read: a request cut
by a read boundary is lost or mis-parsed exactly like on the controller. Answers come from the
emulator's shared :class:`~kukavarproxy_emu.responder.Responder` (its ``show_var``/``set_var``).

Bounds, per connection: one read of 2048 bytes holds at most 512 requests (each consumes at least
its 4 header bytes), so one event does at most 512 store calls and writes at most 512 replies.
Memory is bounded the way the real server bounds it: KVP's socket ``Write`` on a non-blocking
socket fails once the send buffer is full and the proxy then drops the client (``DropClient``);
here, once more than :data:`SEND_LIMIT` reply bytes wait in user space, the client is dropped.
Replies are written at least every :data:`FLUSH_SIZE` bytes, so at most SEND_LIMIT + FLUSH_SIZE
+ one reply wait in the process per connection (an unknown mode after other requests nests the
previous reply, so one 2048-byte read can answer ~0.5 MB: real KVP does the same).

Without latency or faults a read is answered inside ``buffer_updated`` for up to ``IMMEDIATE``
seconds, the same work budget as the robust mode (:mod:`kukavarproxy_emu.connection_base`); a read that
needs longer (hundreds of whole-array reads) is parked where it stopped and continues in the
emulator's rounds, ``SLICE`` per round and ``ROUND`` for all connections together, so a flooding
client cannot hold the event loop and other clients are answered in between. VB's parsing is
unchanged: the parked read resumes at the very statement it stopped at. Otherwise (latency or
faults) a worker task serves the read (CrossComm calls wait for the global
:class:`~kukavarproxy_emu.latency.ServiceQueue`, replies go through the faults), yielding to the
loop once its slice is used up. Either way the socket is not read while a read is served: like
the single-threaded proxy, the next read happens only after this one was handled, and takes
whatever has arrived meanwhile, up to 2048 bytes.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from collections.abc import Coroutine, Generator
from dataclasses import dataclass
from functools import partial
from typing import Any

from .connection_base import IMMEDIATE, SLICE, Connection, ConnectionInfo, Host
from .faults import send_reply
from .kvp9 import KVP_READ_BYTES, ReadOutcome, sock_server_read
from .responder import Responder

__all__ = ["FLUSH_SIZE", "SEND_LIMIT", "Kvp9Connection", "Kvp9ConnectionInfo"]

log = logging.getLogger(__name__)

#: Reply bytes allowed to wait in user space before the client counts as not reading (KVP's
#: failed ``Write`` → ``DropClient``); the kernel's socket buffers come on top of it.
SEND_LIMIT = 64 * 1024
#: The fast path writes its collected replies at the latest when they exceed this many bytes.
FLUSH_SIZE = 16 * 1024


@dataclass(frozen=True, slots=True)
class Kvp9ConnectionInfo(ConnectionInfo):
    """:class:`ConnectionInfo` plus the per-read counters of the wire-faithful mode."""

    #: Socket reads (events) so far, and their bytes.
    reads: int = 0
    bytes_read: int = 0
    #: The largest single read (never above 2048) and the most requests one read went through.
    largest_read: int = 0
    most_messages: int = 0


class _Pause:
    """Awaited by the fast wire once its budget is used up: the parked read's driver
    (:meth:`Kvp9Connection._resume`) receives it from ``coro.send`` and stops there."""

    def __await__(self) -> Generator[_Pause, None, None]:
        yield self


_PAUSE = _Pause()
#: A read of the fast path, parked between two slices of work.
_Read = Coroutine[Any, Any, ReadOutcome]


def _show(responder: Responder, name: bytes) -> bytes:
    text = responder.show_var(name.decode("latin-1"))
    return b"" if text is None else text.encode("latin-1", errors="replace")


def _set(responder: Responder, name: bytes, value: bytes) -> bool:
    return responder.set_var(name.decode("latin-1"), value.decode("latin-1"))


class _FastWire:
    """CrossComm without service time; replies coalesced into few writes (one per read, as a
    rule; every FLUSH_SIZE bytes when a read answers a lot, so the send limit is checked).
    Every CrossComm call and reply first checks the time budget: once ``deadline`` has passed
    (and something was done since the read was resumed) the read pauses (``_PAUSE``)."""

    def __init__(self, conn: Kvp9Connection) -> None:
        self.conn = conn
        self.responder = conn.emu.responder
        self.out: list[bytes] = []
        self.size = 0
        #: perf_counter time at which the read in progress pauses, and whether it did a step
        #: since it was (re)started: one step per slice at least, so a read always progresses.
        self.deadline = 0.0
        self.moved = False

    async def _budget(self) -> None:
        if self.moved and time.perf_counter() > self.deadline:
            await _PAUSE
        self.moved = True

    async def show_var(self, name: bytes) -> bytes:
        await self._budget()
        return _show(self.responder, name)

    async def set_var(self, name: bytes, value: bytes) -> bool:
        await self._budget()
        return _set(self.responder, name, value)

    async def send(self, data: bytes) -> None:
        await self._budget()
        self.out.append(data)
        self.size += len(data)
        if self.size > FLUSH_SIZE:
            self.flush()

    def flush(self) -> None:
        out = self.out
        if out:
            self.conn.replies += len(out)
            self.conn.emu.stats.requests += len(out)
            self.conn.write(out[0] if len(out) == 1 else b"".join(out))
            out.clear()
            self.size = 0


class _SlowWire:
    """CrossComm through the latency queue; each reply written at once, through the faults;
    without latency (faults only) the worker yields to the loop every ``SLICE`` seconds."""

    def __init__(self, conn: Kvp9Connection) -> None:
        self.conn = conn
        self.deadline = 0.0

    async def show_var(self, name: bytes) -> bytes:
        emu = self.conn.emu
        call = partial(self._show_now, name)
        return await emu.service.run("read", call) if emu.service else call()

    def _show_now(self, name: bytes) -> bytes:
        # a robot coasting since the read arrived (see motion.clock) first runs its due ticks
        emu = self.conn.emu
        if emu.robot is not None:
            emu.robot.clock.settle()
        return _show(emu.responder, name)

    async def set_var(self, name: bytes, value: bytes) -> bool:
        emu = self.conn.emu
        call = partial(_set, emu.responder, name, value)
        return await emu.service.run("write", call) if emu.service else call()

    async def send(self, data: bytes) -> None:
        if time.perf_counter() > self.deadline:
            await asyncio.sleep(0)  # the others' turn (with latency, CrossComm waits anyway)
            self.deadline = time.perf_counter() + SLICE
        conn = self.conn
        conn.replies += 1
        conn.emu.stats.requests += 1
        faults = conn.emu.faults.match(conn.index, conn.replies) if conn.emu.faults else []
        if not faults:
            conn.write(data)
        elif conn.transport is not None and not conn.dropped:
            if not await send_reply(conn.transport, data, faults):
                conn.dropped = True


class Kvp9Connection(Connection):
    """One client of the wire-faithful mode (``EmulatorConfig(wire="kvp9")``)."""

    def __init__(self, emu: Host) -> None:
        super().__init__(emu, KVP_READ_BYTES)
        #: The proxy dropped us (send buffer full, or a fault closed the socket): later replies
        #: of the same read are computed (writes still apply, as in VB) but not sent.
        self.dropped = False
        self.replies = 0
        self.reads = 0
        self.bytes_read = 0
        self.largest_read = 0
        self.most_messages = 0
        self.worker: asyncio.Task[None] | None = None
        self._backlog: deque[bytes] = deque()  # at most one read: reading pauses meanwhile
        #: The fast path's read in progress, parked until the emulator's next round.
        self._parked: _Read | None = None
        self._fast = _FastWire(self)
        self._slow = _SlowWire(self)
        self._ping = emu.responder.ping

    # -- asyncio callbacks ----------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        if not self._accept(transport):  # accepted, then disconnected in the Connect event
            return
        log.info("client %d connected from %s (wire kvp9)", self.index, self.peer)

    def connection_lost(self, exc: Exception | None) -> None:
        # a parked read is finished all the same (its writes apply, as VB's loop goes on after
        # a failed Write), its replies go nowhere
        self.closed = True
        if self.index:
            self.emu.forget(self)
            log.info("client %d (%s) disconnected", self.index, self.peer)
        if self.worker is not None:
            self.worker.cancel()

    def buffer_updated(self, nbytes: int) -> None:
        if self.closed:
            return
        data = bytes(self._rbuf[:nbytes])
        self.reads += 1
        self.bytes_read += nbytes
        self.largest_read = max(self.largest_read, nbytes)
        robot = self.emu.robot
        if robot is not None:
            robot.clock.poll()  # a due IPO tick goes before this read (bounded jitter)
        if self.worker is None and self._parked is None and not self.emu.slow:
            self._start(data)
            return
        self._backlog.append(data)  # served after the read in progress (parked or worker)
        self._set_reading(False)
        if self.worker is None and self._parked is None:
            self.worker = asyncio.get_running_loop().create_task(self._work())

    def eof_received(self) -> bool:
        # KVP drops the client in its Disconnect event, after the reads before it were served.
        # So does closing here: reading is paused while a read is served (parked or in the
        # worker), so the end of the stream is only seen once the reads before it are done.
        return False

    # -- serving reads --------------------------------------------------------------------

    def _start(self, data: bytes) -> None:
        """Serve one read on the fast path: at once for up to ``IMMEDIATE`` seconds, the rest
        (if any) in the emulator's rounds."""
        wire = self._fast
        wire.deadline = time.perf_counter() + IMMEDIATE
        wire.moved = False
        self._resume(sock_server_read(data, wire, ping=self._ping, legacy_ids=self.emu.legacy_ids))

    def serve(self, budget: float) -> None:
        """The emulator's round: continue the parked read for ``budget`` seconds (one step
        at least)."""
        read = self._parked
        if read is None:
            return
        self._fast.deadline = time.perf_counter() + budget
        self._fast.moved = False
        self._resume(read)

    def _resume(self, read: _Read) -> None:
        wire = self._fast
        try:
            read.send(None)  # runs until the read ends (StopIteration) or its budget is used up
        except StopIteration as done:
            self._parked = None
            self._account(done.value)
            wire.flush()
            self._next_read()
            return
        except Exception:
            self._parked = None
            wire.out.clear()
            log.exception("client %d (%s): internal error, closing", self.index, self.peer)
            self.abort()
            return
        self._parked = read  # paused: what it answered so far goes out now
        wire.flush()
        self._set_reading(False)
        self.emu.enqueue(self)

    def _next_read(self) -> None:
        """After a fast-path read: a read that arrived meanwhile, or reading again."""
        if self._backlog and not self.closed:
            self._start(self._backlog.popleft())
        else:
            self._set_reading(True)

    def _unpark(self) -> None:
        read, self._parked = self._parked, None
        if read is not None:
            read.close()
            self._fast.out.clear()

    async def _work(self) -> None:
        self._slow.deadline = time.perf_counter() + SLICE
        try:
            while self._backlog and not self.closed:
                data = self._backlog.popleft()
                outcome = await sock_server_read(
                    data, self._slow, ping=self._ping, legacy_ids=self.emu.legacy_ids
                )
                self._account(outcome)
        except Exception:  # not a cancellation (connection_lost): that is no Exception
            log.exception("client %d (%s): internal error, closing", self.index, self.peer)
            self.abort()
        finally:
            self.worker = None
            self._set_reading(True)

    def _account(self, outcome: ReadOutcome) -> None:
        self.most_messages = max(self.most_messages, outcome.messages)
        if outcome.completed:
            # lLastReceiveDate(Index) = Now() is the last statement before Exit Sub: a read
            # that ends in errRead does not count as activity for the idle timer.
            self.last_rx = time.monotonic()
        else:
            self.emu.stats.protocol_errors += 1
            log.info("client %d (%s): read ended in errRead", self.index, self.peer)

    def write(self, data: bytes) -> None:
        """``sockServer(Index).Write``; a client that stops reading is dropped, as KVP does."""
        transport = self.transport
        if transport is None or self.dropped or transport.is_closing():
            return
        transport.write(data)
        if transport.get_write_buffer_size() > SEND_LIMIT:
            log.warning("client %d (%s) does not read its replies; dropped", self.index, self.peer)
            self.dropped = True
            self.abort()

    def _set_reading(self, on: bool) -> None:
        transport = self.transport
        if transport is None or transport.is_closing() or self._reading_paused is not on:
            return
        self._reading_paused = not on
        if on:
            transport.resume_reading()
        else:
            transport.pause_reading()

    # -- used by the Emulator -------------------------------------------------------------

    def drop(self) -> None:
        """Close now, discarding what is queued or unsent (idle timer, shutdown; the name the
        reworked robust connection uses for this). Always an abort: with nothing unsent it is
        the same as a close, and with replies unsent a close would wait for a peer that does
        not read."""
        self.closed = True
        self._backlog.clear()
        self._unpark()
        if self.transport is not None:
            self.transport.abort()

    def abort(self) -> None:
        self.closed = True
        if self.transport is not None:
            self.transport.abort()

    def info(self) -> Kvp9ConnectionInfo:
        transport = self.transport
        return Kvp9ConnectionInfo(
            index=self.index,
            peer=self.peer,
            received=self.replies,
            buffered=0,  # nothing survives a read
            pending=len(self._backlog) + (self._parked is not None),
            write_buffer=transport.get_write_buffer_size() if transport else 0,
            reading_paused=self._reading_paused,
            reads=self.reads,
            bytes_read=self.bytes_read,
            largest_read=self.largest_read,
            most_messages=self.most_messages,
        )
