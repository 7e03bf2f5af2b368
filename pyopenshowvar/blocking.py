"""One blocking TCP connection to a KUKAVARPROXY, for the synchronous client.

The same rules as the asyncio connection — ids, matching and checks from
:mod:`pyopenshowvar.session`, one write per burst of whole requests, bounded pipelining,
timeouts that never desynchronise, stall detection — on a plain blocking socket: no event
loop, no thread per call. A lock makes one connection safe to share between threads.

Timeouts are kernel socket timeouts (``SO_RCVTIMEO``/``SO_SNDTIMEO``), set only when the
call's timeout changes, so a serial read costs one ``send`` and one ``recv`` system call, as in
the plainest client; Python's own socket timeouts would add a ``poll`` to every call.
A serial read on an idle connection (:meth:`BlockingConnection.idle_request`) is checked and
returned straight from its one recv when its reply comes whole and alone; any other case falls
back to the queue, the decoder and the general matching rules.
Keep-alive, when enabled, is a daemon thread that pings only while the connection is idle and
nobody else holds it.
"""

from __future__ import annotations

import logging
import socket
import struct
import sys
import threading
import time
from typing import Any, NoReturn

from .errors import KvpConnectionError, KvpError, KvpStalledError, KvpTimeoutError, ProtocolError
from .link import LinkBase
from .protocol import FIRST_EXTENDED, Reply, encode_read
from .session import Pending, new_reply

__all__ = ["BlockingConnection"]

log = logging.getLogger(__name__)

#: What a pending request of the blocking connection holds: nothing yet, its reply or its error.
_Outcome = Reply | KvpError | None
#: id, L, mode, value length: the head of a reply
_HEAD = struct.Struct(">HHBH")
#: a message id as the first two bytes of a frame
_ID = struct.Struct(">H")
#: read requests remembered by name (a control loop reads the same few names again and again)
_READS_MAX = 256
_clock = time.perf_counter


def _timeval(seconds: float, windows: bool = sys.platform == "win32") -> bytes:
    """SO_RCVTIMEO/SO_SNDTIMEO for ``seconds``, never 0 (which means "wait forever"): a
    ``struct timeval``, or on Windows a DWORD of milliseconds."""
    if windows:
        return struct.pack("I", max(1, int(seconds * 1000)))
    sec = int(seconds)
    usec = max(1, int((seconds - sec) * 1e6)) if sec == 0 else int((seconds - sec) * 1e6)
    return struct.pack("ll", sec, usec)


class BlockingConnection(LinkBase[_Outcome]):
    """A connected KVP session on a blocking socket (see :class:`pyopenshowvar.sync.Client`)."""

    def __init__(self, host: str, port: int, **kw: Any) -> None:
        super().__init__(host, port, **kw)
        self.lock = threading.RLock()
        self._sock: socket.socket | None = None
        self._sock_timeout = -1.0
        self._stop = threading.Event()
        #: the decoder holds part of a reply (kept by _dispatch: cheaper than asking it)
        self._partial = False
        #: read requests by name, without their id, and their values' prefix (see idle_request)
        self._reads: dict[str, tuple[bytes, bytes | None]] = {}

    @property
    def is_open(self) -> bool:
        return self._sock is not None and self._closed_reason is None

    # ------------------------------------------------------------------ life cycle

    def connect(self, timeout: float) -> None:
        try:
            sock = socket.create_connection((self.host, self.port), timeout=timeout)
        except OSError as exc:  # TimeoutError included
            raise self._connect_error(exc, timeout) from exc
        self._connected(sock)
        sock.settimeout(None)  # blocking; the kernel timeouts below bound every call
        self._sock = sock
        self._last_activity = time.perf_counter()
        if self.session.needs_probe:
            self._sendall(self.session.register_probe(None, time.perf_counter(), self.timeout))
        if self.keepalive:
            threading.Thread(
                target=self._keepalive_loop, name=f"kvp-keepalive {self.endpoint}", daemon=True
            ).start()
        log.debug("connected to %s", self.endpoint)

    def close(self) -> None:
        self._stop.set()
        with self.lock:
            if self._sock is not None and self._closed_reason is None:
                self._fail_all(f"connection to {self.endpoint} closed")

    # ------------------------------------------------------------------ requests

    def request(self, name: str, frame0: bytes, timeout: float | None) -> Reply:
        """Send one request and wait for its reply (raises its error)."""
        return self._exchange(name, frame0, timeout)

    def idle_request(
        self, name: str, timeout: float | None, tail: bytes | None = None
    ) -> str | Reply | None:
        """One request on an idle connection, sent and answered without being queued: the
        serial read of :meth:`pyopenshowvar.sync.Client.read` and the first try of
        :meth:`request`.

        Without ``tail`` it reads ``name`` and returns the text of a successful read with a
        non-empty value, or the :class:`Reply` of any other answer for the caller to
        interpret. With ``tail`` (a request frame without its two id bytes) it sends that and
        returns its :class:`Reply`. None when the connection is not idle (closed, requests
        pending, bytes buffered) or the read request is too large: nothing was sent and the
        caller takes the general path. Raises what :meth:`request` raises.
        """
        if tail is None:
            entry = self._reads.get(name) or self._read_entry(name)
            if entry is None:
                return None
            tail, prefix = entry
            text = True
        else:
            prefix = None
            text = False
        if timeout is None:
            timeout = self.timeout
        lock = self.lock
        lock.acquire()  # not `with`: its __exit__ call costs twice an acquire and a release
        try:
            sock = self._sock
            session = self.session
            if sock is None or self._closed_reason is not None or session.queue or self._partial:
                return None
            # The control-loop hot path, written out: its cost is a serial read's round trip.
            if timeout != self._sock_timeout:
                self._fit_timeout(timeout)
            msg_id = session.next_id  # an idle connection: no id is pending
            session.next_id = (msg_id + 1) & 0xFFFF
            frame = _ID.pack(msg_id) + tail
            self._last_activity = sent_at = _clock()
            try:
                sock.sendall(frame)
            except OSError as exc:
                self._send_failed(exc)
            try:
                data = sock.recv(65536)
            except OSError:
                data = b""  # timed out or lost: the general path meets it again and decides
            size = len(data)
            if text and size > 10:
                rid, length, mode, n = _HEAD.unpack_from(data)
                # one whole reply with our id, mode 0, success and a non-empty value
                if (
                    rid == msg_id
                    and length == size - 4
                    and n == size - 10
                    and mode == 0
                    and data[-1] == 1
                ):
                    now = _clock()
                    value = data[7:-3]
                    if prefix is not None and value.startswith(prefix):
                        session.last_label = msg_id  # its shape holds (Session.text_prefix)
                    else:
                        self._check_value(name, msg_id, value, tail)
                    self.stats.record(now - sent_at)
                    return value.decode("latin-1")
            return self._finish_idle(name, frame, data, sent_at, timeout)
        finally:
            lock.release()

    def _read_entry(self, name: str) -> tuple[bytes, bytes | None] | None:
        """A read request for ``name`` without its id, and the prefix of its value once known;
        None when the request is too large to send."""
        frame0 = encode_read(0, name)
        if len(frame0) > self.session.pipeline_bytes:
            return None  # the general path refuses it with the reason
        entry = (frame0[2:], self.session.text_prefix(name))
        if len(self._reads) < _READS_MAX:
            self._reads[name] = entry
        return entry

    def _check_value(self, name: str, msg_id: int, value: bytes, tail: bytes) -> None:
        """The session's check of a successful read's value (it learns the variable's shape
        on the first read); remembers the shape's prefix for the next reads of ``name``."""
        session = self.session
        try:
            session.answered_read(name, msg_id, value)
        except ProtocolError as exc:
            self._protocol_error(exc)
            raise KvpConnectionError(self._closed_reason or "") from None
        prefix = session.text_prefix(name)
        if prefix is not None and name in self._reads:
            self._reads[name] = (tail, prefix)

    def _exchange(self, name: str, frame0: bytes, timeout: float | None) -> Reply:
        """:meth:`request`; on an idle connection, without queueing the request first."""
        timeout = self.timeout if timeout is None else timeout
        session = self.session
        if len(frame0) > session.pipeline_bytes:
            session.check_size(name, frame0)
        reply = self.idle_request(name, timeout, frame0[2:])
        if reply is None:  # not idle: queue it behind the others
            with self.lock:
                self._check_open()
                return self._request_queued(name, frame0, timeout)
        assert isinstance(reply, Reply)  # given a tail, never a text
        return reply

    def _finish_idle(
        self, name: str, frame: bytes, data: bytes, sent_at: float, timeout: float
    ) -> Reply:
        """The reply to ``frame``, sent on an idle connection without being queued, given the
        first bytes received. The serial case: the reply comes whole in one recv, alone, and
        needs no queue, no index and no decoder buffer. Anything else (a cut reply, several
        frames, another id, a timeout) queues the request after all, and the general path
        sorts it out."""
        session = self.session
        size = len(data)
        if size >= 10 and data[:2] == frame[:2]:
            msg_id, length, mode, n = _HEAD.unpack_from(data)
            if length + 4 == size and n + 10 == size and mode < FIRST_EXTENDED:
                now = _clock()
                reply = new_reply(msg_id, mode, data[7:-3], data[-1], data[-3:-1])
                try:
                    session.answered_idle(name, frame, reply)
                except ProtocolError as exc:
                    self._protocol_error(exc)
                    raise KvpConnectionError(self._closed_reason or "") from None
                self.stats.record(now - sent_at)
                return reply
        pending = session.register_sent(name, frame, None, timeout)
        pending.sent_at = sent_at
        if data:
            self._dispatch(data)
        return self._wait(pending, sent_at + timeout, timeout)

    def _request_queued(self, name: str, frame0: bytes, timeout: float) -> Reply:
        session = self.session
        deadline = time.perf_counter() + timeout
        if not session.fits(len(frame0)):
            self._wait_for_room(len(frame0), deadline, True)
        pending = session.register(name, frame0, None, timeout)
        pending.sent_at = time.perf_counter()
        self._sendall(pending.frame)
        return self._wait(pending, deadline, timeout)

    def _wait(self, pending: Pending[_Outcome], deadline: float, timeout: float) -> Reply:
        while pending.waiter is None:
            if not self._receive(deadline):
                pending.abandoned = True
                raise KvpTimeoutError(
                    f"no reply for {pending.name!r} from {self.endpoint} within {timeout:g} s"
                )
        outcome = pending.waiter
        if isinstance(outcome, KvpError):
            raise outcome
        return outcome

    def request_many(
        self, items: list[tuple[str, bytes]], timeout: float | None
    ) -> list[Reply | KvpError]:
        """Send many requests pipelined; a reply or an error for each, in order."""
        timeout = self.timeout if timeout is None else timeout
        with self.lock:
            session = self.session
            for name, frame0 in items:  # refuse before anything is sent
                session.check_size(name, frame0)
            self._check_open()
            deadline = time.perf_counter() + timeout
            pendings: list[Pending[_Outcome]] = []
            batch: list[bytes] = []
            timed_out = False
            for name, frame0 in items:
                if not session.fits(len(frame0)):
                    self._flush(batch, pendings)
                    if not self._wait_for_room(len(frame0), deadline, not pendings):
                        timed_out = True
                        break
                pending = session.register(name, frame0, None, timeout)
                pendings.append(pending)
                batch.append(pending.frame)
            self._flush(batch, pendings)
            while not timed_out and any(p.waiter is None for p in pendings):
                timed_out = not self._receive(deadline)
            results: list[Reply | KvpError] = []
            for p in pendings:
                if p.waiter is None:
                    p.abandoned = True
                    p.waiter = KvpTimeoutError(
                        f"no reply for {p.name!r} from {self.endpoint} within {timeout:g} s"
                    )
                results.append(p.waiter)
            for result in results:  # a lost connection fails the whole call, as in asyncio
                if isinstance(result, KvpConnectionError):
                    raise result
            results += [
                KvpTimeoutError(f"no room to send {name!r} to {self.endpoint} within {timeout:g} s")
                for name, _ in items[len(pendings) :]
            ]
            return results

    def _flush(self, batch: list[bytes], pendings: list[Pending[_Outcome]]) -> None:
        if batch:
            now = time.perf_counter()
            for p in pendings[len(pendings) - len(batch) :]:
                p.sent_at = now
            self._sendall(b"".join(batch))
            batch.clear()

    def _wait_for_room(self, size: int, deadline: float, sent_nothing: bool) -> bool:
        """Receive until ``size`` more bytes may be sent; False at the deadline."""
        session = self.session
        while not session.fits(size):
            if session.stalled(size, time.perf_counter()):
                message = session.stall_message(time.perf_counter())
                log.warning("%s", message)
                self._fail_all(message)
                raise KvpStalledError(message, sent_nothing=sent_nothing)
            if not self._receive(deadline):
                return False
            self._check_open()
        return True

    # ------------------------------------------------------------------ socket

    def _check_open(self) -> None:
        super()._check_open()
        if self._sock is None:
            raise KvpConnectionError(f"not connected to {self.endpoint}")

    def _set_timeout(self, seconds: float) -> None:
        assert self._sock is not None
        if seconds != self._sock_timeout:
            tv = _timeval(seconds)
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, tv)
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, tv)
            self._sock_timeout = seconds

    def _sendall(self, data: bytes) -> None:
        sock = self._sock
        assert sock is not None
        self._last_activity = time.perf_counter()
        if self._sock_timeout < 0:
            self._set_timeout(self.timeout)
        try:
            sock.sendall(data)
        except OSError as exc:
            self._send_failed(exc)

    def _send_failed(self, exc: OSError) -> NoReturn:
        # Timed out or failed part-way: the stream may hold half a request; drop it.
        why = "timed out" if isinstance(exc, BlockingIOError | TimeoutError) else str(exc)
        self._fail_all(f"sending to {self.endpoint} failed: {why}")
        raise KvpConnectionError(f"sending to {self.endpoint} failed: {why}") from None

    def _fit_timeout(self, timeout: float) -> None:
        """Re-arm the kernel timeout only when it is far off (a syscall): a wait may overshoot
        the deadline by at most 10 % + 5 ms, and never stops short of it."""
        current = self._sock_timeout
        if current < 0 or current > timeout * 1.1 + 0.005 or current < timeout / 2:
            self._set_timeout(timeout)

    def _receive(self, deadline: float) -> bool:
        """One ``recv`` and the dispatch of the replies it completes; False at the deadline.

        A lost connection or a protocol error fails every unanswered request (their outcome
        is a :class:`KvpConnectionError`) and closes the connection; it does not raise.
        """
        sock = self._sock
        assert sock is not None
        remaining = deadline - time.perf_counter()
        if remaining <= 0:
            return False
        self._fit_timeout(remaining)
        try:
            data = sock.recv(65536)
        except (BlockingIOError, TimeoutError):
            return time.perf_counter() < deadline
        except OSError as exc:
            self._fail_all(f"{self.endpoint} closed the connection: {exc}")
            return True
        if not data:
            self._fail_all(self._eof_reason())
            return True
        self._dispatch(data)
        return True

    def _dispatch(self, data: bytes) -> None:
        self._last_activity = now = time.perf_counter()
        session = self.session
        try:
            for reply in self._decoder.feed_replies(data):
                pending, dropped = session.dispatch(reply)
                for lost in dropped:
                    lost.waiter = KvpTimeoutError(
                        f"{self.endpoint} never answered the request for {lost.name!r}"
                    )
                if pending is not None:
                    self.stats.record(now - pending.sent_at)
                    pending.waiter = reply
        except ProtocolError as exc:
            self._protocol_error(exc)
        finally:
            self._partial = self._decoder.buffered > 0

    def _protocol_error(self, exc: ProtocolError) -> None:
        log.warning("protocol error from %s: %s; dropping the connection", self.endpoint, exc)
        # replies matched before the bad one keep their outcome; the rest fail
        self._fail_all(f"connection to {self.endpoint} dropped: protocol error: {exc}")

    def _fail_all(self, reason: str) -> None:
        if self._closed_reason is None:
            self._closed_reason = reason
        for p in self.session.clear():
            if p.waiter is None:
                p.waiter = KvpConnectionError(reason)
        self._stop.set()
        if self._sock is not None:
            try:
                self._sock.close()
            except OSError:  # pragma: no cover - closing never matters here
                pass

    # ------------------------------------------------------------------ keep-alive

    def _keepalive_loop(self) -> None:
        assert self.keepalive
        interval = self.keepalive
        while not self._stop.wait(max(interval / 10, 0.01)):
            if time.perf_counter() - self._last_activity < interval:
                continue
            if not self.lock.acquire(blocking=False):
                continue  # a call is running: the connection is not idle
            try:
                if self.is_open:
                    self.ping(None)
            except KvpError as exc:
                log.info("keep-alive to %s failed: %s", self.endpoint, exc)
            finally:
                self.lock.release()

    def ping(self, timeout: float | None) -> float:
        """Round trip of a keep-alive request in seconds (``PING`` or, on old proxies, ``$OV_PRO``)."""
        start = time.perf_counter()
        name, frame = self._keepalive_frame()
        if not self._keepalive_answered(name, self.request(name, frame, timeout)):
            name, frame = self._keepalive_frame()
            self.request(name, frame, timeout)
        return time.perf_counter() - start
