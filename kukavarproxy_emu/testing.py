"""pytest fixtures for tests that need a live emulator.

Enable them in a conftest with ``pytest_plugins = ["kukavarproxy_emu.testing"]`` (or import the
fixture names into a test module). All of them bind 127.0.0.1 on an ephemeral port with no
latency and no discovery, and close the emulator after the test:

* ``emulator`` — an async fixture yielding a started :class:`Emulator`;
* ``emulator_factory`` — ``await emulator_factory(strict=True, ...)``: any EmulatorConfig field
  as a keyword (``store=`` for a prepared store), as many emulators as the test wants;
* ``emulator_thread`` — an :class:`EmulatorThread` for synchronous code (CLI tests);
* ``ideal_emulator`` / ``ideal_emulator_thread`` — the same with ``plant="ideal"``: measured
  axes = set-point and statics torques, for tests that compare exact values (the default
  dynamic plant adds servo lag and seeded sensor noise, like a real robot).

:class:`RawClient` is a deliberately dumb asyncio client speaking raw frames (no ids, no
retries), for tests that need to see exactly the bytes the emulator sends.

:func:`wait_until` / :func:`wait_until_sync` poll a condition with a deadline: what a test
waits on instead of a fixed sleep, so it holds on a loaded machine and is quick on an idle one.
"""

from __future__ import annotations

import asyncio
import inspect
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from dataclasses import replace
from types import TracebackType
from typing import Any, Protocol, Self

import pytest
import pytest_asyncio

from pyopenshowvar.protocol import HEADER_SIZE, Reply, decode_reply

from .config import EmulatorConfig
from .emulator_thread import EmulatorThread
from .server import Emulator
from .store import VariableStore

__all__ = [
    "IDEAL_CONFIG",
    "TEST_CONFIG",
    "EmulatorFactory",
    "RawClient",
    "emulator",
    "emulator_factory",
    "emulator_thread",
    "fast_robot",
    "ideal_emulator",
    "ideal_emulator_thread",
    "wait_until",
    "wait_until_sync",
]

#: The configuration every fixture starts from.
TEST_CONFIG = EmulatorConfig(port=0, latency="none", discovery=False)
#: The same with the ideal plant (exact values).
IDEAL_CONFIG = replace(TEST_CONFIG, plant="ideal")


async def wait_until(
    predicate: Callable[[], object],
    timeout: float = 10.0,
    *,
    interval: float = 0.005,
    what: str = "",
) -> None:
    """Poll ``predicate()`` (its result may be awaitable) every ``interval`` seconds until it
    is true; AssertionError naming ``what`` if it is not within ``timeout`` seconds.

    The deadline is generous on purpose: on an idle machine the wait ends as soon as the
    condition holds, and a loaded one may take many times longer without failing the test.
    """
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while True:
        value = predicate()
        if inspect.isawaitable(value):
            value = await value
        if value:
            return
        if loop.time() > end:
            raise AssertionError(f"not true within {timeout} s: {what or predicate}")
        await asyncio.sleep(interval)


def wait_until_sync(
    predicate: Callable[[], object],
    timeout: float = 10.0,
    *,
    interval: float = 0.005,
    what: str = "",
) -> None:
    """:func:`wait_until` for synchronous code (CLI tests, threads): sleeps between polls."""
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f"not true within {timeout} s: {what or predicate}")
        time.sleep(interval)


class RawClient:
    """One TCP connection that sends bytes and reads whole frames, with timeouts."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader = reader
        self.writer = writer

    @classmethod
    async def connect(cls, host: str, port: int) -> RawClient:
        reader, writer = await asyncio.open_connection(host, port)
        return cls(reader, writer)

    async def send(self, data: bytes) -> None:
        self.writer.write(data)
        await self.writer.drain()

    async def read_frame(self, timeout: float = 2.0) -> bytes:
        """One whole frame as framed by its length field (raises TimeoutError, EOF errors)."""
        async with asyncio.timeout(timeout):
            header = await self.reader.readexactly(HEADER_SIZE)
            body = await self.reader.readexactly(int.from_bytes(header[2:4], "big"))
        return header + body

    async def read_reply(self, timeout: float = 2.0) -> Reply:
        return decode_reply(await self.read_frame(timeout))

    async def request(self, frame: bytes, timeout: float = 2.0) -> bytes:
        await self.send(frame)
        return await self.read_frame(timeout)

    async def read_until_eof(self, timeout: float = 2.0) -> bytes:
        """Everything until the server closes (raises TimeoutError if it does not)."""
        async with asyncio.timeout(timeout):
            return await self.reader.read()

    async def is_closed_by_peer(self, timeout: float = 2.0) -> bool:
        """True when the server closes within ``timeout`` without sending anything more."""
        try:
            async with asyncio.timeout(timeout):
                data = await self.reader.read(1)
        except TimeoutError:
            return False
        except ConnectionError:
            return True
        return data == b""

    async def close(self) -> None:
        self.writer.close()
        try:
            await self.writer.wait_closed()
        except ConnectionError:
            pass

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()


class EmulatorFactory(Protocol):
    def __call__(
        self, *, store: VariableStore | None = None, **overrides: Any
    ) -> Awaitable[Emulator]: ...


@pytest_asyncio.fixture
async def emulator_factory() -> AsyncIterator[EmulatorFactory]:
    started: list[Emulator] = []

    async def make(*, store: VariableStore | None = None, **overrides: Any) -> Emulator:
        emu = Emulator(replace(TEST_CONFIG, **overrides), store=store)
        await emu.start()
        started.append(emu)
        return emu

    yield make
    for emu in reversed(started):
        await emu.close()


@pytest_asyncio.fixture
async def emulator(emulator_factory: EmulatorFactory) -> Emulator:
    return await emulator_factory()


@pytest_asyncio.fixture
async def fast_robot(emulator_factory: EmulatorFactory) -> Emulator:
    """An emulator whose simulated robot runs 20× faster than real time (``speed=20``)."""
    return await emulator_factory(speed=20.0)


@pytest_asyncio.fixture
async def ideal_emulator(emulator_factory: EmulatorFactory) -> Emulator:
    """An emulator with the ideal plant (exact values)."""
    return await emulator_factory(plant="ideal")


@pytest.fixture
def emulator_thread() -> Iterator[EmulatorThread]:
    with EmulatorThread(TEST_CONFIG) as emu:
        yield emu


@pytest.fixture
def ideal_emulator_thread() -> Iterator[EmulatorThread]:
    """An :class:`EmulatorThread` with the ideal plant (exact values)."""
    with EmulatorThread(IDEAL_CONFIG) as emu:
        yield emu
