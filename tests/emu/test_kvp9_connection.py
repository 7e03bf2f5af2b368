"""``--wire kvp9``'s connection over real TCP: what it counts, how it serves a read on either
path (at once and parked, or in the worker behind latency and faults), and how it ends.

The parsing itself is :mod:`kukavarproxy_emu.kvp9`'s (``test_kvp9_rules.py``, the wire table);
these tests are about the socket around it. "Fast" is the path without latency or faults,
"worker" the one with faults armed (a fault that never matches) or a latency profile.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import struct
import time
from typing import Any

import pytest

from kukavarproxy_emu import Emulator, Fault
from kukavarproxy_emu.kvp9_connection import Kvp9Connection, Kvp9ConnectionInfo
from kukavarproxy_emu.latency import LatencyProfile, ServiceTime
from kukavarproxy_emu.testing import EmulatorFactory, RawClient, wait_until
from pyopenshowvar.protocol import encode_read, encode_write

H = bytes.fromhex
#: armed but never matching: the replies take the worker path, unchanged
NEVER = (Fault("drop", nth=10**9),)


def a100(msg_id: int) -> bytes:
    """The reply to a read of $OV_PRO (100)."""
    return msg_id.to_bytes(2, "big") + H("0009 00 0003 313030 000101")


async def kvp9(factory: EmulatorFactory, path: str = "fast", **kw: Any) -> Emulator:
    faults = NEVER if path == "worker" else ()
    return await factory(wire="kvp9", robot=False, faults=kw.pop("faults", faults), **kw)


def connection(emu: Emulator) -> Kvp9Connection:
    conn = emu._connections[max(emu._connections)]
    assert isinstance(conn, Kvp9Connection)
    return conn


def idle_info(c: RawClient, **counters: int) -> Kvp9ConnectionInfo:
    """What ``info()`` says of the emulator's first connection, ``c``, with nothing in progress
    (``counters``: those not zero)."""
    port = c.writer.get_extra_info("sockname")[1]
    return Kvp9ConnectionInfo(
        index=1,
        peer=f"127.0.0.1:{port}",
        received=counters.pop("received", 0),
        buffered=0,
        pending=0,
        write_buffer=0,
        reading_paused=False,
        **counters,
    )


async def read_all(c: RawClient, timeout: float = 5.0) -> bytes:
    """Everything until the server closes; a reset ends it too."""
    data = b""
    async with asyncio.timeout(timeout):
        while True:
            try:
                more = await c.reader.read(65536)
            except ConnectionError:
                return data
            if not more:
                return data
            data += more


@pytest.mark.parametrize("path", ["fast", "worker"])
async def test_every_read_is_counted(emulator_factory: EmulatorFactory, path: str) -> None:
    emu = await kvp9(emulator_factory, path)
    async with await RawClient.connect(emu.host, emu.port) as c:
        assert await c.request(encode_read(1, "$OV_PRO")) == a100(1)
        await c.send(b"".join(encode_read(i, "$OV_PRO") for i in (2, 3, 4)))  # one read
        assert [await c.read_frame() for _ in range(3)] == [a100(2), a100(3), a100(4)]
        await c.send(H("000100"))  # three bytes: the read ends in errRead, nothing answered
        await wait_until(lambda: emu.stats.protocol_errors == 1, what="the errRead counted")
        await c.send(H("000100"))
        await wait_until(lambda: emu.stats.protocol_errors == 2, what="another errRead")
        await wait_until(lambda: not connection(emu).info().reading_paused, what="reading")
        (info,) = emu.connections()
        assert info == idle_info(
            c, received=4, reads=4, bytes_read=14 + 42 + 3 + 3, largest_read=42, most_messages=3
        )
        assert emu.stats.requests == 4 and emu.stats.clients == 1
        assert (await c.request(encode_read(5, "$OV_PRO")))[:2] == H("0005")  # still served
    await wait_until(lambda: emu.stats.clients == 0, what="the slot freed")


@pytest.mark.parametrize("path", ["fast", "worker"])
async def test_bytes_beyond_ascii_pass_unchanged(
    emulator_factory: EmulatorFactory, path: str
) -> None:
    """KVP's strings are bytes (a single-byte code page): a name or value byte 0xE9 is one byte
    both ways, as CrossComm has it."""
    emu = await kvp9(emulator_factory, path)
    async with await RawClient.connect(emu.host, emu.port) as c:
        echo = await c.request(encode_write(1, "MYSTRING[]", b'"caf\xe9"'))
        assert echo == H("0001 000C 01 0006") + b'"caf\xe9"' + H("000101")
        assert await c.request(encode_read(2, "MYSTRING[]")) == H("0002 000C 00 0006") + (
            b'"caf\xe9"' + H("000101")
        )
        assert emu.store.read("MYSTRING[]") == '"caf\xe9"'
        # an unknown name (with a byte beyond ASCII): CrossComm's empty answer, a success
        assert await c.request(encode_read(3, b"N\xe9")) == H("0003 0006 00 0000 000101")


@pytest.mark.parametrize("path", ["fast", "worker"])
async def test_an_emulator_fault_closes_only_that_client(
    emulator_factory: EmulatorFactory,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
    path: str,
) -> None:
    """A bug of the emulator itself (planted: a variable whose read raises) ends that client's
    connection, logged with its traceback; the fast path sends nothing of that read, the worker
    what it had sent before; other clients go on."""
    emu = await kvp9(emulator_factory, path)
    show = emu.responder.show_var

    def planted(name: str) -> str | None:
        if name == "BOOM":
            raise RuntimeError("planted")
        return show(name)

    monkeypatch.setattr(emu.responder, "show_var", planted)
    async with (
        await RawClient.connect(emu.host, emu.port) as victim,
        await RawClient.connect(emu.host, emu.port) as other,
    ):
        assert (await other.request(encode_read(9, "$OV_PRO"))) == a100(9)
        with caplog.at_level(logging.ERROR, "kukavarproxy_emu.kvp9_connection"):
            await victim.send(encode_read(1, "$OV_PRO") + encode_read(2, "BOOM"))
            data = await read_all(victim)
        assert data == (b"" if path == "fast" else a100(1))
        assert (await other.request(encode_read(10, "$OV_PRO"))) == a100(10)
        await wait_until(lambda: emu.stats.clients == 1, what="the victim's slot freed")
    (record,) = [r for r in caplog.records if "internal error" in r.getMessage()]
    assert record.exc_info is not None and str(record.exc_info[1]) == "planted"


@pytest.mark.parametrize("budget", ["parked", "at once"])
async def test_eof_closes_after_the_reads_before_it(
    emulator_factory: EmulatorFactory, monkeypatch: pytest.MonkeyPatch, budget: str
) -> None:
    """KVP drops a client in its Disconnect event, after the reads before it were served: a
    read parked between slices is finished first, and an idle connection closes at once."""
    from kukavarproxy_emu import kvp9_connection, server

    if budget == "parked":  # one step per slice: the read parks after every request
        monkeypatch.setattr(kvp9_connection, "IMMEDIATE", 0.0)
        monkeypatch.setattr(server, "SLICE", 0.0)
        monkeypatch.setattr(server, "ROUND", 0.0)
    emu = await kvp9(emulator_factory)
    async with await RawClient.connect(emu.host, emu.port) as c:
        await c.send(b"".join(encode_read(i, "$OV_PRO") for i in range(1, 9)))
        c.writer.write_eof()
        assert await read_all(c) == b"".join(a100(i) for i in range(1, 9))
    async with await RawClient.connect(emu.host, emu.port) as c:
        c.writer.write_eof()  # nothing in progress
        assert await c.is_closed_by_peer(timeout=5)


async def test_a_dropped_client_takes_its_worker_with_it(emulator_factory: EmulatorFactory) -> None:
    """The idle timer drops a client whose read waits 5 s for CrossComm (the proxy reads nothing
    meanwhile, so that client cannot even be seen leaving): the read is abandoned, its slot
    free at once and its reply never computed."""
    emu = await kvp9(emulator_factory, latency="fixed:5", idle_timeout=0.2)
    async with await RawClient.connect(emu.host, emu.port) as c:
        await c.send(encode_read(1, "$OV_PRO"))
        conn = connection(emu)
        await wait_until(lambda: conn.worker is not None, what="the worker serving the read")
        assert conn.info().reading_paused  # the proxy reads nothing while it serves a read
        assert await c.is_closed_by_peer(timeout=3)
    await wait_until(lambda: conn.worker is None, timeout=3, what="the worker cancelled")
    assert emu.stats.idle_drops == 1 and emu.stats.clients == 0
    assert emu.stats.requests == 0 and conn.replies == 0


@pytest.mark.parametrize("kind", ["read", "write"])
async def test_each_request_waits_the_service_time_of_its_kind(
    emulator_factory: EmulatorFactory, kind: str
) -> None:
    """Reads and writes queue for CrossComm with their own service time (here only ``kind``
    takes 0.3 s, the other none)."""
    slow, none = ServiceTime(floor=0.3, median=0.0), ServiceTime(floor=0.0, median=0.0)
    profile = LatencyProfile("test", read=slow if kind == "read" else none, write=none)
    if kind == "write":
        profile = LatencyProfile("test", read=none, write=slow)
    emu = await kvp9(emulator_factory, latency=profile)
    request = encode_read(1, "$OV_PRO") if kind == "read" else encode_write(1, "$OV_PRO", "55")
    async with await RawClient.connect(emu.host, emu.port) as c:
        start = time.monotonic()
        reply = await c.request(request, timeout=5)
        assert time.monotonic() - start >= 0.29
    assert reply[:2] == H("0001") and reply[4] == (0 if kind == "read" else 1)


async def test_replies_after_a_fault_closed_the_socket_are_computed_not_sent(
    emulator_factory: EmulatorFactory,
) -> None:
    """A fault that closes the connection in the middle of reply 2: the rest of that read is
    still walked (its write applies, as VB's loop goes on after a failed Write), unsent."""
    emu = await kvp9(emulator_factory, faults=(Fault("close", nth=2),))
    async with await RawClient.connect(emu.host, emu.port) as c:
        await c.send(
            encode_read(1, "$OV_PRO") + encode_read(2, "$OV_PRO") + encode_write(3, "$OV_PRO", "7")
        )
        data = await read_all(c)
    assert data == a100(1) + a100(2)[:6]  # the fault writes half of reply 2, then closes
    await wait_until(lambda: emu.stats.requests == 3, what="all three replies computed")
    assert emu.store.read("$OV_PRO") == "7"


async def test_only_the_faulted_connections_nth_reply_is_hit(
    emulator_factory: EmulatorFactory,
) -> None:
    """Faults count each connection's replies from 1 and may name the connection."""
    emu = await kvp9(emulator_factory, faults=(Fault("drop", nth=2, connection=2, count=None),))
    async with (
        await RawClient.connect(emu.host, emu.port) as first,
        await RawClient.connect(emu.host, emu.port) as second,
    ):
        for c in (first, second):
            await c.send(b"".join(encode_read(i, "$OV_PRO") for i in (1, 2, 3)))
        assert [await first.read_frame() for _ in range(3)] == [a100(1), a100(2), a100(3)]
        assert [await second.read_frame() for _ in range(2)] == [a100(1), a100(3)]


async def test_a_big_read_is_written_every_16_kib(
    emulator_factory: EmulatorFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The fast path coalesces a read's replies, but writes them once they pass FLUSH_SIZE
    (so the send limit is checked while a read answers a lot): 10 replies of 2512 bytes in one
    read go out as two writes, the first once the 7th passes 16 KiB; 8 replies of 2048 bytes
    are exactly 16 KiB, not past it, so 9 of them go out in one write."""
    from kukavarproxy_emu import kvp9_connection

    monkeypatch.setattr(kvp9_connection, "IMMEDIATE", 60.0)  # each read in one go
    emu = await kvp9(emulator_factory, dat_text="DECL CHAR BIG[2600]\nDECL CHAR MID[2600]\n")
    emu.store.write("BIG[]", '"' + "X" * 2500 + '"')  # a reply of 10 + 2502 bytes
    emu.store.write("MID[]", '"' + "X" * 2036 + '"')  # 10 + 2038 = 2048
    writes: list[int] = []
    original = Kvp9Connection.write

    def logged(self: Kvp9Connection, data: bytes) -> None:
        writes.append(len(data))
        original(self, data)

    monkeypatch.setattr(Kvp9Connection, "write", logged)
    serve = Kvp9Connection.serve
    served: list[float] = []

    def counted(self: Kvp9Connection, budget: float) -> None:
        served.append(budget)
        serve(self, budget)

    monkeypatch.setattr(Kvp9Connection, "serve", counted)
    async with await RawClient.connect(emu.host, emu.port) as c:
        assert connection(emu).info() == idle_info(c)  # nothing read yet: all zero
        for batch in ("MID[]", "BIG[]", "MID[]"):  # the count starts from 0 at every read
            await c.send(
                b"".join(encode_read(i, batch) for i in range(10 if batch == "BIG[]" else 9))
            )
            if batch == "BIG[]":
                assert [len(await c.read_frame()) for _ in range(10)] == [2512] * 10
            else:
                assert [len(await c.read_frame()) for _ in range(9)] == [2048] * 9
    # 7 * 2512 > 16384 >= 6 * 2512
    assert writes == [9 * 2048, 7 * 2512, 3 * 2512, 9 * 2048]
    assert served == []  # within the immediate budget: each read answered at once, never parked


@pytest.mark.parametrize("what", ["elements of one write", "replies without CrossComm"])
async def test_a_read_pauses_between_any_two_steps(
    emulator_factory: EmulatorFactory, monkeypatch: pytest.MonkeyPatch, what: str
) -> None:
    """With no time budget a read does one step per round: a CrossComm call or a reply. Both
    kinds of work that one request can multiply are spread over event-loop iterations: the
    300 element writes of one mode-3 request, and the 300 replies of unknown-mode requests
    (each nests the previous reply, no CrossComm call between them)."""
    from kukavarproxy_emu import kvp9_connection, server

    monkeypatch.setattr(kvp9_connection, "IMMEDIATE", 0.0)
    monkeypatch.setattr(server, "SLICE", 0.0)
    monkeypatch.setattr(server, "ROUND", 0.0)
    emu = await kvp9(emulator_factory, dat_text="DECL INT WA[300]\n")
    tick = [0]
    seen: list[int] = []  # the loop iteration of every element write, or of every socket write
    pending: list[int] = []  # reads parked or waiting, as info() tells, at every element write
    if what == "elements of one write":
        set_var = emu.responder.set_var

        def counted_set(name: str, value: str) -> bool:
            seen.append(tick[0])
            pending.append(connection(emu).info().pending)
            return set_var(name, value)

        monkeypatch.setattr(emu.responder, "set_var", counted_set)
        payload = b"".join(i.to_bytes(2, "big") for i in range(1, 301))
        body = b"\x03" + H("0004") + b"WA[]" + len(payload).to_bytes(2, "big") + payload
        chunk = H("0001") + len(body).to_bytes(2, "big") + body
        replies = 1
    else:
        write = Kvp9Connection.write

        def counted_write(self: Kvp9Connection, data: bytes) -> None:
            seen.append(tick[0])
            write(self, data)

        monkeypatch.setattr(Kvp9Connection, "write", counted_write)
        chunk = encode_read(1, "$OV_PRO") + H("0002 0001 07") * 300
        replies = 301

    async def ticker() -> None:
        while True:
            await asyncio.sleep(0)
            tick[0] += 1

    counting = asyncio.create_task(ticker())
    try:
        async with await RawClient.connect(emu.host, emu.port) as c:
            await c.send(chunk)
            for _ in range(replies):
                await c.read_frame(timeout=10)
            assert await c.request(encode_read(9, "$OV_PRO")) == a100(9)  # reading again
    finally:
        counting.cancel()
    if what == "elements of one write":
        assert len(seen) == 300 and emu.store.get("WA[300]") == 300
        assert set(pending[1:]) == {1}  # the read parked: one pending
    assert len(set(seen)) >= 100, seen  # not all in one go


@pytest.mark.parametrize("quirks", [False, True], ids=["9.0", "quirks"])
@pytest.mark.parametrize("path", ["fast", "worker"])
async def test_ping_and_ids_on_either_path(
    emulator_factory: EmulatorFactory, path: str, quirks: bool
) -> None:
    """KVP 9.0 answers PING itself and gives each reply its request's id; the ``no-ping``
    quirk (before 9.0: PING is a variable like any other, unknown, an empty answer) and the
    ``legacy-ids`` one (every reply of a read carries its first id) hold on both paths."""
    extra = {"quirks": frozenset({"no-ping", "legacy-ids"})} if quirks else {}
    emu = await kvp9(emulator_factory, path, **extra)
    async with await RawClient.connect(emu.host, emu.port) as c:
        await c.send(encode_read(1, "PING") + encode_read(2, "$OV_PRO"))
        if quirks:
            assert await c.read_frame() == H("0001 0006 00 0000 000101")
            assert await c.read_frame() == a100(1)
        else:
            assert await c.read_frame() == H("0001 000A 00 0004 504F4E47 000101")
            assert await c.read_frame() == a100(2)


async def test_a_dropped_client_that_does_not_read_is_cut_at_once(
    emulator_factory: EmulatorFactory,
) -> None:
    """A client that asked for 48 KB of replies and reads none (tiny socket buffers on both
    ends) goes idle: the idle timer drops it at once, the replies waiting in user space
    discarded, rather than waiting for a flush that never comes."""
    emu = await kvp9(emulator_factory, idle_timeout=0.3)
    with socket.socket() as sock:  # a plain socket nobody reads from
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect((emu.host, emu.port))
        await wait_until(lambda: emu.stats.clients == 1, what="connected")
        conn = connection(emu)
        assert conn.transport is not None
        conn.transport.get_extra_info("socket").setsockopt(
            socket.SOL_SOCKET, socket.SO_SNDBUF, 4096
        )
        sock.sendall(encode_read(2, "$IN[]") + encode_read(3, "$IN[]"))
        await wait_until(lambda: conn.info().write_buffer > 0, what="replies waiting")
        await wait_until(lambda: emu.stats.idle_drops == 1, what="the idle drop")
        await wait_until(lambda: emu.stats.clients == 0, timeout=3, what="the slot freed")


async def test_a_parked_read_goes_on_for_its_rounds_budget(
    emulator_factory: EmulatorFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A read parked at once (no immediate budget) continues in the emulator's next round for
    that round's whole budget: with a round of 5 s, 100 reads are done in that one round."""
    from kukavarproxy_emu import kvp9_connection, server

    monkeypatch.setattr(kvp9_connection, "IMMEDIATE", 0.0)
    monkeypatch.setattr(server, "SLICE", 5.0)
    monkeypatch.setattr(server, "ROUND", 5.0)
    emu = await kvp9(emulator_factory)
    served: list[float] = []
    original = Kvp9Connection.serve

    def counted(self: Kvp9Connection, budget: float) -> None:
        served.append(budget)
        original(self, budget)

    monkeypatch.setattr(Kvp9Connection, "serve", counted)
    async with await RawClient.connect(emu.host, emu.port) as c:
        await c.send(b"".join(encode_read(i, "$OV_PRO") for i in range(100)))
        assert [await c.read_frame() for _ in range(100)] == [a100(i) for i in range(100)]
    assert len(served) == 1 and served[0] > 4.0


async def test_text_outside_the_code_page_is_answered_as_question_marks(
    emulator_factory: EmulatorFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    """KVP's replies are single-byte ANSI: a character the code page lacks goes out as ``?``,
    as in the robust mode (planted: a variable whose text holds one)."""
    emu = await kvp9(emulator_factory)
    show = emu.responder.show_var
    monkeypatch.setattr(
        emu.responder, "show_var", lambda name: "\u20ac 5" if name == "EURO" else show(name)
    )
    async with await RawClient.connect(emu.host, emu.port) as c:
        assert await c.request(encode_read(1, "EURO")) == H("0001 0009 00 0003 3F2035 000101")


async def test_a_client_that_resets_during_a_long_read(
    emulator_factory: EmulatorFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A client that resets the connection while its long read is parked: the read is walked
    to its end all the same (as VB's loop goes on after a failed Write), its replies go
    nowhere, and nothing is written to the dead socket (asyncio would log that)."""
    from kukavarproxy_emu import kvp9_connection, server

    monkeypatch.setattr(kvp9_connection, "IMMEDIATE", 0.0)
    monkeypatch.setattr(server, "SLICE", 0.0)
    monkeypatch.setattr(server, "ROUND", 0.0)
    emu = await kvp9(emulator_factory)
    with socket.socket() as sock:
        sock.connect((emu.host, emu.port))
        await wait_until(lambda: emu.stats.clients == 1, what="connected")
        conn = connection(emu)
        sock.sendall(b"".join(encode_read(i, "$IN[]") for i in range(40)))
        await wait_until(  # every loop iteration: the read moves one step per round
            lambda: conn.replies > 0 and conn._parked is not None, interval=0, what="parked"
        )
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    await wait_until(lambda: conn.closed, what="the reset seen")
    await wait_until(lambda: conn._parked is None, timeout=10, what="the read walked to its end")
    assert conn.replies == 40 and emu.stats.clients == 0
