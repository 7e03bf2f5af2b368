"""The web server's connection caps and log limit (web/httpguard.py), without uvicorn.

:class:`ConnectionGuard` counts real server-side transports of a plain asyncio server on
loopback, the clients bound to different 127.0.0.x addresses; the uvicorn protocols built on
it are tested end to end in tests/test_web_hostile.py.
"""

from __future__ import annotations

import asyncio
import logging
import socket
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest
from pyopenshowvar_apps.web import httpguard
from pyopenshowvar_apps.web.httpguard import ConnectionGuard, LogLimit

Connect = Callable[[str], Awaitable[asyncio.BaseTransport]]


@pytest.fixture
async def connect() -> AsyncIterator[Connect]:
    """Connects a client from the given address; yields the server side of the connection."""
    accepted: asyncio.Queue[asyncio.BaseTransport] = asyncio.Queue()

    class Accept(asyncio.Protocol):
        def connection_made(self, transport: asyncio.BaseTransport) -> None:
            accepted.put_nowait(transport)

    loop = asyncio.get_running_loop()
    server = await loop.create_server(Accept, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    clients: list[asyncio.BaseTransport] = []

    async def make(source: str) -> asyncio.BaseTransport:
        transport, _ = await loop.create_connection(
            asyncio.Protocol, "127.0.0.1", port, local_addr=(source, 0)
        )
        clients.append(transport)
        return await asyncio.wait_for(accepted.get(), 2.0)

    yield make
    for transport in clients:
        transport.close()
    server.close()
    await server.wait_closed()


async def test_connections_are_capped_per_address_and_in_all(connect: Connect) -> None:
    guard = ConnectionGuard(per_address=2, total=3)
    a1, a2, a3 = [await connect("127.0.0.2") for _ in range(3)]
    assert guard.address(a1) == "127.0.0.2"
    assert guard.admit(a1) and guard.admit(a2)
    assert not guard.admit(a3)  # the third from one address
    assert (guard.count, guard.refused, guard.open) == (2, 1, {"127.0.0.2": {a1, a2}})
    assert guard.admit(a1)  # the same connection again (its WebSocket upgrade): not counted
    assert guard.count == 2
    b1, b2 = await connect("127.0.0.3"), await connect("127.0.0.3")
    assert guard.admit(b1)
    assert not guard.admit(b2)  # the total is reached, the address has room
    assert (guard.count, guard.refused) == (3, 2)
    # a refused connection is not released: nothing was counted for it
    guard.release(a3)
    guard.release(b2)
    assert guard.count == 3
    guard.release(a1)
    assert guard.count == 2 and guard.open["127.0.0.2"] == {a2}
    guard.release(a1)  # twice: no effect
    assert guard.count == 2
    assert guard.admit(a3)  # room again
    for transport in (a2, a3, b1):
        guard.release(transport)
    assert (guard.count, guard.open) == (0, {})


async def test_the_defaults_are_the_documented_caps(connect: Connect) -> None:
    guard = ConnectionGuard()
    assert (guard.per_address, guard.total, guard.head_timeout) == (16, 64, 2.0)
    assert (httpguard.PER_ADDRESS, httpguard.TOTAL, httpguard.HEAD_TIMEOUT) == (16, 64, 2.0)
    conns = [await connect("127.0.0.4") for _ in range(17)]
    assert [guard.admit(t) for t in conns] == [True] * 16 + [False]


async def test_a_connection_without_an_address_is_counted_under_one_name(tmp_path: Path) -> None:
    accepted: asyncio.Queue[asyncio.BaseTransport] = asyncio.Queue()

    class Accept(asyncio.Protocol):
        def connection_made(self, transport: asyncio.BaseTransport) -> None:
            accepted.put_nowait(transport)

    loop = asyncio.get_running_loop()
    path = str(tmp_path / "s")
    server = await loop.create_unix_server(Accept, path)
    client, _ = await loop.create_unix_connection(asyncio.Protocol, path)
    named = socket.socket(socket.AF_UNIX)
    named.bind(str(tmp_path / "c"))  # a client with a path: its peer name is that text
    named.connect(path)
    other, _ = await loop.create_unix_connection(asyncio.Protocol, sock=named)
    try:
        transport = await asyncio.wait_for(accepted.get(), 2.0)
        guard = ConnectionGuard(per_address=1)
        assert guard.address(transport) == "?"
        assert guard.admit(transport) and guard.open == {"?": {transport}}
        second = await asyncio.wait_for(accepted.get(), 2.0)
        assert second.get_extra_info("peername") == str(tmp_path / "c")
        assert guard.address(second) == "?"
        assert not guard.admit(second)  # the same "address" as the first
    finally:
        other.close()
        client.close()
        server.close()
        await server.wait_closed()


def test_the_log_limit_forgets_quiet_keys_beyond_a_thousand(
    caplog: pytest.LogCaptureFixture,
) -> None:
    now = [100.0]
    limit = LogLimit(logging.getLogger("test.loglimit.keys"), period=10.0, clock=lambda: now[0])
    with caplog.at_level(logging.WARNING, logger="test.loglimit.keys"):
        for i in range(1000):
            limit.warning(f"k{i}", "refused %s", i)
        now[0] += 10.0  # one period later: every key is quiet
        limit.warning("n1", "refused %s", "n1")
        assert len(limit._last) == 1001  # a thousand keys are kept
        limit.warning("n2", "refused %s", "n2")  # beyond: the quiet ones are forgotten
        assert set(limit._last) == {"n1", "n2"}
    assert len(caplog.records) == 1002


def test_the_log_limit_speaks_again_after_exactly_one_period(
    caplog: pytest.LogCaptureFixture,
) -> None:
    now = [0.0]
    limit = LogLimit(logging.getLogger("test.loglimit.period"), period=10.0, clock=lambda: now[0])
    with caplog.at_level(logging.WARNING, logger="test.loglimit.period"):
        limit.warning("a", "refused %s", "a")
        now[0] = 9.999
        limit.warning("a", "refused %s", "a")  # left out, and counted
        now[0] = 10.0
        limit.warning("a", "refused %s", "a")
    assert [r.getMessage() for r in caplog.records] == [
        "refused a",
        "refused a (and 1 more like it)",
    ]


async def _app(scope: dict[str, Any], receive: Any, send: Any) -> None:
    """The smallest ASGI page: ``/slow`` answers after 0.5 s (longer than the head timeout)."""
    if scope["type"] != "http":
        return
    if scope["path"] == "/slow":
        await asyncio.sleep(0.5)
    await send(
        {"type": "http.response.start", "status": 200, "headers": [(b"content-length", b"2")]}
    )
    await send({"type": "http.response.body", "body": b"ok"})


async def test_uvicorn_with_the_guard_times_out_heads_and_refuses_beyond_the_cap(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """uvicorn's own protocols with the guard, on a minimal page (about 1.5 s: two head
    timeouts of 0.3 s and a 0.5 s response)."""
    import uvicorn

    guard = ConnectionGuard(per_address=2, total=10, head_timeout=0.3)
    http, ws = httpguard.guarded_protocols(guard)
    config = uvicorn.Config(
        _app, host="127.0.0.1", port=0, http=http, ws=ws, lifespan="off", log_level="error"
    )
    server = uvicorn.Server(config)
    serving = asyncio.create_task(server.serve())
    try:
        async with asyncio.timeout(5):
            while not server.started:  # noqa: ASYNC110 - uvicorn has no event for it
                await asyncio.sleep(0.01)
        port = server.servers[0].sockets[0].getsockname()[1]
        get = b"GET /%s HTTP/1.1\r\nHost: x\r\n\r\n"
        # a response slower than the head timeout is not cut; the idle keep-alive then is
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(get % b"slow")
        answer = await asyncio.wait_for(reader.read(), 5)
        writer.close()
        assert answer.startswith(b"HTTP/1.1 200 ") and b"\r\n\r\nok" in answer
        assert answer.endswith(b"HTTP/1.1 408 Request Timeout\r\nConnection: close\r\n"
                               b"Content-Length: 0\r\n\r\n")  # fmt: skip
        assert guard.timed_out == 1
        # two held connections from one address, the third refused at once, unread
        held = [await asyncio.open_connection("127.0.0.1", port) for _ in range(2)]
        with caplog.at_level(logging.WARNING, logger=httpguard.__name__):
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            writer.write(get % b"")  # never parsed
            refused = await asyncio.wait_for(reader.read(), 5)
            writer.close()
        assert refused == (
            b"HTTP/1.1 503 Service Unavailable\r\nConnection: close\r\nContent-Length: 0\r\n\r\n"
        )
        assert guard.refused == 1 and guard.count == 2
        assert "refused connections from 127.0.0.1: too many" in caplog.text
        for r, w in held:  # neither sends a head: both are closed after the timeout
            assert (await asyncio.wait_for(r.read(), 5)).startswith(b"HTTP/1.1 408 ")
            w.close()
        assert guard.timed_out == 3
        async with asyncio.timeout(2):
            while guard.count:  # noqa: ASYNC110 - connection_lost releases them
                await asyncio.sleep(0.01)
        assert guard.open == {}
    finally:
        server.should_exit = True
        await serving
