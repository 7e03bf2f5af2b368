"""No leaked failures, and a stalled server is reported (issue 16, items 9 and 10).

A connection lost in the middle of a pipelined batch must fail the call with one clear error:
no "Future exception was never retrieved", no "socket.send() raised exception" (the suite's
conftest fails any test that logs one), and no failed future kept alive by the Client. A
server that stops answering must not leave a client that says ``connected`` while every call
fails with "no room".
"""

from __future__ import annotations

import asyncio
import gc
import logging

import pytest

from pyopenshowvar import Client, KvpConnectionError, KvpStalledError, KvpTimeoutError
from pyopenshowvar.protocol import Request
from pyopenshowvar.testing import FakeProxy, ReadHandler, answer


def _failed_futures() -> list[asyncio.Future[object]]:
    gc.collect()
    return [
        o
        for o in gc.get_objects()
        if isinstance(o, asyncio.Future) and o.done() and not o.cancelled() and o.exception()
    ]


def _closer(after: int, *, reset: bool) -> ReadHandler:
    """A server that answers ``after`` requests of a connection, then drops it (RST or FIN)."""

    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        for r in reqs:
            if r.name.startswith(("MYE6ARRAY", "OUTPUT", "V")) and int(r.msg_id) >= after:
                if reset:
                    w.transport.abort()  # RST: the client's next send fails
                else:
                    w.close()
                return
            w.write(answer(r))

    return on_read


@pytest.mark.parametrize("reset", [False, True])
@pytest.mark.parametrize("call", ["write_many", "read_many", "write_joint_path"])
async def test_connection_lost_mid_batch_leaks_nothing(
    call: str, reset: bool, asyncio_errors: list[logging.LogRecord]
) -> None:
    async with FakeProxy(on_read=_closer(7, reset=reset)) as port:
        kvp = Client(port=port, timeout=2.0)
        await kvp.connect()
        try:
            if call == "write_many":
                await kvp.write_many([(f"V{i}", i) for i in range(20)])
            elif call == "read_many":
                await kvp.read_many([f"V{i}" for i in range(20)])
            else:
                await kvp.write_joint_path(
                    [[i, -90, 90, 0, 0, 0] for i in range(20)], handshake=None
                )
        except KvpConnectionError as exc:
            message = str(exc)
        else:
            pytest.fail("the lost connection was not reported")
        assert f"127.0.0.1:{port}" in message
        assert not kvp.connected
        for _ in range(3):  # let asyncio run the transport's own callbacks
            await asyncio.sleep(0)
        assert _failed_futures() == []  # none kept alive, by the Client or anything else
        assert asyncio_errors == []
        with pytest.raises(KvpConnectionError, match="closed"):
            await kvp.read("AFTER")
        await kvp.close()


async def test_cancelled_batch_leaves_no_unretrieved_failure() -> None:
    async def never(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "$OV_PRO":
            w.write(answer(req))

    async with FakeProxy(never) as port, Client(port=port, timeout=0.2) as kvp:
        task = asyncio.create_task(kvp.read_many([f"V{i}" for i in range(10)]))
        await asyncio.sleep(0.05)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        await asyncio.sleep(0.3)  # the batch's timer fires after the cancellation
    assert _failed_futures() == []


async def test_stalled_server_marks_the_connection_unhealthy() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "$OV_PRO":
            w.write(answer(req))  # the id probe; everything else is never answered

    async with FakeProxy(handler) as port:
        async with Client(port=port, timeout=0.1, max_in_flight=8) as kvp:
            for i in range(8):  # each times out and keeps its place until answered
                with pytest.raises(KvpTimeoutError):
                    await kvp.read(f"S{i}", timeout=0.02 if i else 0.1)
            assert kvp.connected  # timeouts alone do not condemn a connection
            with pytest.raises(KvpStalledError) as info:
                await kvp.read("NEXT")
            text = str(info.value)
            assert "stopped answering" in text and "8 requests unanswered" in text
            assert "unhealthy" in text and "auto_reconnect is off" in text
            assert isinstance(info.value, KvpConnectionError)
            assert not kvp.connected


async def test_stalled_server_reconnects_with_auto_reconnect() -> None:
    connections: list[asyncio.StreamWriter] = []  # the writers themselves: ids get reused

    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        if w not in connections:
            connections.append(w)
        first = connections[0] is w
        w.write(b"".join(answer(r) for r in reqs if r.name == "$OV_PRO" or not first))

    async with FakeProxy(on_read=on_read) as port:
        async with Client(port=port, timeout=0.05, max_in_flight=4, auto_reconnect=True) as kvp:
            for i in range(4):
                with pytest.raises(KvpTimeoutError):
                    await kvp.read(f"S{i}")
            # the next call finds the window full of timed-out requests: the connection is
            # replaced and the call, which had sent nothing, goes out on the new one
            assert await kvp.read("AFTER", timeout=1.0) == "v:AFTER"
            assert kvp.reconnects == 1 and kvp.connected
