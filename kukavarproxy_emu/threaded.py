"""Run an :class:`~kukavarproxy_emu.server.Emulator` in a background thread for synchronous code.

The ``kvp`` CLI (``--emulate``), typer's CliRunner tests and scripts that are not asyncio use it;
the emulator keeps its own event loop so it serves requests while the caller blocks.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from types import TracebackType
from typing import Any, Self, TypeVar

from .config import EmulatorConfig
from .faults import FaultSet
from .server import Emulator, Stats
from .store import VariableStore

__all__ = ["EmulatorThread"]

T = TypeVar("T")


class EmulatorThread:
    """An :class:`Emulator` on its own event loop in a daemon thread, for synchronous code.

    ``with EmulatorThread(EmulatorConfig(port=0)) as emu: ... emu.port ...``. The store and the
    faults may be used from the calling thread (both are plain, GIL-protected objects); use
    :meth:`call` to run something on the emulator's loop when ordering with traffic matters.
    """

    def __init__(
        self,
        config: EmulatorConfig | None = None,
        *,
        store: VariableStore | None = None,
        start_timeout: float = 10.0,
    ) -> None:
        self.config = config if config is not None else EmulatorConfig(port=0)
        self._store = store
        self._start_timeout = start_timeout
        self._ready = threading.Event()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._emulator: Emulator | None = None
        self._error: BaseException | None = None

    @property
    def emulator(self) -> Emulator:
        if self._emulator is None:
            raise RuntimeError("EmulatorThread is not running")
        return self._emulator

    @property
    def host(self) -> str:
        return self.emulator.host

    @property
    def port(self) -> int:
        return self.emulator.port

    @property
    def store(self) -> VariableStore:
        return self.emulator.store

    @property
    def faults(self) -> FaultSet:
        return self.emulator.faults

    @property
    def stats(self) -> Stats:
        return self.emulator.stats

    def start(self) -> Self:
        if self._thread is not None:
            return self
        self._thread = threading.Thread(target=self._run, name="kukavarproxy-emu", daemon=True)
        self._thread.start()
        if not self._ready.wait(self._start_timeout):
            raise TimeoutError("the emulator thread did not start in time")
        if self._error is not None:
            raise RuntimeError(f"the emulator failed to start: {self._error}") from self._error
        return self

    def stop(self) -> None:
        thread, self._thread = self._thread, None
        if thread is None:
            return
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        thread.join(timeout=10.0)
        self._emulator = None

    def call(self, fn: Callable[..., T], *args: Any) -> T:
        """Run ``fn(*args)`` on the emulator's loop and return its result."""
        if self._loop is None:
            raise RuntimeError("EmulatorThread is not running")

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
        emulator = Emulator(self.config, store=self._store)
        await emulator.start()
        try:
            self._loop = asyncio.get_running_loop()
            self._stop = asyncio.Event()
            self._emulator = emulator
            self._ready.set()
            await self._stop.wait()
        finally:
            await emulator.close()
