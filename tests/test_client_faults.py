"""Client fault tests against deliberately broken servers (the only place mocks are allowed).

Each server here is a real asyncio TCP server on 127.0.0.1 that misbehaves in one specific way:
drops a reply, splits frames, closes mid-frame, stalls, mislabels ids like a pre-9.0 proxy.
"""

from __future__ import annotations

import asyncio
import time

import pytest

from pyopenshowvar import (
    Client,
    KvpConnectionError,
    KvpTimeoutError,
    ReadFailedError,
    UnknownVariableError,
    WriteRefusedError,
)
from pyopenshowvar.protocol import Mode, Reply, Request, encode_reply
from pyopenshowvar.testing import FakeProxy, Handler, answer


def broken_server(handler: Handler) -> FakeProxy:
    return FakeProxy(handler)


async def test_dropped_reply_times_out_and_connection_stays_usable() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name != "$OV_RO":  # never answered
            w.write(answer(req))

    async with broken_server(handler) as port, Client(port=port, timeout=0.3) as kvp:
        t0 = time.monotonic()
        with pytest.raises(KvpTimeoutError) as info:
            await kvp.read("$OV_RO")
        assert 0.25 < time.monotonic() - t0 < 1.5
        assert "$OV_RO" in str(info.value) and str(port) in str(info.value)
        assert isinstance(info.value, TimeoutError)
        assert await kvp.read("$AXIS_ACT") == "v:$AXIS_ACT"


async def test_dropped_reply_is_detected_when_the_next_reply_arrives() -> None:
    # The server silently skips request 1 of a pipelined pair; the client must not hand
    # request 2's reply to request 1 and must fail request 1 without waiting for its timeout.
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "A":
            return
        await asyncio.sleep(0.01)
        w.write(answer(req))

    async with broken_server(handler) as port, Client(port=port, timeout=5.0) as kvp:
        t0 = time.monotonic()
        r1, r2 = await asyncio.gather(kvp.read("A"), kvp.read("B"), return_exceptions=True)
        assert isinstance(r1, KvpTimeoutError)
        assert r2 == "v:B"
        assert time.monotonic() - t0 < 1.0
        assert kvp.connection is not None and kvp.connection.dropped_requests == 1


async def test_late_reply_after_timeout_is_discarded() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "SLOW":
            await asyncio.sleep(0.4)  # stall: answer arrives after the client gave up
        w.write(answer(req))

    async with broken_server(handler) as port, Client(port=port, timeout=0.2) as kvp:
        with pytest.raises(KvpTimeoutError):
            await kvp.read("SLOW")
        # the next call must get its own answer, not the late one for SLOW
        assert await kvp.read("FAST", timeout=2.0) == "v:FAST"


async def test_split_frames_are_reassembled() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        frame = answer(req, b"{E6AXIS: A1 1.0, A2 2.0}" * 20)
        for i in range(len(frame)):
            w.write(frame[i : i + 1])
            await w.drain()
            if i % 50 == 0:
                await asyncio.sleep(0.001)

    async with broken_server(handler) as port, Client(port=port) as kvp:
        assert await kvp.read("$AXIS_ACT") == "{E6AXIS: A1 1.0, A2 2.0}" * 20


async def test_close_mid_frame_fails_every_pending_call_at_once() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "$OV_PRO":  # the id probe: ids are echoed, so the reads are pipelined
            w.write(answer(req))
        if req.name == "V2":
            w.write(answer(req)[:5])
            await w.drain()
            w.close()

    async with broken_server(handler) as port, Client(port=port, timeout=5.0) as kvp:
        t0 = time.monotonic()
        results = await asyncio.gather(
            *(kvp.read(f"V{i}") for i in range(5)), return_exceptions=True
        )
        assert all(isinstance(r, KvpConnectionError) for r in results)
        assert "middle of a reply" in str(results[0])
        assert time.monotonic() - t0 < 1.0
        with pytest.raises(KvpConnectionError):
            await kvp.read("AFTER")


async def test_auto_reconnect_after_drop() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "MYINT":
            w.close()
            return
        w.write(answer(req))

    async with broken_server(handler) as port, Client(port=port, auto_reconnect=True) as kvp:
        with pytest.raises(KvpConnectionError):
            await kvp.write("MYINT", "1")  # a write in flight is failed, never resent
        assert await kvp.read("X") == "v:X"
        assert kvp.reconnects == 1


async def test_legacy_proxy_ids_matched_in_order() -> None:
    # Pre-9.0 KVP: every reply to one socket read carries the id of that read's first request.
    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        await asyncio.sleep(0.005)  # let a batch pile up
        first = reqs[0].msg_id
        w.write(b"".join(encode_reply(Reply(first, r.mode, f"v:{r.name}".encode())) for r in reqs))

    async with FakeProxy(on_read=on_read) as port, Client(port=port) as kvp:
        names = [f"N{i}" for i in range(40)]
        results = await kvp.read_many(names)
        assert [r.text for r in results.values()] == [f"v:{n}" for n in names]
        assert kvp.connection is not None and kvp.connection.session.ids == "legacy"
        assert kvp.connection.mislabeled_replies >= 1

    # declared ids echoed: the first repeated id is a protocol error, never a value
    async with FakeProxy(on_read=on_read) as port, Client(port=port, id_policy="strict") as kvp:
        with pytest.raises(KvpConnectionError, match="repeats the previous reply's id"):
            await kvp.read_many(["N0", "N1", "N2", "N3"])
        assert not kvp.connected


async def test_status_and_empty_value_outcomes() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "UNKNOWN":
            w.write(answer(req, b""))
        elif req.name == "FAIL":
            w.write(answer(req, b"", status=0))
        elif req.mode == Mode.WRITE:
            w.write(answer(req, status=0))  # KVP echoes the value with a failure status
        else:
            w.write(answer(req))

    async with broken_server(handler) as port, Client(port=port) as kvp:
        with pytest.raises(UnknownVariableError) as unk:
            await kvp.read("UNKNOWN")
        assert isinstance(unk.value, LookupError) and "UNKNOWN" in str(unk.value)
        with pytest.raises(ReadFailedError):
            await kvp.read("FAIL")
        with pytest.raises(WriteRefusedError) as ref:
            await kvp.write("$AXIS_ACT", "{A1 1}")
        assert ref.value.value == "{A1 1}" and "$AXIS_ACT" in str(ref.value)
        res = await kvp.read_many(["A", "UNKNOWN", "B"])
        assert res["A"].text == "v:A" and res["B"].ok
        assert isinstance(res["UNKNOWN"].error, UnknownVariableError)


async def test_unknown_mode_four_byte_reply() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        w.write(encode_reply(Reply(req.msg_id, None)) if req.mode > 1 else answer(req))

    async with broken_server(handler) as port, Client(port=port) as kvp:
        with pytest.raises(ReadFailedError, match="mode"):
            await kvp.read_array_words("ARR[]")


async def test_stalled_server_keeps_every_call_bounded() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        await asyncio.sleep(10)

    async with broken_server(handler) as port, Client(port=port, timeout=0.2) as kvp:
        t0 = time.monotonic()
        results = await asyncio.gather(
            *(kvp.read(f"S{i}") for i in range(10)), return_exceptions=True
        )
        assert all(isinstance(r, KvpTimeoutError) for r in results)
        assert time.monotonic() - t0 < 1.0
        # a per-call override is honoured
        t0 = time.monotonic()
        with pytest.raises(KvpTimeoutError):
            await kvp.read("S", timeout=0.05)
        assert time.monotonic() - t0 < 0.5


async def test_connect_errors_are_clear() -> None:
    server = await asyncio.start_server(lambda r, w: None, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    server.close()
    await server.wait_closed()
    with pytest.raises(KvpConnectionError) as info:
        async with Client(port=port, timeout=0.5):
            pass
    assert f"127.0.0.1:{port}" in str(info.value)
    assert isinstance(info.value, ConnectionError)


async def test_id_wrap_and_skip_pending_ids() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        w.write(answer(req, str(req.msg_id).encode()))

    async with broken_server(handler) as port, Client(port=port) as kvp:
        conn = kvp.connection
        assert conn is not None
        conn.session.next_id = 65534
        ids = [int(await kvp.read("ID")) for _ in range(4)]
        assert ids == [65534, 65535, 0, 1]


async def test_keepalive_falls_back_to_a_cheap_read_on_old_proxies() -> None:
    seen: list[str] = []

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        seen.append(req.name)
        # an old proxy passes PING to CrossComm: empty value, success
        w.write(answer(req, b"" if req.name == "PING" else b"100"))

    async with broken_server(handler) as port, Client(port=port, keepalive=0.05) as kvp:
        await asyncio.sleep(0.4)
        assert kvp.connected
    # (the first two reads are the message-id probe)
    assert seen[2] == "PING" and "$OV_PRO" in seen[3:] and seen.count("PING") == 1


async def test_pipelining_never_exceeds_the_proxy_read_buffer() -> None:
    # KVP reads at most 2048 bytes per socket event and cannot reassemble a request cut there.
    # The client bounds unanswered bytes, so no single server read can exceed 2048 bytes.
    sizes: list[int] = []

    async def on_read(reqs: list[Request], writer: asyncio.StreamWriter) -> None:
        sizes.append(sum(len(r.encode()) for r in reqs))
        await asyncio.sleep(0.002)  # a slow proxy lets requests pile up
        writer.write(b"".join(answer(r) for r in reqs))

    async with FakeProxy(on_read=on_read) as port, Client(port=port, id_policy="strict") as kvp:
        names = [f"MYE6ARRAY[{i}]" for i in range(1, 401)]
        res = await kvp.read_many(names)
        assert [r.text for r in res.values()] == [f"v:{n}" for n in names]
    assert max(sizes) <= 2048
    assert len(sizes) < 400  # requests were coalesced, not sent one segment each


async def test_torques_fall_back_to_pipelined_element_reads() -> None:
    # A proxy that cannot read the whole array answers an empty value (KVP's "unknown").
    seen: list[str] = []

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        seen.append(req.name)
        if req.name.endswith("[]"):
            w.write(answer(req, b""))
        elif req.name == "$OV_PRO":  # the message-id probe before the first pipelined batch
            w.write(answer(req, b"100"))
        else:
            idx = int(req.name.split("[")[1].rstrip("]"))
            w.write(answer(req, f"{-1.5 * idx}".encode()))

    async with broken_server(handler) as port, Client(port=port) as kvp:
        tau = await kvp.read_joint_torques()
        assert list(tau) == [-1.5, -3.0, -4.5, -6.0, -7.5, -9.0]
        tau = await kvp.read_joint_torques()  # the fallback is remembered: no second [] read
    assert seen.count("$TORQUE_AXIS_ACT[]") == 1
    assert len(seen) == 13 + 2  # the two reads of the id probe (once per connection)


async def test_garbage_reply_drops_the_connection_with_a_protocol_message() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        w.write(b"\x00\x01\x00\x03\x00\x00\x05")  # L = 3 is impossible for a reply

    async with broken_server(handler) as port, Client(port=port) as kvp:
        with pytest.raises(KvpConnectionError, match="shorter than the minimum"):
            await kvp.read("X")
        assert not kvp.connected


async def test_a_request_that_waited_for_the_slot_still_times_out() -> None:
    """A request registered after the watchdog last ran gets a watchdog of its own.

    Until the ids are known only one request is in flight. A waited for the slot behind B; B's
    deadline fired the watchdog, which found no other request yet and went quiet; A, sent the
    moment B gave up, then waited forever (seen as a 60-second hang of the test above under
    load). Now A times out at its own deadline."""

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        await asyncio.sleep(10)  # never answers

    async with broken_server(handler) as port, Client(port=port, timeout=0.2) as kvp:
        t0 = time.monotonic()
        first = asyncio.ensure_future(kvp.read("B"))
        await asyncio.sleep(0)  # B takes the slot
        results = await asyncio.wait_for(
            asyncio.gather(first, kvp.read("A", timeout=0.6), return_exceptions=True), 5.0
        )
        assert all(isinstance(r, KvpTimeoutError) for r in results), results
        assert 0.5 < time.monotonic() - t0 < 2.0
