"""Deliberately misbehaving KUKAVARPROXY servers, for testing clients (ours and yours).

A :class:`FakeProxy` is a real TCP server on 127.0.0.1 (ephemeral port) that decodes requests
with the shared codec and lets a handler decide what, if anything, to send back: drop a reply,
swap two, answer with another id, stall, close mid-frame. Use it in a running event loop
(``async with FakeProxy(handler) as port:``) or, for blocking clients, on its own thread
(``with FakeProxy(handler) as port:``). It shuts its connections down cleanly, so a test that
uses it leaves no task behind and no unhandled error in the log.

``answer(req)`` builds the reply a correct KVP 9.0 would send (reads: ``v:NAME``, writes: echo).
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Awaitable, Callable
from types import TracebackType

from .protocol import Mode, Reply, Request, RequestDecoder, encode_reply

__all__ = ["FakeProxy", "Handler", "ReadHandler", "answer"]

#: Called for each request with the writer and the request's 1-based number on the server.
Handler = Callable[[Request, asyncio.StreamWriter, int], Awaitable[None]]
#: Called once per socket read with every request that read delivered (for legacy-id servers).
ReadHandler = Callable[[list[Request], asyncio.StreamWriter], Awaitable[None]]


def answer(req: Request, value: bytes | None = None, status: int = 1) -> bytes:
    """A correct KVP 9.0 reply: reads answer ``v:NAME``, writes echo their value."""
    if value is None:
        value = req.value if req.mode == Mode.WRITE else f"v:{req.name}".encode()
    assert value is not None
    return encode_reply(Reply(req.msg_id, req.mode, value, status))


class FakeProxy:
    """A scripted server; ``port`` is known once started. ``requests`` counts what it decoded."""

    def __init__(
        self, handler: Handler | None = None, *, on_read: ReadHandler | None = None
    ) -> None:
        if (handler is None) == (on_read is None):
            raise ValueError("give exactly one of handler and on_read")
        self.handler = handler
        self.on_read = on_read
        self.port = 0
        self.requests = 0
        self._server: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[None]] = set()
        self._writers: set[asyncio.StreamWriter] = set()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._tasks.add(task)
        self._writers.add(writer)
        decoder = RequestDecoder()
        try:
            while data := await reader.read(65536):
                requests = decoder.feed_requests(data)
                if self.on_read is not None:
                    self.requests += len(requests)
                    await self.on_read(requests, writer)
                    continue
                assert self.handler is not None
                for req in requests:
                    self.requests += 1
                    await self.handler(req, writer, self.requests)
        except (ConnectionError, asyncio.CancelledError):
            # end normally: on Python 3.11 a cancelled connection task makes asyncio's stream
            # callback log "Exception in callback"
            pass
        finally:
            self._writers.discard(writer)
            writer.close()
            self._tasks.discard(task)

    async def start(self) -> int:
        self._server = await asyncio.start_server(self._serve, "127.0.0.1", 0)
        self.port = self._server.sockets[0].getsockname()[1]
        return self.port

    async def stop(self) -> None:
        if self._server is not None:
            self._server.close()
        for writer in list(self._writers):
            writer.close()
        tasks = list(self._tasks)
        for task in tasks:
            task.cancel()
        if tasks:
            await asyncio.wait(tasks, timeout=2.0)

    async def __aenter__(self) -> int:
        return await self.start()

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.stop()

    # ------------------------------------------------------------------ on a thread

    def __enter__(self) -> int:
        started = threading.Event()

        async def main() -> None:
            self._stop = asyncio.Event()
            self._loop = asyncio.get_running_loop()
            await self.start()
            started.set()
            await self._stop.wait()
            await self.stop()

        self._thread = threading.Thread(target=asyncio.run, args=(main(),), daemon=True)
        self._thread.start()
        if not started.wait(5.0):
            raise RuntimeError("the fake proxy did not start")
        return self.port

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._loop is not None and self._stop is not None:
            with contextlib.suppress(RuntimeError):  # the loop already ended
                self._loop.call_soon_threadsafe(self._stop.set)
        if self._thread is not None:
            self._thread.join(5.0)
