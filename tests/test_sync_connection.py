"""The blocking connection's own rules, each driven through a deliberately odd peer.

What the serial fast path hands over is in ``tests/test_sync_fast_path.py``; here: kernel
timeouts (never "wait forever", re-armed when a call's timeout shrinks), a send into a reset
connection or one that times out, keep-alive (idle only, ``PING`` or ``$OV_PRO``, surviving a
failed ping), the pipelined ``read_many``/``write_many`` (refused before sending, bounded
window, lost connection, no room, a stall after part of a burst was sent) and a refused
connect. Servers are real sockets on 127.0.0.1; the one fake socket stands for a peer whose
receive window stays shut.
"""

from __future__ import annotations

import asyncio
import itertools
import re
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from pyopenshowvar import (
    KvpConnectionError,
    KvpStalledError,
    KvpTimeoutError,
    ProtocolError,
    ReadFailedError,
    UnknownVariableError,
    sync,
)
from pyopenshowvar.blocking import _timeval
from pyopenshowvar.protocol import Mode, Reply, Request, encode_reply
from pyopenshowvar.testing import FakeProxy, answer


def _poll(condition: Callable[[], bool], within: float = 5.0) -> bool:
    deadline = time.monotonic() + within
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


# --------------------------------------------------------------------------- kernel timeouts


@pytest.mark.parametrize(
    ("seconds", "sec", "usec"),
    [(2.5, 2, 500_000), (3.0, 3, 0), (0.25, 0, 250_000), (1e-9, 0, 1), (0.0, 0, 1)],
)
def test_a_kernel_timeout_is_the_call_timeout_and_never_zero(
    seconds: float, sec: int, usec: int
) -> None:
    """SO_RCVTIMEO of 0 means "wait forever": a tiny timeout must become 1 µs, not 0."""
    assert struct.unpack("ll", _timeval(seconds, windows=False)) == (sec, usec)


@pytest.mark.parametrize(("seconds", "ms"), [(2.5, 2500), (0.25, 250), (1e-6, 1), (0.0, 1)])
def test_a_kernel_timeout_on_windows_is_milliseconds_and_never_zero(
    seconds: float, ms: int
) -> None:
    assert _timeval(seconds, windows=True) == struct.pack("I", ms)


def test_a_shorter_timeout_after_a_longer_one_bounds_the_wait() -> None:
    """The kernel timeout armed for 2 s is re-armed for a 1 s call (a wait may overshoot by
    10 % + 5 ms at most, and never stops short); the idle read, an idle write and a read
    queued behind an unanswered one all keep their own timeout. Takes about 1.3 s."""

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if not req.name.startswith("SILENT"):
            w.write(answer(req))

    with FakeProxy(handler) as port:
        with sync.Client(port=port, timeout=2.0) as kvp:
            assert kvp.read("A") == "v:A"  # arms the kernel timeout at 2 s
            t0 = time.monotonic()
            with pytest.raises(KvpTimeoutError, match=r"within 1 s"):
                kvp.read("SILENT", timeout=1.0)
            assert 0.99 <= time.monotonic() - t0 < 1.6  # not the 2 s armed before
            t0 = time.monotonic()
            with pytest.raises(KvpTimeoutError, match=r"within 0\.1 s"):
                kvp.write("SILENT", "1", timeout=0.1)  # the general path, behind SILENT's read
            assert time.monotonic() - t0 < 1.0
        with sync.Client(port=port, timeout=5.0) as kvp:
            assert kvp.read("A") == "v:A"
            t0 = time.monotonic()
            with pytest.raises(KvpTimeoutError, match=r"within 0\.1 s"):
                kvp.write("SILENTW", "1", timeout=0.1)  # the idle path of a write
            assert time.monotonic() - t0 < 1.0


def test_the_first_call_of_a_connection_without_a_probe_is_bounded() -> None:
    """id_policy="strict" sends nothing at connect: the first call arms the kernel timeout."""

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        pass

    with (
        FakeProxy(handler) as port,
        sync.Client(port=port, timeout=1.0, id_policy="strict") as kvp,
    ):
        t0 = time.monotonic()
        with pytest.raises(KvpTimeoutError):
            kvp.read("SILENT")
        assert time.monotonic() - t0 < 1.6
        conn = kvp.connection
        assert conn is not None and conn._sock is not None
        assert conn._sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1


# --------------------------------------------------------------------------- failed sends


@pytest.fixture
def resetting_server() -> Iterator[tuple[int, threading.Event]]:
    """A server that answers one read (id echoed), then resets the connection (RST)."""
    srv = socket.create_server(("127.0.0.1", 0))
    reset = threading.Event()

    def serve() -> None:
        conn, _ = srv.accept()
        with conn:
            request = conn.recv(4096)
            conn.sendall(encode_reply(Reply(int.from_bytes(request[:2], "big"), 0, b"1")))
            conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        reset.set()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield srv.getsockname()[1], reset
    srv.close()
    thread.join(5.0)


def test_a_send_into_a_reset_connection_fails_loudly_and_closes_it(
    resetting_server: tuple[int, threading.Event],
) -> None:
    port, reset = resetting_server
    with sync.Client(port=port, timeout=2.0, id_policy="strict") as kvp:
        assert kvp.read("$OV_PRO") == "1"
        assert reset.wait(5.0)
        assert _poll(lambda: _peer_gone(kvp))
        failed = rf"sending to 127\.0\.0\.1:{port} failed: \[Errno \d+\]"  # the OS's reason
        with pytest.raises(KvpConnectionError, match=failed):
            kvp.write("$OV_PRO", "2")
        assert not kvp.connected
        assert kvp.connection is not None and "sending" in (kvp.connection.closed_reason or "")
        with pytest.raises(KvpConnectionError, match="is closed: sending"):
            kvp.read("$OV_PRO")


def _peer_gone(kvp: sync.Client) -> bool:
    """The RST has reached the client's socket (it reports a pending error)."""
    conn = kvp.connection
    assert conn is not None and conn._sock is not None
    return conn._sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR) != 0 or _peeked_eof(conn._sock)


def _peeked_eof(sock: socket.socket) -> bool:
    sock.setblocking(False)
    try:
        return sock.recv(1, socket.MSG_PEEK) == b""
    except BlockingIOError:
        return False
    except OSError:
        return True
    finally:
        sock.setblocking(True)


class _ShutWindow:
    """A socket whose peer never opens its receive window: every send times out."""

    def __init__(self, sock: socket.socket) -> None:
        self._sock = sock

    def sendall(self, data: bytes) -> None:
        raise BlockingIOError(11, "Resource temporarily unavailable")

    def recv(self, size: int) -> bytes:  # pragma: no cover - never reached
        raise AssertionError("nothing was sent")

    def setsockopt(self, *args: Any) -> None:
        pass

    def close(self) -> None:
        self._sock.close()


@pytest.mark.parametrize("call", ["read", "read_many"])
def test_a_send_that_times_out_says_so_and_closes_the_connection(call: str) -> None:
    with FakeProxy(lambda req, w, n: _write(w, answer(req))) as port:
        with sync.Client(port=port, timeout=1.0) as kvp:
            kvp.read("A")
            conn = kvp.connection
            assert conn is not None and conn._sock is not None
            conn._sock = _ShutWindow(conn._sock)  # type: ignore[assignment]
            expected = f"sending to 127.0.0.1:{port} failed: timed out"
            with pytest.raises(KvpConnectionError, match=expected):
                if call == "read":
                    kvp.read("B")
                else:
                    kvp.read_many(["B", "C"])
            assert conn.closed_reason == expected


async def _write(w: asyncio.StreamWriter, data: bytes) -> None:
    w.write(data)


# --------------------------------------------------------------------------- keep-alive


class _Recorder:
    """A FakeProxy handler that records (time, name) and answers PING as ``pong``."""

    def __init__(self, pong: bytes = b"PONG", ignore_first_ping: bool = False) -> None:
        self.seen: list[tuple[float, str]] = []
        self.pong = pong
        self.ignore_first_ping = ignore_first_ping

    async def __call__(self, req: Request, w: asyncio.StreamWriter, n: int) -> None:
        self.seen.append((time.monotonic(), req.name))
        if req.name == "PING":
            if self.ignore_first_ping:
                self.ignore_first_ping = False
                return
            w.write(answer(req, self.pong))
        else:
            w.write(answer(req))

    def names(self, name: str) -> list[float]:
        return [t for t, n in self.seen if n == name]


def test_keepalive_pings_only_an_idle_connection_once_per_interval() -> None:
    """Times are taken where the proxy decodes the requests: half an interval of margin for a
    loaded machine, against a keep-alive that would ping every check (a 30 ms period)."""
    rec = _Recorder()
    with FakeProxy(rec) as port, sync.Client(port=port, timeout=1.0, keepalive=0.3) as kvp:
        kvp.read("A")
        last_read = rec.names("A")[-1]
        assert _poll(lambda: len(rec.names("PING")) >= 2)
        pings = rec.names("PING")
        assert pings[0] - last_read >= 0.15  # only once the connection was idle that long
        assert all(b - a >= 0.15 for a, b in itertools.pairwise(pings))
        assert kvp.connected and kvp.stats.count >= 3


def test_keepalive_survives_a_ping_that_times_out() -> None:
    rec = _Recorder(ignore_first_ping=True)
    with FakeProxy(rec) as port, sync.Client(port=port, timeout=0.1, keepalive=0.1) as kvp:
        kvp.read("A")
        assert _poll(lambda: len(rec.names("PING")) >= 3)  # the thread kept going
        assert kvp.read("B", timeout=1.0) == "v:B"


@pytest.mark.parametrize("id_policy", ["auto", "strict"])
def test_keepalive_of_an_unused_connection_and_close(id_policy: Any) -> None:
    """An unused connection is kept alive (with or without the id probe at connect); close()
    fails it with its reason, closes the socket and ends the daemon keep-alive thread."""
    rec = _Recorder()
    with FakeProxy(rec) as port:
        kvp = sync.Client(port=port, timeout=1.0, keepalive=0.05, id_policy=id_policy)
        kvp.connect()
        assert _poll(lambda: len(rec.names("PING")) >= 1)
        name = f"kvp-keepalive 127.0.0.1:{port}"
        (thread,) = [t for t in threading.enumerate() if t.name == name]
        assert thread.daemon  # never keeps a script from exiting
        conn = kvp.connection
        assert conn is not None and conn._sock is not None
        kvp.close()
        assert conn.closed_reason == f"connection to 127.0.0.1:{port} closed"
        assert not conn.is_open and conn._sock.fileno() == -1
        thread.join(2.0)
        assert not thread.is_alive()
        count = len(rec.seen)
        time.sleep(0.2)
        assert len(rec.seen) == count


def test_keepalive_goes_on_after_a_call_held_the_connection() -> None:
    """While a call holds the connection the keep-alive skips its checks; it must not give
    up: pings resume once the connection is idle again."""
    rec = _Recorder()

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "SLOW":
            await asyncio.sleep(0.3)  # many of the keep-alive's 10 ms checks find it busy
        await rec(req, w, n)

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=2.0, keepalive=0.1) as kvp:
        assert kvp.read("SLOW") == "v:SLOW"
        n = len(rec.names("PING"))
        assert _poll(lambda: len(rec.names("PING")) >= n + 2)


@pytest.mark.parametrize(
    ("pong", "first", "later"),
    [(b"PONG", ["PING"], ["PING"]), (b"", ["PING", "$OV_PRO"], ["$OV_PRO"])],
    ids=["kvp 9.0", "old proxy"],
)
def test_ping_is_ping_or_ov_pro_on_an_old_proxy(
    pong: bytes, first: list[str], later: list[str]
) -> None:
    rec = _Recorder(pong)
    with FakeProxy(rec) as port, sync.Client(port=port, timeout=1.0, keepalive=None) as kvp:
        kvp.read("A")
        n = len(rec.seen)
        rtt = kvp.ping()
        assert 0 < rtt < 1.0
        assert [name for _, name in rec.seen[n:]] == first
        n = len(rec.seen)
        kvp.ping()
        assert [name for _, name in rec.seen[n:]] == later


# --------------------------------------------------------------------------- pipelining


def test_an_oversized_request_in_a_burst_is_refused_before_anything_is_sent() -> None:
    rec = _Recorder()
    with FakeProxy(rec) as port, sync.Client(port=port, timeout=1.0) as kvp:
        kvp.read("A")
        n = len(rec.seen)
        with pytest.raises(ProtocolError, match=r"request for 'BIG' is \d+ bytes"):
            kvp.write_many([("B", "1"), ("BIG", '"' + "x" * 2100 + '"'), ("C", "2")])
        assert kvp.read("D") == "v:D"
        assert [name for _, name in rec.seen[n:]] == ["D"]  # neither B nor C was written


def test_a_burst_never_has_more_in_flight_than_allowed() -> None:
    batches: list[list[str]] = []

    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        batches.append([r.name for r in reqs])
        await asyncio.sleep(0.01)  # let the client's next requests queue up behind
        w.write(b"".join(answer(r) for r in reqs))

    with (
        FakeProxy(on_read=on_read) as port,
        sync.Client(port=port, timeout=2.0, max_in_flight=2, id_policy="strict") as kvp,
    ):
        names = [f"N{i}" for i in range(7)]
        res = kvp.read_many(names)
        assert [res[n].text for n in names] == [f"v:{n}" for n in names]
        assert sum(len(b) for b in batches) == 7
        assert max(len(b) for b in batches) <= 2
        assert kvp.stats.count == 7


def test_a_connection_lost_in_a_burst_fails_the_whole_call() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "CUT":
            w.close()
            return
        w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=1.0) as kvp:
        with pytest.raises(KvpConnectionError, match="closed the connection"):
            kvp.read_many(["A", "CUT", "C"])
        assert not kvp.connected


def test_a_burst_without_room_names_what_was_never_sent() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if not req.name.startswith("Q"):
            w.write(answer(req))

    with (
        FakeProxy(handler) as port,
        sync.Client(port=port, timeout=5.0, max_in_flight=2, id_policy="strict") as kvp,
    ):
        res = kvp.read_many(["Q1", "Q2", "Q3", "Q4"], timeout=0.2)
        errors = [str(res[n].error) for n in ("Q1", "Q2", "Q3", "Q4")]
        endpoint = f"127.0.0.1:{port}"
        assert errors == [
            f"no reply for 'Q1' from {endpoint} within 0.2 s",
            f"no reply for 'Q2' from {endpoint} within 0.2 s",
            f"no room to send 'Q3' to {endpoint} within 0.2 s",
            f"no room to send 'Q4' to {endpoint} within 0.2 s",
        ]
        assert kvp.connected


def test_connecting_to_a_closed_port_is_a_connection_error() -> None:
    with socket.create_server(("127.0.0.1", 0)) as probe:
        port = probe.getsockname()[1]
    with pytest.raises(KvpConnectionError, match=f"cannot connect to 127.0.0.1:{port}"):
        sync.Client(port=port, connect_timeout=1.0).connect()


def test_a_reply_with_another_mode_on_the_idle_path_is_a_protocol_error() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "W":  # a write answered as a read
            w.write(encode_reply(Reply(req.msg_id, Mode.READ, req.value or b"", 1)))
        else:
            w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=1.0) as kvp:
        assert kvp.write("OK", "1") == "1"
        with pytest.raises(KvpConnectionError, match="has mode 0, but the request for 'W'"):
            kvp.write("W", "1")
        assert not kvp.connected


def test_a_read_too_large_to_send_is_refused_with_the_reason() -> None:
    rec = _Recorder()
    with FakeProxy(rec) as port, sync.Client(port=port, timeout=1.0) as kvp:
        kvp.read("A")
        n = len(rec.seen)
        with pytest.raises(ProtocolError, match=r"request for 'X+' is \d+ bytes"):
            kvp.read("X" * 2100)
        assert len(rec.seen) == n and kvp.read("B") == "v:B"


def test_the_first_request_waits_while_the_id_probe_fills_the_byte_window() -> None:
    """pipeline_bytes=30: the probe's two reads (26 bytes) leave no room for a 9-byte read,
    which waits for their replies instead of being sent behind them."""
    batches: list[list[str]] = []

    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        batches.append([r.name for r in reqs])
        await asyncio.sleep(0.05)
        w.write(b"".join(answer(r) for r in reqs))

    with (
        FakeProxy(on_read=on_read) as port,
        sync.Client(port=port, timeout=2.0, pipeline_bytes=30) as kvp,
    ):
        assert kvp.read("A") == "v:A"
        assert batches == [["$OV_PRO", "$OV_PRO"], ["A"]]


def test_the_read_cache_stays_bounded_with_many_names() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        w.write(answer(req, b'"text"'))  # a string: its shape is a prefix, cached per name

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=2.0) as kvp:
        kvp.read("A")  # the id probe answered: every read below takes the idle path
        names = [f"S{i}" for i in range(300)]
        for name in names:
            assert kvp.read(name) == '"text"'
        conn = kvp.connection
        assert conn is not None and len(conn._reads) == 256
        assert all(e[1] == b'"' for name, e in conn._reads.items() if name != "A")


def test_a_late_reply_is_discarded_and_not_counted_as_an_access_time() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name.startswith("LATE"):
            await asyncio.sleep(0.15)
        w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=2.0) as kvp:
        kvp.read("A")
        kvp.stats.reset()
        with pytest.raises(KvpTimeoutError):
            kvp.read("LATE1", timeout=0.05)
        res = kvp.read_many(["B", "LATE2"], timeout=0.05)
        assert res["B"].text is None or res["B"].text == "v:B"
        assert kvp.read("C", timeout=2.0) == "v:C"  # behind both late replies
        assert kvp.read("D", timeout=2.0) == "v:D"
        answered = 3 if res["B"].ok else 2
        assert kvp.stats.count == answered  # never LATE1's or LATE2's
        assert 0 < kvp.stats.maximum < 1.0


def test_access_times_of_the_idle_paths_are_round_trips() -> None:
    with FakeProxy(lambda req, w, n: _write(w, answer(req))) as port:
        with sync.Client(port=port, timeout=2.0) as kvp:
            kvp.read("A")
            kvp.stats.reset()
            kvp.read("B")  # the read's text path
            kvp.write("C", "1")  # a write: the idle path's whole-reply check
            assert kvp.stats.count == 2
            assert 0 < kvp.stats.minimum <= kvp.stats.maximum < 1.0


def test_a_legacy_proxy_may_repeat_the_last_reply_id_after_any_idle_path() -> None:
    """A pre-9.0 proxy labels replies with the first id of a socket read; in legacy mode a
    reply that repeats the previous reply's id is matched in order. The idle paths must leave
    that label behind like the general path: after a read's first value (its shape learnt),
    a read taken by its known prefix, and a write."""

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name.startswith("DUP"):
            w.write(encode_reply(Reply((req.msg_id - 1) & 0xFFFF, req.mode, b"v:DUP", 1)))
        elif req.name == "AX":
            w.write(answer(req, b"{E6AXIS: A1 1.0}"))
        else:
            w.write(answer(req))

    with (
        FakeProxy(handler) as port,
        sync.Client(port=port, timeout=1.0, id_policy="legacy") as kvp,
    ):
        assert kvp.read("AX") == "{E6AXIS: A1 1.0}"  # learns the shape
        assert kvp.read("DUP1") == "v:DUP"
        assert kvp.read("AX") == "{E6AXIS: A1 1.0}"  # by its prefix
        assert kvp.read("DUP2") == "v:DUP"
        assert kvp.write("W", "1") == "1"
        assert kvp.read("DUP3") == "v:DUP"
        assert kvp.connection is not None and kvp.connection.mislabeled_replies == 3
        assert kvp.connected


@pytest.mark.parametrize("part_sent", [True, False], ids=["part sent", "nothing sent"])
def test_a_stall_in_a_burst_is_retried_only_when_nothing_was_sent(part_sent: bool) -> None:
    """Two reads time out and keep their places; the oldest then waited longer than its
    timeout. A burst that finds no room is a stall: retried on a new connection when none of
    it went out, raised when part of it did (retrying could send it twice)."""

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if not req.name.startswith("S"):
            w.write(answer(req))

    window = 3 if part_sent else 2  # with 3, B fits and goes out before C finds no room
    kw: dict[str, Any] = {"timeout": 0.05, "max_in_flight": window, "auto_reconnect": True}
    with FakeProxy(handler) as port, sync.Client(port=port, **kw) as kvp:
        kvp.read("A")  # idle: S0 goes out on the idle path and is queued when it times out
        for i in range(2):
            with pytest.raises(KvpTimeoutError):
                kvp.read(f"S{i}")
        time.sleep(0.06)
        if part_sent:
            stalled = r"stopped answering.*the next call reconnects"
            with pytest.raises(KvpStalledError, match=stalled):
                kvp.read_many(["B", "C"])
            assert kvp.reconnects == 0 and not kvp.connected
        else:
            res = kvp.read_many(["B", "C"], timeout=1.0)
            assert [res[n].text for n in ("B", "C")] == ["v:B", "v:C"]
            assert kvp.reconnects == 1


def test_a_write_too_large_to_send_is_refused_with_the_reason() -> None:
    with FakeProxy(lambda req, w, n: _write(w, answer(req))) as port:
        with sync.Client(port=port, timeout=1.0) as kvp:
            kvp.read("A")
            with pytest.raises(ProtocolError, match=r"request for 'BIG' is \d+ bytes"):
                kvp.write("BIG", '"' + "x" * 2100 + '"')
            assert kvp.read("B") == "v:B"


def test_a_request_the_proxy_dropped_is_named_as_never_answered() -> None:
    """KVP drops a request it gets while busy; the reply to a later one proves it."""

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name != "DROPPED":
            w.write(answer(req))

    with (
        FakeProxy(handler) as port,
        sync.Client(port=port, timeout=1.0, id_policy="strict") as kvp,
    ):
        res = kvp.read_many(["A", "DROPPED", "C"])
        assert res["A"].text == "v:A" and res["C"].text == "v:C"
        error = res["DROPPED"].error
        assert isinstance(error, KvpTimeoutError)
        assert str(error) == f"127.0.0.1:{port} never answered the request for 'DROPPED'"
        assert kvp.connected and kvp.connection is not None
        assert kvp.connection.dropped_requests == 1


def test_a_reset_while_waiting_fails_the_call_with_the_reason() -> None:
    """The proxy resets the connection once it has the id probe and the first read: the read,
    waiting on the general path, fails as a lost connection, not as a timeout."""
    srv = socket.create_server(("127.0.0.1", 0))
    port = srv.getsockname()[1]

    def serve() -> None:
        conn, _ = srv.accept()
        with conn:
            got = b""
            while len(got) < 2 * 13 + 9:  # two reads of $OV_PRO, one of "A"
                chunk = conn.recv(4096)
                if not chunk:
                    return
                got += chunk
            conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        with sync.Client(port=port, timeout=2.0) as kvp:
            with pytest.raises(KvpConnectionError, match=f"127.0.0.1:{port} closed the connection"):
                kvp.read("A")
            assert not kvp.connected
    finally:
        srv.close()
        thread.join(5.0)


@pytest.mark.parametrize("head", [9, 1])
def test_a_value_smuggled_in_the_tail_of_a_cut_reply_is_never_taken(head: int) -> None:
    """A proxy sends a reply together with the head of a reply to nothing; the rest, sent
    after the next request, is shaped like a whole reply to that request. With bytes of a
    frame buffered the connection is not idle: the next request goes through the decoder,
    which completes the reply to nothing and drops the connection, never the fast path,
    which would take the tail for the next value."""
    rest: list[bytes] = []

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "CUT":
            inner = encode_reply(Reply((req.msg_id + 1) & 0xFFFF, Mode.READ, b"v:EVIL"))
            if head == 9:  # the head of a reply to nothing, whose tail is a whole reply
                stray = encode_reply(Reply(0x7777, Mode.READ, b"xx" + inner[:-3]))
            else:  # one byte, then a whole reply: together no reply to this client
                stray = b"\x00" + inner
            assert stray[head:] == inner
            w.write(answer(req) + stray[:head])
            rest.append(stray[head:])
        elif rest:
            w.write(rest.pop())
            await w.drain()
            await asyncio.sleep(0.05)
            w.write(answer(req))
        else:
            w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=0.3) as kvp:
        kvp.read("A")
        assert kvp.read("CUT") == "v:CUT"
        if head == 9:
            with pytest.raises(KvpConnectionError, match="reply with id 30583 answers no request"):
                kvp.read("NEXT")
            assert not kvp.connected
        else:  # the decoder waits for the rest of a frame that never comes whole
            with pytest.raises((KvpConnectionError, KvpTimeoutError)):
                kvp.read("NEXT")


@pytest.mark.parametrize(
    ("code", "error"),
    [(b"\x00\x00", UnknownVariableError), (b"\x00\x01", ReadFailedError)],
    ids=["c3 general failure", "kvp failure"],
)
def test_the_code_of_a_failed_reply_on_the_idle_path_decides_the_error(
    code: bytes, error: type[Exception]
) -> None:
    """C3 Bridge answers a name it cannot show with the code ``00 00`` (an unknown variable);
    any other failed read is a failed read. The idle path reads the code from its two bytes."""

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "F":
            w.write(encode_reply(Reply(req.msg_id, Mode.READ, b"", 0, code)))
        else:
            w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=1.0) as kvp:
        kvp.read("A")
        with pytest.raises(error) as info:
            kvp.read("F")
        assert type(info.value) is error
        assert kvp.read("B") == "v:B"


@pytest.mark.parametrize("old_proxy", [False, True], ids=["ping", "ov_pro"])
def test_ping_keeps_its_timeout(old_proxy: bool) -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "PING" and old_proxy:
            w.write(answer(req, b""))  # an old proxy: PING is an unknown variable
        elif req.name not in ("PING", "$OV_PRO") or n <= 2:  # n <= 2: the id probe
            w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=5.0) as kvp:
        kvp.read("A")
        t0 = time.monotonic()
        name = "$OV_PRO" if old_proxy else "PING"
        with pytest.raises(KvpTimeoutError, match=re.escape(f"no reply for '{name}'")):
            kvp.ping(timeout=0.1)
        assert time.monotonic() - t0 < 2.5


def test_a_well_formed_reply_of_another_message_type_is_a_protocol_error() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "X":
            w.write(encode_reply(Reply(req.msg_id, 4, b"v:X", 1)))
        else:
            w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=1.0) as kvp:
        kvp.read("A")
        with pytest.raises(
            KvpConnectionError, match="has mode 4, but the request for 'X' had mode 0"
        ):
            kvp.read("X")
        assert not kvp.connected
