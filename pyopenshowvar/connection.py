"""One asyncio TCP connection to a KUKAVARPROXY: sending, timeouts, stalls, keep-alive.

The id and matching rules live in :mod:`pyopenshowvar.session` (shared with the blocking
client); this module adds what is asyncio-specific. Design choices, each forced by how the
real proxy behaves (protocol reference §1.4, §2.5, §2.6):

* **Each request is one ``transport.write``** with TCP_NODELAY, because KVP does not reassemble
  a request cut across two TCP reads.
* **Pipelining is bounded** by a request count and by the bytes of unanswered requests: at most
  ``pipeline_bytes`` and one TCP segment (see :mod:`pyopenshowvar.session`); a request larger
  than ``pipeline_bytes`` is refused with :class:`ProtocolError` before anything is sent.
* **Timeouts never desynchronise.** A timed-out request keeps its place in the queue, marked
  abandoned; its late reply is recognised and discarded.
* **A stalled server is reported.** When timed-out requests fill the window, the connection is
  marked unhealthy and closed (:class:`KvpStalledError`); the client reconnects when
  ``auto_reconnect`` is on.
* **No failure leaks.** Every future the connection fails is marked retrieved (its caller gets
  the error through its await; a caller that went away needs no log), each gets its own
  exception object, and nothing is written to a transport that is closing.
* **Keep-alive**: after ``keepalive`` seconds without traffic a ``PING`` is sent (KVP 9.0 answers
  ``PONG``); an older proxy answers an empty value, and from then on a cheap read of ``$OV_PRO``
  is used instead, keeping the proxy's 30 s idle timer from closing the connection.
"""

from __future__ import annotations

import asyncio
import logging
import struct
import time
from collections.abc import Callable
from typing import Any

from .errors import KvpConnectionError, KvpError, KvpStalledError, KvpTimeoutError, ProtocolError
from .link import LinkBase
from .protocol import FIRST_EXTENDED, Reply, encode_read, encode_write
from .session import IdPolicy, Pending, new_reply

__all__ = ["Connection", "IdPolicy"]

log = logging.getLogger(__name__)

#: Builds a complete request frame for a given message id.
_Builder = Callable[[int], bytes]
_Fut = asyncio.Future[Reply]
#: id, L, mode, value length: the head of a reply
_HEAD = struct.Struct(">HHBH")


def _fail(future: _Fut, exc: BaseException) -> None:
    if not future.done():
        future.set_exception(exc)
        # The caller awaiting it gets the error; one that went away (cancelled, or an earlier
        # result of its batch raised) must not make asyncio log "never retrieved".
        future.exception()


class _Protocol(asyncio.Protocol):
    """Feeds received bytes to the owning connection; kept tiny on purpose (hot path)."""

    def __init__(self, owner: Connection) -> None:
        self.owner = owner

    def data_received(self, data: bytes) -> None:
        self.owner._on_data(data)

    def connection_lost(self, exc: Exception | None) -> None:
        self.owner._on_lost(exc)


class Connection(LinkBase[_Fut]):
    """A connected KVP session. Use :meth:`open`; normally wrapped by :class:`~pyopenshowvar.Client`."""

    def __init__(self, host: str, port: int, **kw: Any) -> None:
        super().__init__(host, port, **kw)
        self._transport: asyncio.Transport | None = None
        self._slot = asyncio.Event()
        self._keepalive_task: asyncio.Task[None] | None = None
        self._watchdog: asyncio.TimerHandle | None = None
        self._watchdog_at = 0.0

    @property
    def is_open(self) -> bool:
        """Connected and healthy: False once lost, closed, dropped or marked stalled."""
        return self._transport is not None and self._closed_reason is None

    # ------------------------------------------------------------------ life cycle

    @classmethod
    async def open(
        cls, host: str, port: int, *, connect_timeout: float | None = None, **kw: object
    ) -> Connection:
        conn = cls(host, port, **kw)
        await conn._connect(connect_timeout if connect_timeout is not None else conn.timeout)
        return conn

    async def _connect(self, timeout: float) -> None:
        loop = asyncio.get_running_loop()
        try:
            async with asyncio.timeout(timeout):
                transport, _ = await loop.create_connection(
                    lambda: _Protocol(self), self.host, self.port
                )
        except OSError as exc:  # TimeoutError included
            raise self._connect_error(exc, timeout) from exc
        self._connected(transport.get_extra_info("socket"))
        # No isinstance check on the transport: uvloop's transports are not asyncio.Transport
        # subclasses, and only the interface matters.
        self._transport = transport
        self._last_activity = time.perf_counter()
        if self.session.needs_probe:
            probe = self.session.register_probe(
                loop.create_future(), time.perf_counter(), self.timeout
            )
            transport.write(probe)
        if self.keepalive:
            self._keepalive_task = loop.create_task(self._keepalive_loop())
        log.debug("connected to %s", self.endpoint)

    async def close(self) -> None:
        """Close the socket; pending calls fail with KvpConnectionError."""
        self._stop_keepalive()
        if self._transport is not None and self._closed_reason is None:
            self._transport.close()
            self._fail_all(f"connection to {self.endpoint} closed")
        if self._transport is not None:
            # give the transport a chance to really close the socket
            await asyncio.sleep(0)

    # ------------------------------------------------------------------ requests

    async def read(self, name: str, *, timeout: float | None = None) -> Reply:
        return await self._request(name, encode_read(0, name), timeout)

    async def write(self, name: str, value: str, *, timeout: float | None = None) -> Reply:
        return await self._request(name, encode_write(0, name, value), timeout)

    # One watchdog timer per connection, not one timer per request: requests carry their
    # deadline and the watchdog, armed for the earliest one, fails those overdue when it fires
    # (in the serial case it is re-armed once per timeout period, not once per request).

    def _watch(self, loop: asyncio.AbstractEventLoop, deadline: float) -> None:
        if self._watchdog is None or deadline < self._watchdog_at:
            if self._watchdog is not None:
                self._watchdog.cancel()
            self._watchdog = loop.call_at(deadline, self._on_watchdog, loop)
            self._watchdog_at = deadline

    def _on_watchdog(self, loop: asyncio.AbstractEventLoop) -> None:
        self._watchdog = None
        now = loop.time()
        upcoming = None
        for p in self.session.queue:
            if p.abandoned or p.waiter.done():
                continue
            if p.deadline <= now:
                self._expire(p)
            elif upcoming is None or p.deadline < upcoming:
                upcoming = p.deadline
        if upcoming is not None:
            self._watch(loop, upcoming)

    def _expire(self, p: Pending[_Fut]) -> None:
        if not p.waiter.done():
            p.abandoned = True
            self._slot.set()  # one request in flight (legacy ids): the next may go now
            _fail(
                p.waiter,
                KvpTimeoutError(
                    f"no reply for {p.name!r} from {self.endpoint} within {p.timeout:g} s"
                ),
            )

    async def _request(self, name: str, frame0: bytes, timeout: float | None) -> Reply:
        session = self.session
        transport = self._transport
        if (
            not session.queue
            and self._closed_reason is None
            and transport is not None
            and not transport.is_closing()
        ):
            # Fast path of request_many for one request on an idle connection (the serial
            # control-loop case): same registration, deadline, send and outcome, less overhead.
            timeout = self.timeout if timeout is None else timeout
            if len(frame0) > session.pipeline_bytes:
                session.check_size(name, frame0)
            loop = asyncio.get_running_loop()
            pending = session.register(name, frame0, loop.create_future(), timeout)
            pending.deadline = deadline = loop.time() + timeout
            if self._watchdog is None or deadline < self._watchdog_at:
                self._watch(loop, deadline)
            self._last_activity = pending.sent_at = time.perf_counter()
            transport.write(pending.frame)
            try:
                return await pending.waiter
            except asyncio.CancelledError:
                pending.abandoned = True
                raise
        result = (await self._request_many([(name, frame0)], timeout))[0]
        if isinstance(result, BaseException):
            raise result
        return result

    async def request_many(
        self, items: list[tuple[str, _Builder]], *, timeout: float | None = None
    ) -> list[Reply | KvpError]:
        """Send many requests pipelined and return a reply or an error for each, in order.

        Requests are coalesced into as few socket writes as the pipelining bounds allow (every
        write holds only whole requests). A lost connection fails the whole call (after every
        outcome was collected); a timeout fails the requests still unanswered at the deadline.
        """
        return await self._request_many([(n, build(0)) for n, build in items], timeout)

    async def _request_many(
        self, items: list[tuple[str, bytes]], timeout: float | None
    ) -> list[Reply | KvpError]:
        timeout = self.timeout if timeout is None else timeout
        session = self.session
        for name, frame0 in items:  # refuse before anything is sent
            session.check_size(name, frame0)
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        if items:
            self._check_stalled(len(items[0][1]), sent_nothing=True)
        pendings: list[Pending[_Fut]] = []
        batch: list[Pending[_Fut]] = []
        self._watch(loop, deadline)
        try:
            for name, frame0 in items:
                if not session.fits(len(frame0)):
                    self._send(batch)
                    try:
                        await self._wait_for_room(len(frame0), deadline, not pendings)
                    except TimeoutError:
                        break
                else:
                    self._check_open()
                pending = session.register(name, frame0, loop.create_future(), timeout)
                pending.deadline = deadline
                pendings.append(pending)
                batch.append(pending)
            self._send(batch)
            # Armed again now that the requests are registered: one that waited for room may
            # have been registered after the watchdog last ran, found nothing due later and
            # went quiet (it re-arms only for the requests it sees), and would wait forever.
            self._watch(loop, deadline)
            results: list[Reply | KvpError] = []
            for p in pendings:  # every outcome is collected before anything is raised
                try:
                    results.append(await p.waiter)
                except KvpError as exc:
                    results.append(exc)
        except asyncio.CancelledError:
            for p in pendings:
                p.abandoned = True
            raise
        sent = len(pendings)
        pendings.clear()  # a raised error's traceback must not keep the futures alive
        for result in results:
            if isinstance(result, KvpConnectionError):
                raise result
        for name, _ in items[sent:]:
            results.append(
                KvpTimeoutError(f"no room to send {name!r} to {self.endpoint} within {timeout:g} s")
            )
        return results

    async def _wait_for_room(self, size: int, deadline: float, sent_nothing: bool) -> None:
        while True:
            self._check_open()
            if self.session.fits(size):
                return
            self._check_stalled(size, sent_nothing)
            self._slot.clear()
            async with asyncio.timeout_at(deadline):
                await self._slot.wait()

    def _check_stalled(self, size: int, sent_nothing: bool) -> None:
        now = time.perf_counter()
        if self._closed_reason is None and self.session.stalled(size, now):
            message = self.session.stall_message(now)
            log.warning("%s", message)
            if self._transport is not None:
                self._transport.abort()
            self._fail_all(message)
            raise KvpStalledError(message, sent_nothing=sent_nothing)

    def _send(self, batch: list[Pending[_Fut]]) -> None:
        if not batch:
            return
        transport = self._transport
        if transport is None or transport.is_closing():
            # Lost but not yet told (connection_lost runs on the next loop iteration): never
            # write to a dead transport (asyncio would log "socket.send() raised exception").
            self._fail_all(f"{self.endpoint} closed the connection")
            batch.clear()
            return
        now = time.perf_counter()
        for p in batch:
            p.sent_at = now
        self._last_activity = time.perf_counter()
        transport.write(batch[0].frame if len(batch) == 1 else b"".join(p.frame for p in batch))
        batch.clear()

    def _check_open(self) -> None:
        super()._check_open()
        if self._transport is None:
            raise KvpConnectionError(f"not connected to {self.endpoint}")

    # ------------------------------------------------------------------ receiving

    def _on_data(self, data: bytes) -> None:
        session = self.session
        try:
            size = len(data)
            if size >= 10 and not self._decoder.buffered:
                msg_id, length, mode, n = _HEAD.unpack_from(data)
                # one whole KVP reply: the common case (C3 types >= 4 carry raw payloads)
                if length + 4 == size and n + 10 == size and mode < FIRST_EXTENDED:
                    replies = [new_reply(msg_id, mode, data[7:-3], data[-1], data[-3:-1])]
                else:
                    replies = self._decoder.feed_replies(data)
            else:
                replies = self._decoder.feed_replies(data)
            now = time.perf_counter()
            for reply in replies:
                pending, dropped = session.dispatch(reply)
                for lost in dropped:
                    _fail(
                        lost.waiter,
                        KvpTimeoutError(
                            f"{self.endpoint} never answered the request for {lost.name!r}"
                        ),
                    )
                if pending is not None and not pending.waiter.done():
                    self.stats.record(now - pending.sent_at)
                    pending.waiter.set_result(reply)
        except ProtocolError as exc:
            self._abort(str(exc))
            return
        self._last_activity = now
        self._slot.set()

    def _on_lost(self, exc: Exception | None) -> None:
        self._fail_all(self._eof_reason(exc))

    def _abort(self, problem: str) -> None:
        log.warning("protocol error from %s: %s; dropping the connection", self.endpoint, problem)
        if self._transport is not None:
            self._transport.abort()
        self._fail_all(f"connection to {self.endpoint} dropped: protocol error: {problem}")

    def _fail_all(self, reason: str) -> None:
        if self._closed_reason is None:
            self._closed_reason = reason
        for p in self.session.clear():
            # one exception object per caller: a shared one would collect every caller's
            # traceback (and with it their frames and futures) for as long as it lives
            _fail(p.waiter, KvpConnectionError(reason))
        self._slot.set()
        self._stop_keepalive()
        if self._watchdog is not None:
            self._watchdog.cancel()
            self._watchdog = None

    def _stop_keepalive(self) -> None:
        task = self._keepalive_task
        if task is not None and task is not asyncio.current_task():
            task.cancel()
            self._keepalive_task = None

    # ------------------------------------------------------------------ keep-alive

    async def _keepalive_loop(self) -> None:
        assert self.keepalive
        interval = self.keepalive
        while self.is_open:
            idle = time.perf_counter() - self._last_activity
            if idle < interval or self.session.queue:
                await asyncio.sleep(max(interval - idle, interval / 10))
                continue
            try:
                await self.ping()
            except KvpError as exc:
                log.info("keep-alive to %s failed: %s", self.endpoint, exc)
                if not self.is_open:
                    return

    async def ping(self, *, timeout: float | None = None) -> float:
        """Round trip of a keep-alive request in seconds (``PING`` or, on old proxies, ``$OV_PRO``)."""
        start = time.perf_counter()
        name, frame = self._keepalive_frame()
        if not self._keepalive_answered(name, await self._request(name, frame, timeout)):
            name, frame = self._keepalive_frame()
            await self._request(name, frame, timeout)
        return time.perf_counter() - start
