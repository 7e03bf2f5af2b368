"""The emulator's interpolation clocks: one tick per IPO cycle against absolute deadlines.

Simulated time advances exactly ``ipo`` seconds per tick. Wall time between ticks is
``ipo / speed``: ``speed = 1`` is real time, ``speed = 20`` runs every timing of the simulated
robot twenty times faster, consistently (a 1 s move takes 50 ms of wall time and 1 s of
simulated time). Tick ``n`` is due at ``start + phase + n · ipo / speed`` on the loop's monotonic
clock; scheduling against these absolute deadlines (not "sleep one period after the last
tick") means the sleep overshoot of one tick does not delay the next ones, so jitter never
accumulates. ``phase`` spreads the robots of a cell over the period, so their ticks do not all
fall due at the same instant.

Every clock of one event loop runs on one shared timer (:class:`_Wheel`): a single
``loop.call_at`` for the earliest deadline, which runs every clock due and re-arms. A cell of
fifty robots costs one timer callback per due deadline, not fifty sleeping tasks.

**Replies first.** With a latency profile the emulator answers each request at an absolute
deadline; a tick running at that instant would make the reply late, and a tick running while
a request arrives makes its deadline late (it is booked when the loop reads it). A clock may
therefore have a ``gate``: at its deadline the tick runs only if the gate says the loop is
free for the tick's expected cost (the next reply is far enough away); otherwise it is held
until :func:`release` (called when a request has just been booked, i.e. in the shadow of a
reply that is at least a service time away) or for at most ``max_hold`` seconds. A held tick
is late, never skipped: simulated time still advances exactly one ``ipo`` per tick.

When the loop falls behind (a long callback, a busy machine), late ticks run back to back until
the clock has caught up (each in its own loop iteration, so requests are still answered in
between); after more than ``MAX_BEHIND`` seconds behind it gives up and re-bases the deadlines
(``overruns`` counts that), so a suspended process does not replay minutes.

**Coasting.** Waking the process costs more than a tick of a robot at rest, and a process
woken every 12 ms already costs about 1 % of a core. A clock with ``coast = K > 1`` and a
``quiet()`` predicate (the robot: "this tick changed nothing that wall time could show":
kernel standing still, both KRL passes skipped as exact repeats, the plant resting, no store
write) may therefore sleep through up to ``K - 1`` ticks and run them back to back at its next
wake-up, just before the tick that is due then. No tick is skipped and each still advances
simulated time by exactly one ``ipo``; only their wall time moves. Whoever looks at the robot
calls :meth:`IpoClock.poll` first (the servers before each batch, the robot's in-process API,
any write into the store from outside a tick): it runs every coasted tick that is due and ends
the coast, so the reader sees the state of the last due tick and a write is acted on by the
next regular tick. Coasted ticks are deliberate, so they are not counted as lateness.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import logging
import math
import time
import weakref
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["IpoClock", "JitterStats", "release"]

log = logging.getLogger(__name__)

#: Seconds of wall time the clock may lag before it drops ticks instead of catching up.
MAX_BEHIND = 0.5
#: A timer callback also runs the ticks due within this many seconds ...
EARLY = 0.004
#: ... as long as it has run for less than this (s).
BURST = 0.0005
#: Seconds between two "clock behind" warnings of one process.
WARN_EVERY = 10.0
#: Longest wall time a clock may coast (s), whatever its ``coast`` and period: well below
#: ``MAX_BEHIND``, so a coast is never mistaken for a stall.
COAST_MAX = 0.1


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


class _Wheel:
    """The clocks of one event loop on one timer: a heap of ``(deadline, seq, clock)``.

    Entries go stale when a clock stops or ticks through :meth:`IpoClock.poll` (its deadline
    moved on); they are skipped when they reach the top.
    """

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self._heap: list[tuple[float, int, IpoClock]] = []
        self._seq = itertools.count()
        self._handle: asyncio.TimerHandle | None = None
        self._when = float("inf")
        #: Clocks whose due tick waits for :meth:`release` (or for their hold to run out).
        self.held: set[IpoClock] = set()
        #: Timer callbacks run so far (wake-ups of the process for its clocks).
        self.fires = 0

    def push(self, clock: IpoClock) -> None:
        clock._wake = clock._deadline + clock._coasting * clock.period
        heapq.heappush(self._heap, (clock._wake, next(self._seq), clock))
        self._arm()

    def _arm(self) -> None:
        heap = self._heap
        while heap and (not heap[0][2]._running or heap[0][0] != heap[0][2]._wake):
            heapq.heappop(heap)
        when = heap[0][0] if heap else float("inf")
        if when == self._when:
            return
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
        self._when = when
        if heap:
            self._handle = self.loop.call_at(when, self._fire)

    def _fire(self) -> None:
        self._handle, self._when = None, float("inf")
        self.fires += 1
        loop, heap = self.loop, self._heap
        now = loop.time()
        due: list[IpoClock] = []
        while heap and heap[0][0] <= now:
            wake, _, clock = heapq.heappop(heap)
            if clock._running and wake == clock._wake:
                due.append(clock)
        for clock in due:
            if not clock._running:
                continue
            if clock._may_tick(now):
                clock._catch_up(now)
                if clock._deadline <= now:  # not after a re-base in the catch-up
                    clock._tick(loop.time())
                clock._plan()
            else:  # held: until release() or the hold runs out
                clock._holding = True
                clock._wake = clock._due() + clock.max_hold
                self.held.add(clock)
            heapq.heappush(heap, (clock._wake, next(self._seq), clock))
        self._early(now)
        # a clock still behind is due again at once: call_at(past) runs in the next loop
        # iteration, after the I/O that is ready (requests are answered between late ticks)
        self._arm()

    def _early(self, now: float) -> None:
        """Run ticks due within ``EARLY`` seconds now, while this callback has taken less than
        ``BURST``: a cell of robots at rest then wakes the process once per period instead of
        once per phase (a wake-up costs more than a tick at rest), and a cell of moving robots,
        whose ticks are expensive, still spreads its work over the phases."""
        heap, loop = self._heap, self.loop
        while heap and heap[0][0] <= now + EARLY and loop.time() - now < BURST:
            wake, _, clock = heap[0]
            if not clock._running or wake != clock._wake:
                heapq.heappop(heap)
                continue
            if clock.gate is not None or clock._holding:
                return  # a gated (or held) clock ticks at its deadline, not before
            heapq.heappop(heap)
            clock._catch_up(now + EARLY)
            clock._tick(max(loop.time(), clock._deadline))
            clock._plan()
            heapq.heappush(heap, (clock._wake, next(self._seq), clock))

    def release(self) -> None:
        """Run the held ticks now: a request was just booked, so its reply is a service time
        away, the best moment the tick will get (even if it is longer than that)."""
        held, self.held = self.held, set()
        for clock in held:
            now = self.loop.time()
            if clock._running and clock._due() <= now:
                clock._catch_up(now)
                if clock._deadline <= now:
                    clock._tick(self.loop.time())
                clock._coasting = 0
                self.push(clock)


_WHEELS: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, _Wheel] = weakref.WeakKeyDictionary()


def _wheel(loop: asyncio.AbstractEventLoop) -> _Wheel:
    wheel = _WHEELS.get(loop)
    if wheel is None:
        wheel = _WHEELS[loop] = _Wheel(loop)
    return wheel


_last_warning = -math.inf


def _warn_behind(late: float) -> None:
    """One warning per ``WARN_EVERY`` seconds for the whole process: a saturated cell of fifty
    robots would otherwise log fifty lines every half second."""
    global _last_warning
    now = time.monotonic()
    if now - _last_warning >= WARN_EVERY:
        _last_warning = now
        log.warning(
            "IPO clock %.0f ms behind; skipping ticks (the machine is too busy)", late * 1e3
        )


def release(loop: asyncio.AbstractEventLoop | None = None) -> None:
    """Run the ticks held by their gate on ``loop`` (default: the running loop) if they may
    run now; the latency worker calls it right after booking a request."""
    wheel = _WHEELS.get(loop if loop is not None else asyncio.get_running_loop())
    if wheel is not None and wheel.held:
        wheel.release()


class IpoClock:
    """Calls ``callback()`` once per interpolation cycle until :meth:`stop`."""

    def __init__(
        self,
        callback: Callable[[], None],
        *,
        ipo: float = 0.012,
        speed: float = 1.0,
        phase: float = 0.0,
        gate: Callable[[float], bool] | None = None,
        max_hold: float = 0.003,
        keep: int = 100_000,
        coast: int = 1,
        quiet: Callable[[], bool] | None = None,
    ) -> None:
        if ipo <= 0 or speed <= 0:
            raise ValueError("ipo and speed must be positive")
        if not phase >= 0:
            raise ValueError("phase must be >= 0")
        if coast < 1:
            raise ValueError("coast must be >= 1")
        self.callback = callback
        self.ipo = ipo
        self.speed = speed
        #: Wall seconds the deadline grid is shifted by (robots of a cell spread their ticks).
        self.phase = phase
        #: ``gate(cost)``: may a tick expected to take ``cost`` seconds run now? None: always.
        self.gate = gate
        #: Longest wall time a gate may hold a due tick (s).
        self.max_hold = max_hold
        #: Running estimate of one tick's wall time (s), what the gate is asked about.
        self.cost = 0.0
        #: Ticks that ran late because the gate held them.
        self.held = 0
        self.ticks = 0
        self.overruns = 0
        #: Lateness of the most recent ticks (s), for the jitter benchmark; coasted ticks are
        #: deliberately late and not recorded.
        self.jitter: deque[float] = deque(maxlen=keep)
        #: At most this many ticks per wake-up while ``quiet()`` (1: never coast).
        self.coast = coast
        #: Did the tick that just ran change nothing wall time could show? (see the module)
        self.quiet = quiet
        #: Ticks run late on purpose, in a coast's catch-up.
        self.coasted = 0
        self._wheel: _Wheel | None = None
        self._running = False
        self._start = 0.0
        self._n = 0
        self._deadline = float("inf")
        self._wake = float("inf")
        self._holding = False
        #: Ticks slept through: due from ``_deadline`` on, run before the tick due at the wake.
        self._coasting = 0

    @property
    def period(self) -> float:
        """Wall seconds per tick."""
        return self.ipo / self.speed

    @property
    def running(self) -> bool:
        return self._running

    @property
    def deadline(self) -> float:
        """Loop time (``loop.time()``) at which the next tick is due (``inf`` when stopped
        before it started); while coasting, the first of the ticks slept through."""
        return self._deadline

    @property
    def coasting(self) -> int:
        """Ticks the clock is sleeping through right now (0: it wakes for the next tick)."""
        return self._coasting

    @property
    def wakeups(self) -> int:
        """Timer wake-ups so far of the event loop's shared clock timer (all the clocks of
        this loop; 0 before :meth:`start`): what coasting saves."""
        return self._wheel.fires if self._wheel is not None else 0

    def start(self) -> None:
        """Start ticking (on the running event loop); the first tick is one period away."""
        if self._running:
            return
        loop = asyncio.get_running_loop()
        self._wheel = _wheel(loop)
        self._start = loop.time() + self.phase
        self._n = 1
        self._coasting = 0
        self._deadline = self._start + self.period
        self._running = True
        self._wheel.push(self)

    async def stop(self) -> None:
        self._running = False
        if self._wheel is not None:
            self._wheel._arm()  # drops this clock's entry; no timer is left for an empty wheel

    def poll(self) -> None:
        """Bring the robot up to date: run the coasted ticks that are due, then the tick due
        now (if any), and end a coast (back to one wake-up per tick).

        The server calls this before answering each batch of requests: under load from many
        clients one event-loop pass answers every client before the timer callback gets its
        turn, so the tick would wait behind all of them. Polling here bounds the lateness by one
        client's batch instead. A coasting robot must poll before it is looked at or changed
        from outside its tick (see the module).
        """
        wheel = self._wheel
        if wheel is None or not self._running:
            return
        coasting = self._coasting
        now = wheel.loop.time()
        if now < self._deadline and not coasting:
            return
        if coasting:
            self._catch_up(now)  # coasted ticks ran late on purpose: no gate for them
            self._coasting = 0
        if now >= self._deadline and self._may_tick(now):
            self._tick(now)
            wheel.held.discard(self)
        elif not coasting:
            return
        wheel.push(self)  # the entry of the old deadline (or wake) is stale now

    def settle(self) -> None:
        """Run the coasted ticks that are due and end the coast, but not a regular tick: for a
        reply computed at its latency deadline, which a regular tick must not delay (the
        coasted ticks of a robot at rest cost microseconds)."""
        if self._coasting and self._wheel is not None and self._running:
            self._catch_up(self._wheel.loop.time())
            self._wheel.push(self)

    def _due(self) -> float:
        """The deadline of the tick the clock wakes for (after the coasted ones)."""
        return self._deadline + self._coasting * self.period

    def _catch_up(self, limit: float) -> None:
        """Run the coasted ticks due by ``limit``, back to back; the coast ends."""
        while self._coasting and self._deadline <= limit and self._running:
            self._coasting -= 1
            self.coasted += 1
            self._tick(limit, coasted=True)
        self._coasting = 0

    def _plan(self) -> None:
        """After a regular tick: coast through the next ticks if it was quiet, else wake for
        the next one."""
        k = 0
        if self.coast > 1 and self.quiet is not None and self.quiet():
            k = min(self.coast - 1, int(COAST_MAX / self.period))
        self._coasting = k
        self._wake = self._deadline + k * self.period

    def _may_tick(self, now: float) -> bool:
        gate = self.gate
        if gate is None or now - self._due() >= self.max_hold:
            return True
        return gate(self.cost)

    def _tick(self, now: float, *, coasted: bool = False) -> None:
        late = now - self._deadline
        if late > MAX_BEHIND:
            self.overruns += 1
            _warn_behind(late)
            self._start, self._n = now, 0
        if not coasted:
            self.jitter.append(max(late, 0.0))
        if self._holding:
            self.held += 1
            self._holding = False
        self.ticks += 1
        self._n += 1
        self._deadline = self._start + self._n * self.period
        t0 = time.thread_time()
        try:
            self.callback()
        except Exception:  # a bug in one tick must not stop the robot's clock for good
            log.exception("IPO tick failed")
        # CPU time, not wall time: a tick the OS preempted on a busy machine is no more work
        spent = time.thread_time() - t0
        # quick to learn an expensive tick (a motion starts), slower to forget it
        self.cost = spent if spent > self.cost else 0.8 * self.cost + 0.2 * spent

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
