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
