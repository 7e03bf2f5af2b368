"""One asyncio TCP connection to a KUKAVARPROXY: sending, timeouts, stalls, keep-alive.

The id and matching rules live in :mod:`pyopenshowvar.session` (shared with the blocking
client); this module adds what is asyncio-specific. Design choices, each forced by how the
real proxy behaves (protocol reference §1.4, §2.5, §2.6):

* **Each request is one ``transport.write``** with TCP_NODELAY, because KVP does not reassemble
  a request cut across two TCP reads.
* **Pipelining is bounded** by a request count and by the bytes of unanswered requests
  (default 2048, the size of KVP's single ``Read``), so a burst can never be cut at the proxy's
  buffer boundary.
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
import socket
import time
from collections.abc import Callable

from .errors import KvpConnectionError, KvpError, KvpStalledError, KvpTimeoutError, ProtocolError
from .protocol import Reply, ReplyDecoder, encode_read, encode_write
from .session import IdPolicy, Pending, Session
from .stats import AccessStats

__all__ = ["Connection", "IdPolicy"]

log = logging.getLogger(__name__)

#: Builds a complete request frame for a given message id.
_Builder = Callable[[int], bytes]
_Fut = asyncio.Future[Reply]


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


class Connection:
    """A connected KVP session. Use :meth:`open`; normally wrapped by :class:`~pyopenshowvar.Client`."""

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
        self.session: Session[_Fut] = Session(
            self.endpoint,
            max_in_flight=max_in_flight,
            pipeline_bytes=pipeline_bytes,
            id_policy=id_policy,
        )
        self.stats = AccessStats()
        self._transport: asyncio.Transport | None = None
        self._decoder = ReplyDecoder()
        self._slot = asyncio.Event()
        self._closed_reason: str | None = None
        self._last_activity = time.monotonic()
        self._keepalive_task: asyncio.Task[None] | None = None
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

    def use_stats(self, stats: AccessStats) -> None:
        """Record into ``stats`` (the client keeps one object across reconnects)."""
        self.stats = stats

    @property
    def closed_reason(self) -> str | None:
        """Why the connection was closed, lost or dropped (None while open)."""
        return self._closed_reason

    @property
    def is_open(self) -> bool:
        """Connected and healthy: False once lost, closed, dropped or marked stalled."""
        return self._transport is not None and self._closed_reason is None

    @property
    def in_flight(self) -> int:
        return len(self.session.queue)

    # ------------------------------------------------------------------ life cycle

    @classmethod
    async def open(
        cls, host: str, port: int, *, connect_timeout: float | None = None, **kw: object
    ) -> Connection:
        conn = cls(host, port, **kw)  # type: ignore[arg-type]
        await conn._connect(connect_timeout if connect_timeout is not None else conn.timeout)
        return conn

    async def _connect(self, timeout: float) -> None:
        loop = asyncio.get_running_loop()
        try:
            async with asyncio.timeout(timeout):
                transport, _ = await loop.create_connection(
                    lambda: _Protocol(self), self.host, self.port
                )
        except TimeoutError as exc:
            raise KvpTimeoutError(
                f"connecting to {self.endpoint} timed out after {timeout:g} s"
            ) from exc
        except OSError as exc:
            raise KvpConnectionError(
                f"cannot connect to {self.endpoint}: {exc.strerror or exc}"
            ) from exc
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        # No isinstance check on the transport: uvloop's transports are not asyncio.Transport
        # subclasses, and only the interface matters.
        self._transport = transport
        self._last_activity = time.monotonic()
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

    async def request_frame(
        self, name: str, build: _Builder, *, timeout: float | None = None
    ) -> Reply:
        """Send a frame made by ``build(msg_id)`` (used for modes 2/3 and tests)."""
        return await self._request(name, build(0), timeout)

    def _expire(self, pendings: list[Pending[_Fut]], timeout: float) -> None:
        for p in pendings:
            if not p.waiter.done():
                p.abandoned = True
                _fail(
                    p.waiter,
                    KvpTimeoutError(
                        f"no reply for {p.name!r} from {self.endpoint} within {timeout:g} s"
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
            # control-loop case): same registration, timer, send and outcome, less overhead.
            timeout = self.timeout if timeout is None else timeout
            loop = asyncio.get_running_loop()
            pending = session.register(name, frame0, loop.create_future(), timeout)
            pendings = [pending]
            timer = loop.call_at(loop.time() + timeout, self._expire, pendings, timeout)
            try:
                pending.sent_at = time.perf_counter()
                self._last_activity = time.monotonic()
                transport.write(pending.frame)
                return await pending.waiter
            except asyncio.CancelledError:
                pending.abandoned = True
                raise
            finally:
                timer.cancel()
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
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        session = self.session
        if items:
            self._check_stalled(len(items[0][1]), sent_nothing=True)
        pendings: list[Pending[_Fut]] = []
        batch: list[Pending[_Fut]] = []
        timer = loop.call_at(deadline, self._expire, pendings, timeout)
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
                pendings.append(pending)
                batch.append(pending)
            self._send(batch)
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
        finally:
            timer.cancel()
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
        self._last_activity = time.monotonic()
        transport.write(batch[0].frame if len(batch) == 1 else b"".join(p.frame for p in batch))
        batch.clear()

    def _check_open(self) -> None:
        if self._closed_reason is not None:
            raise KvpConnectionError(
                f"connection to {self.endpoint} is closed: {self._closed_reason}"
            )
        if self._transport is None:
            raise KvpConnectionError(f"not connected to {self.endpoint}")

    # ------------------------------------------------------------------ receiving

    def _on_data(self, data: bytes) -> None:
        session = self.session
        try:
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
        self._last_activity = time.monotonic()
        self._slot.set()

    def _on_lost(self, exc: Exception | None) -> None:
        try:
            self._decoder.eof()
            reason = f"{self.endpoint} closed the connection" + (f": {exc}" if exc else "")
        except ProtocolError:
            reason = f"{self.endpoint} closed the connection in the middle of a reply"
        self._fail_all(reason)

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
            idle = time.monotonic() - self._last_activity
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
        if self._ping_supported is not False:
            reply = await self.read("PING", timeout=timeout)
            if reply.ok and reply.value == b"PONG":
                self._ping_supported = True
                return time.perf_counter() - start
            self._ping_supported = False
            log.info(
                "%s does not answer PING (pre-9.0 proxy); keeping alive with $OV_PRO", self.endpoint
            )
        await self.read("$OV_PRO", timeout=timeout)
        return time.perf_counter() - start
