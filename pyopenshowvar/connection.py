"""One asyncio TCP connection to a KUKAVARPROXY: ids, pipelining, timeouts, keep-alive.

Design choices, each forced by how the real proxy behaves (protocol reference §1.4, §2.5, §2.6):

* **Each request is one ``transport.write``** with TCP_NODELAY, because KVP does not reassemble
  a request cut across two TCP reads.
* **Pipelining is bounded** by a request count and by the bytes of unanswered requests: at most
  ``pipeline_bytes`` (2048, the size of KVP's single ``Read``) and at most one TCP segment of the
  path (its MSS, read from the socket at connect time). KVP parses every socket read on its own,
  and a read ends wherever the segments received so far end; while everything unanswered fits
  in one segment, no segment (and so no read) can end inside a request. A request larger than
  ``pipeline_bytes`` could never arrive in one read and is refused with :class:`ProtocolError`
  before anything is sent (raise ``pipeline_bytes`` for servers that reassemble).
* **Reply matching.** Servers answer in order. A reply is matched by id when the id is pending;
  requests sent *before* that one and still unanswered were silently dropped by the proxy (its
  "reading pending" path) and fail at once instead of waiting for their timeout. A reply whose id
  is not pending while requests are outstanding is the pre-9.0 quirk (every reply of a batch
  carries the first id): it goes to the oldest outstanding request (FIFO), which is what the
  server did answer. ``id_policy="strict"`` instead treats such a reply as a protocol error and
  drops the connection; ``"fifo"`` ignores ids entirely.
* **Timeouts never desynchronise.** A timed-out request keeps its place in the queue, marked
  abandoned; its late reply is recognised and discarded.
* **Connection loss fails every pending call at once** with :class:`KvpConnectionError`.
* **Keep-alive**: after ``keepalive`` seconds without traffic a ``PING`` is sent (KVP 9.0 answers
  ``PONG``); an older proxy answers an empty value, and from then on a cheap read of ``$OV_PRO``
  is used instead, keeping the proxy's 30 s idle timer from closing the connection.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import time
from collections import deque
from collections.abc import Callable
from typing import Literal

from .errors import KvpConnectionError, KvpError, KvpTimeoutError, ProtocolError
from .protocol import MAX_ID, Reply, ReplyDecoder, encode_read, encode_write
from .stats import AccessStats

__all__ = ["Connection", "IdPolicy"]

log = logging.getLogger(__name__)

IdPolicy = Literal["auto", "strict", "fifo"]
#: Builds a complete request frame for a given message id.
_Builder = Callable[[int], bytes]


def _segment_size(sock: socket.socket) -> int:
    """The connection's TCP MSS; 1460 (Ethernet, a KRC's KLI) where the OS does not tell."""
    try:
        return max(1, sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_MAXSEG))
    except (OSError, AttributeError):
        return 1460


class _Pending:
    __slots__ = ("abandoned", "future", "msg_id", "name", "sent_at", "size")

    def __init__(self, msg_id: int, name: str, size: int, future: asyncio.Future[Reply]) -> None:
        self.msg_id = msg_id
        self.name = name
        self.size = size
        self.future = future
        self.sent_at = 0.0
        self.abandoned = False


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
        self.max_in_flight = max(1, max_in_flight)
        self.pipeline_bytes = max(1, pipeline_bytes)
        self.id_policy = id_policy
        self.keepalive = keepalive
        self.stats = AccessStats()
        #: Replies whose id was not pending and were given to the oldest request (pre-9.0 quirk).
        self.mislabeled_replies = 0
        #: Requests the server never answered (detected when a later reply arrived).
        self.dropped_requests = 0
        self._transport: asyncio.Transport | None = None
        self._decoder = ReplyDecoder()
        self._queue: deque[_Pending] = deque()
        self._by_id: dict[int, _Pending] = {}
        self._bytes_in_flight = 0
        #: The unanswered-bytes bound in force: pipeline_bytes, lowered to the path's MSS.
        self._window = self.pipeline_bytes
        self._next_id = 0
        self._slot = asyncio.Event()
        self._closed_exc: Exception | None = None
        self._last_activity = time.monotonic()
        self._keepalive_task: asyncio.Task[None] | None = None
        self._ping_supported: bool | None = None

    @property
    def endpoint(self) -> str:
        return f"{self.host}:{self.port}"

    def use_stats(self, stats: AccessStats) -> None:
        """Record into ``stats`` (the client keeps one object across reconnects)."""
        self.stats = stats

    @property
    def is_open(self) -> bool:
        return self._transport is not None and self._closed_exc is None

    @property
    def in_flight(self) -> int:
        return len(self._queue)

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
            self._window = min(self.pipeline_bytes, _segment_size(sock))
        # No isinstance check on the transport: uvloop's transports are not asyncio.Transport
        # subclasses, and only the interface matters.
        self._transport = transport
        self._last_activity = time.monotonic()
        if self.keepalive:
            self._keepalive_task = asyncio.get_running_loop().create_task(self._keepalive_loop())
        log.debug("connected to %s", self.endpoint)

    async def close(self) -> None:
        """Close the socket; pending calls fail with KvpConnectionError."""
        if self._keepalive_task is not None:
            self._keepalive_task.cancel()
            self._keepalive_task = None
        if self._transport is not None and self._closed_exc is None:
            self._transport.close()
            self._fail_all(KvpConnectionError(f"connection to {self.endpoint} closed"))
            # give the transport a chance to really close the socket
            await asyncio.sleep(0)

    # ------------------------------------------------------------------ requests

    async def read(self, name: str, *, timeout: float | None = None) -> Reply:
        return await self._request(name, lambda i: encode_read(i, name), timeout)

    async def write(self, name: str, value: str, *, timeout: float | None = None) -> Reply:
        return await self._request(name, lambda i: encode_write(i, name, value), timeout)

    async def request_frame(
        self, name: str, build: _Builder, *, timeout: float | None = None
    ) -> Reply:
        """Send a frame made by ``build(msg_id)`` (used for modes 2/3 and tests)."""
        return await self._request(name, build, timeout)

    def _alloc_id(self) -> int:
        # Skip ids still pending (abandoned requests keep theirs until answered).
        for _ in range(MAX_ID + 1):
            msg_id = self._next_id
            self._next_id = (self._next_id + 1) & MAX_ID
            if msg_id not in self._by_id:
                return msg_id
        raise ProtocolError("no free message id")  # pragma: no cover - needs 65536 pending

    def _fits(self, size: int) -> bool:
        if not self._queue:
            return True  # a lone request always goes, whatever its size
        return (
            len(self._queue) < self.max_in_flight and self._bytes_in_flight + size <= self._window
        )

    def _check_size(self, name: str, frame: bytes) -> None:
        if len(frame) > self.pipeline_bytes:
            raise ProtocolError(
                f"request for {name!r} is {len(frame)} bytes; KUKAVARPROXY reads at most "
                f"{self.pipeline_bytes} per socket event and would cut it (see pipeline_bytes)"
            )

    async def _wait_for_room(self, size: int, deadline: float) -> None:
        while True:
            self._check_open()
            if self._fits(size):
                return
            self._slot.clear()
            async with asyncio.timeout_at(deadline):
                await self._slot.wait()

    def _register(
        self, name: str, frame0: bytes, loop: asyncio.AbstractEventLoop
    ) -> tuple[_Pending, bytes]:
        """Give ``frame0`` (built with id 0) a free id and queue it; returns the final frame."""
        msg_id = self._alloc_id()
        # ids are the first two bytes of every frame, so re-stamping is exact and cheap
        frame = msg_id.to_bytes(2, "big") + frame0[2:]
        pending = _Pending(msg_id, name, len(frame), loop.create_future())
        self._queue.append(pending)
        self._by_id[msg_id] = pending
        self._bytes_in_flight += pending.size
        return pending, frame

    def _expire(self, pendings: list[_Pending], timeout: float) -> None:
        for p in pendings:
            if not p.future.done():
                p.abandoned = True
                p.future.set_exception(
                    KvpTimeoutError(
                        f"no reply for {p.name!r} from {self.endpoint} within {timeout:g} s"
                    )
                )

    async def _request(self, name: str, build: _Builder, timeout: float | None) -> Reply:
        if not self._queue and self._closed_exc is None and self._transport is not None:
            # Fast path of request_many for one request on an idle connection (the serial
            # control-loop case): same registration, timer, flush and outcome, less overhead.
            timeout = self.timeout if timeout is None else timeout
            loop = asyncio.get_running_loop()
            frame0 = build(0)
            self._check_size(name, frame0)
            pending, frame = self._register(name, frame0, loop)
            pendings = [pending]
            timer = loop.call_at(loop.time() + timeout, self._expire, pendings, timeout)
            try:
                pending.sent_at = time.perf_counter()
                self._last_activity = time.monotonic()
                self._transport.write(frame)
                return await pending.future
            except asyncio.CancelledError:
                pending.abandoned = True
                raise
            finally:
                timer.cancel()
        results = await self.request_many([(name, build)], timeout=timeout)
        result = results[0]
        if isinstance(result, BaseException):
            raise result
        return result

    async def request_many(
        self, items: list[tuple[str, _Builder]], *, timeout: float | None = None
    ) -> list[Reply | KvpError]:
        """Send many requests pipelined and return a reply or an error for each, in order.

        Requests are coalesced into as few socket writes as the pipelining bounds allow (every
        write holds only whole requests). A lost connection fails the whole call; a timeout
        fails the requests still unanswered at the deadline.
        """
        timeout = self.timeout if timeout is None else timeout
        frames0 = [(name, build(0)) for name, build in items]
        for name, frame0 in frames0:  # refuse before anything is sent
            self._check_size(name, frame0)
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        pendings: list[_Pending] = []
        results: list[Reply | KvpError] = []
        batch: list[bytes] = []
        timer = loop.call_at(deadline, self._expire, pendings, timeout)
        try:
            for name, frame0 in frames0:
                if not self._fits(len(frame0)):
                    self._flush(batch)
                    try:
                        await self._wait_for_room(len(frame0), deadline)
                    except TimeoutError:
                        break
                else:
                    self._check_open()
                pending, frame = self._register(name, frame0, loop)
                pendings.append(pending)
                batch.append(frame)
            self._flush(batch)
            for p in pendings:
                try:
                    results.append(await p.future)
                except KvpTimeoutError as exc:
                    results.append(exc)
        except asyncio.CancelledError:
            for p in pendings:
                p.abandoned = True
            raise
        finally:
            timer.cancel()
        for name, _ in items[len(pendings) :]:
            results.append(
                KvpTimeoutError(f"no room to send {name!r} to {self.endpoint} within {timeout:g} s")
            )
        return results

    def _flush(self, batch: list[bytes]) -> None:
        if not batch:
            return
        assert self._transport is not None
        now = time.perf_counter()
        for p in self._queue:
            if not p.sent_at:
                p.sent_at = now
        self._last_activity = time.monotonic()
        self._transport.write(batch[0] if len(batch) == 1 else b"".join(batch))
        batch.clear()

    def _check_open(self) -> None:
        if self._closed_exc is not None:
            raise KvpConnectionError(f"connection to {self.endpoint} is closed: {self._closed_exc}")
        if self._transport is None:
            raise KvpConnectionError(f"not connected to {self.endpoint}")

    # ------------------------------------------------------------------ receiving

    def _on_data(self, data: bytes) -> None:
        try:
            replies = self._decoder.feed_replies(data)
        except ProtocolError as exc:
            log.warning("protocol error from %s: %s", self.endpoint, exc)
            self._abort(exc)
            return
        now = time.perf_counter()
        for reply in replies:
            self._dispatch(reply, now)
        self._last_activity = time.monotonic()

    def _dispatch(self, reply: Reply, now: float) -> None:
        pending = self._by_id.get(reply.msg_id) if self.id_policy != "fifo" else None
        if pending is not None:
            # Requests ahead of it were dropped by the server: it never reorders.
            while self._queue and self._queue[0] is not pending:
                lost = self._queue[0]
                self._finish(lost)
                self.dropped_requests += 1
                if not lost.future.done():
                    lost.future.set_exception(
                        KvpTimeoutError(
                            f"{self.endpoint} never answered the request for {lost.name!r}"
                        )
                    )
        elif self._queue:
            if self.id_policy == "strict":
                self._abort(ProtocolError(f"reply id {reply.msg_id} matches no request"))
                return
            pending = self._queue[0]
            if self.id_policy == "auto":
                self.mislabeled_replies += 1
                if self.mislabeled_replies == 1:
                    log.warning(
                        "%s answers with wrong message ids (pre-9.0 proxy?); matching in order",
                        self.endpoint,
                    )
        else:
            log.debug("discarding unexpected reply id %d from %s", reply.msg_id, self.endpoint)
            return
        self._finish(pending)
        if pending.abandoned or pending.future.done():
            return
        self.stats.record(now - pending.sent_at)
        pending.future.set_result(reply)

    def _finish(self, pending: _Pending) -> None:
        if self._queue and self._queue[0] is pending:
            self._queue.popleft()
        else:  # pragma: no cover - defensive, the queue head is always the match
            self._queue.remove(pending)
        if self._by_id.get(pending.msg_id) is pending:
            del self._by_id[pending.msg_id]
        self._bytes_in_flight -= pending.size
        self._slot.set()

    def _on_lost(self, exc: Exception | None) -> None:
        try:
            self._decoder.eof()
            reason: Exception = KvpConnectionError(
                f"{self.endpoint} closed the connection" + (f": {exc}" if exc else "")
            )
        except ProtocolError:
            reason = KvpConnectionError(
                f"{self.endpoint} closed the connection in the middle of a reply"
            )
        self._fail_all(reason)

    def _abort(self, exc: Exception) -> None:
        if self._transport is not None:
            self._transport.abort()
        self._fail_all(KvpConnectionError(f"connection to {self.endpoint} dropped: {exc}"))

    def _fail_all(self, exc: Exception) -> None:
        if self._closed_exc is None:
            self._closed_exc = exc
        while self._queue:
            p = self._queue.popleft()
            if not p.future.done():
                p.future.set_exception(exc)
                # mark retrieved so asyncio does not warn about abandoned futures
                if p.abandoned:
                    p.future.exception()
        self._by_id.clear()
        self._bytes_in_flight = 0
        self._slot.set()
        if self._keepalive_task is not None and self._keepalive_task is not asyncio.current_task():
            self._keepalive_task.cancel()

    # ------------------------------------------------------------------ keep-alive

    async def _keepalive_loop(self) -> None:
        assert self.keepalive
        interval = self.keepalive
        while self.is_open:
            idle = time.monotonic() - self._last_activity
            if idle < interval:
                await asyncio.sleep(interval - idle)
                continue
            try:
                await self.ping()
            except (KvpTimeoutError, KvpConnectionError) as exc:
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
