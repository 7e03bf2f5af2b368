"""The emulator's interpolation clock: one tick per IPO cycle against absolute deadlines.

Simulated time advances exactly ``ipo`` seconds per tick. Wall time between ticks is
``ipo / speed``: ``speed = 1`` is real time, ``speed = 20`` runs every timing of the simulated
robot twenty times faster, consistently (a 1 s move takes 50 ms of wall time and 1 s of
simulated time). Tick ``n`` is due at ``start + n · ipo / speed`` on the loop's monotonic clock;
scheduling against these absolute deadlines (not "sleep one period after the last tick") means
the sleep overshoot of one tick does not delay the next ones, so jitter never accumulates.

When the loop falls behind (a long callback, a busy machine), late ticks run back to back until
the clock has caught up; after more than ``MAX_BEHIND`` seconds behind it gives up and re-bases
the deadlines (``overruns`` counts that), so a suspended process does not replay minutes.
"""

from __future__ import annotations

import asyncio
import logging
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["IpoClock", "JitterStats"]

log = logging.getLogger(__name__)

#: Seconds of wall time the clock may lag before it drops ticks instead of catching up.
MAX_BEHIND = 0.5


@dataclass(frozen=True, slots=True)
class JitterStats:
    """Tick lateness (actual − scheduled wall time), seconds, over the recorded ticks."""

    count: int
    p50: float
    p99: float
    max: float
    mean: float

    def __str__(self) -> str:
        ms = 1e3
        return (
            f"n={self.count} p50={self.p50 * ms:.3f} ms p99={self.p99 * ms:.3f} ms "
            f"max={self.max * ms:.3f} ms mean={self.mean * ms:.3f} ms"
        )


class IpoClock:
    """Calls ``callback()`` once per interpolation cycle until :meth:`stop`."""

    def __init__(
        self,
        callback: Callable[[], None],
        *,
        ipo: float = 0.012,
        speed: float = 1.0,
        keep: int = 100_000,
    ) -> None:
        if ipo <= 0 or speed <= 0:
            raise ValueError("ipo and speed must be positive")
        self.callback = callback
        self.ipo = ipo
        self.speed = speed
        self.ticks = 0
        self.overruns = 0
        #: Lateness of the most recent ticks (s), for the jitter benchmark.
        self.jitter: deque[float] = deque(maxlen=keep)
        self._task: asyncio.Task[None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._start = 0.0
        self._n = 0
        self._deadline = float("inf")

    @property
    def period(self) -> float:
        """Wall seconds per tick."""
        return self.ipo / self.speed

    @property
    def running(self) -> bool:
        return self._task is not None and not self._task.done()

    def start(self) -> None:
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run(), name="ipo-clock")

    async def stop(self) -> None:
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            try:
                await task
            except asyncio.CancelledError:
                pass

    def poll(self) -> None:
        """Run the tick now if it is due.

        The server calls this before answering each batch of requests: under load from many
        clients one event-loop pass answers every client before the timer callback gets its
        turn, so the tick would wait behind all of them. Polling here bounds the lateness by one
        client's batch instead.
        """
        if self._loop is not None and self._loop.time() >= self._deadline:
            self._tick(self._loop.time())

    def _tick(self, now: float) -> None:
        late = now - self._deadline
        if late > MAX_BEHIND:
            self.overruns += 1
            log.warning("IPO clock %.0f ms behind; skipping ticks", late * 1e3)
            self._start, self._n = now, 0
        self.jitter.append(max(late, 0.0))
        self.ticks += 1
        self._n += 1
        self._deadline = self._start + self._n * self.period
        try:
            self.callback()
        except Exception:  # a bug in one tick must not stop the robot's clock for good
            log.exception("IPO tick failed")

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        self._start = loop.time()
        self._n = 1
        self._deadline = self._start + self.period
        self._loop = loop
        try:
            while True:
                delay = self._deadline - loop.time()
                if delay > 0:
                    await asyncio.sleep(delay)
                now = loop.time()
                if now >= self._deadline:  # poll() may have run this tick already
                    self._tick(now)
                if self._deadline <= loop.time():
                    await asyncio.sleep(0)  # catching up: still let the server answer requests
        finally:
            self._loop = None

    def stats(self) -> JitterStats:
        """p50 / p99 / max / mean lateness of the recorded ticks."""
        data = sorted(self.jitter)
        if not data:
            return JitterStats(0, 0.0, 0.0, 0.0, 0.0)
        n = len(data)
        return JitterStats(
            n, data[n // 2], data[min(n - 1, int(n * 0.99))], data[-1], sum(data) / n
        )

    def reset_stats(self) -> None:
        self.jitter.clear()
