"""Long CPU work on the event loop's thread, a few milliseconds at a time.

Parsing a 64 KiB KRL module takes a fifth of a second; done in one go it would hold the event
loop, and with it every other client, that long. :func:`run_sliced` runs such a function in
slices of at most :data:`SLICE` seconds, one slice per event-loop iteration for all sliced work
together, so other clients are served between two slices.

The function runs in a worker thread, but never *at the same time* as the loop: the loop hands
it a slice and waits (releasing the GIL) until the function calls its ``checkpoint`` after the
slice is used up, and only then goes on with its own work. So the function may touch what the
loop owns (the variable store) exactly as if it ran on the loop, and there is no contention for
the GIL (a thread left to run freely would make every loop iteration wait for the interpreter's
5 ms switch interval). The function must call ``checkpoint()`` often (every statement, every
few hundred tokens): a slice ends at the first checkpoint after its time is up.

Calls are served first come, first served: one call's slices until it ends, then the next.
That keeps only one call's intermediate data alive at a time (a parse in progress holds
megabytes) and finishes the first caller soonest; the total time is the same either way.
"""

from __future__ import annotations

import asyncio
import threading
import time
import weakref
from collections import deque
from collections.abc import Callable
from typing import Generic, TypeVar

__all__ = ["SLICE", "Checkpoint", "run_sliced"]

#: Seconds of sliced work per event-loop iteration (all sliced calls together).
SLICE = 0.002

T = TypeVar("T")
#: What a sliced function calls to let the loop run once its slice is used up.
Checkpoint = Callable[[], None]


class _Cancelled(BaseException):
    """Raised at a checkpoint when the caller went away: unwinds the worker thread."""


class _Call(Generic[T]):
    """One function run in slices by a worker thread (see the module docstring)."""

    def __init__(self, fn: Callable[[Checkpoint], T]) -> None:
        self.fn = fn
        self.future: asyncio.Future[T] = asyncio.get_running_loop().create_future()
        self._go = threading.Semaphore(0)  # loop -> worker: run one slice
        self._paused = threading.Semaphore(0)  # worker -> loop: slice over (or done)
        self._deadline = 0.0
        self._cancelled = False
        self._thread: threading.Thread | None = None
        self._done = False
        self._result: T | None = None
        self._error: BaseException | None = None

    def _main(self) -> None:
        self._go.acquire()
        try:
            if not self._cancelled:
                self._result = self.fn(self._checkpoint)
        except _Cancelled:
            pass
        except BaseException as exc:  # handed to the caller, raised there
            self._error = exc
        finally:
            self._done = True
            self._paused.release()

    def _checkpoint(self) -> None:
        if time.perf_counter() < self._deadline:
            return
        self._paused.release()
        self._go.acquire()
        if self._cancelled:
            raise _Cancelled

    def step(self, budget: float) -> bool:
        """Run one slice of about ``budget`` seconds (the loop waits meanwhile); True when the
        function has ended."""
        self._deadline = time.perf_counter() + budget
        if self._thread is None:
            self._thread = threading.Thread(target=self._main, name="kvp-emu slice", daemon=True)
            self._thread.start()
        self._go.release()
        self._paused.acquire()
        return self._done

    def cancel(self) -> None:
        """Stop the worker at its next checkpoint (the caller no longer waits)."""
        self._cancelled = True
        if self._thread is not None and not self._done:
            self._go.release()
            self._paused.acquire()

    def finish(self) -> None:
        if self.future.done():
            return
        if self._error is not None:
            self.future.set_exception(self._error)
            self._error = None  # the future holds it now: no reference cycle through us
        else:
            self.future.set_result(self._result)  # type: ignore[arg-type]


class _Scheduler:
    """The sliced calls of one event loop, served one slice per loop iteration."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.calls: deque[_Call[object]] = deque()
        self.scheduled = False

    def add(self, call: _Call[object]) -> None:
        self.calls.append(call)
        self._schedule()

    def _schedule(self) -> None:
        if self.calls and not self.scheduled:
            self.scheduled = True
            self.loop.call_soon(self._run)

    def _run(self) -> None:
        self.scheduled = False
        call = self.calls[0]
        if call.future.done():  # cancelled by its caller
            self.calls.popleft()
            call.cancel()
        elif call.step(SLICE):
            self.calls.popleft()
            call.finish()
        self._schedule()


_SCHEDULERS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, _Scheduler] = (
    weakref.WeakKeyDictionary()
)


async def run_sliced(fn: Callable[[Checkpoint], T]) -> T:
    """``fn(checkpoint)``, run in slices of :data:`SLICE` seconds between other work of the
    running loop; its result, or its exception. Cancelling the caller stops ``fn`` at its next
    checkpoint."""
    loop = asyncio.get_running_loop()
    scheduler = _SCHEDULERS.get(loop)
    if scheduler is None:
        scheduler = _SCHEDULERS[loop] = _Scheduler(loop)
    call: _Call[T] = _Call(fn)
    scheduler.add(call)  # type: ignore[arg-type]
    return await call.future
