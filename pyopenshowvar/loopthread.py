"""An asyncio service on its own event loop in a daemon thread, for synchronous callers.

:class:`~kukavarproxy_emu.emulator_thread.EmulatorThread` and the heave case study's platform
simulator both need the same lifecycle: build the service on a private loop, report start-up
errors to the caller, run callables on that loop, and close the service when stopped. This
module has it once, in the client library both may depend on; it imports nothing else, so a
light service does not pay for more.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from types import TracebackType
from typing import Any, Generic, Protocol, Self, TypeVar

__all__ = ["LoopThread"]

T = TypeVar("T")


class Service(Protocol):
    async def start(self) -> Any: ...

    async def close(self) -> None: ...


S = TypeVar("S", bound=Service)


class LoopThread(Generic[S]):
    """Runs the service :meth:`_make` builds on its own loop in a daemon thread.

    Subclasses set ``NAME`` (the thread's name) and ``LABEL`` (how errors name the service).
    """

    NAME = "service"
    LABEL = "the service"

    def __init__(self, *, start_timeout: float = 10.0) -> None:
        self._start_timeout = start_timeout
        self._ready = threading.Event()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._service: S | None = None
        self._error: BaseException | None = None

    def _make(self) -> S:
        raise NotImplementedError

    @property
    def service(self) -> S:
        if self._service is None:
            raise RuntimeError(f"{self.LABEL} is not running")
        return self._service

    def start(self) -> Self:
        if self._thread is not None:
            return self
        self._thread = threading.Thread(target=self._run, name=self.NAME, daemon=True)
        self._thread.start()
        if not self._ready.wait(self._start_timeout):
            raise TimeoutError(f"{self.LABEL} did not start in time")
        if self._error is not None:
            raise RuntimeError(f"{self.LABEL} failed to start: {self._error}") from self._error
        return self

    def stop(self) -> None:
        thread, self._thread = self._thread, None
        if thread is None:
            return
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        thread.join(timeout=10.0)
        self._service = None

    def call(self, fn: Callable[..., T], *args: Any) -> T:
        """Run ``fn(*args)`` on the service's loop and return its result."""
        if self._loop is None:
            raise RuntimeError(f"{self.LABEL} is not running")

        async def run() -> T:
            return fn(*args)

        return asyncio.run_coroutine_threadsafe(run(), self._loop).result(timeout=10.0)

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:  # reported to start(); the thread must not die silently
            self._error = exc
            self._ready.set()

    async def _main(self) -> None:
        service = self._make()
        await service.start()
        try:
            self._loop = asyncio.get_running_loop()
            self._stop = asyncio.Event()
            self._service = service
            self._ready.set()
            await self._stop.wait()
        finally:
            await service.close()
