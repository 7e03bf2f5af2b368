"""Latency model of the emulator: service-time distributions and the single proxy worker.

A real KUKAVARPROXY is one VB6 thread: every request of every client waits for the previous
one, and each request costs a CrossComm round trip of a few milliseconds (reference §2.5, §6).
This module reproduces that in three parts:

* :class:`LatencyProfile` is a pure sampler — ``sample(kind, rng) -> seconds`` — so tests can
  check its medians over many samples without sleeping;
* :class:`Scheduler` is the one global "proxy thread" as pure arithmetic: a request that arrives
  at ``t`` starts when the worker is free (``max(t, previous deadline)``) and is answered at an
  absolute deadline ``start + sample``; back-to-back requests chain, none is answered early;
* :class:`DeadlineTimer` wakes the event loop *at* a deadline. ``asyncio.sleep`` rounds its
  timeout up to the selector's 1 ms and wakes late by another fraction of a millisecond, which
  shifted every reply by ~1 ms (a paced client saw 3.5 ms instead of 2.3 ms); a timer thread
  sleeping on a monotonic condition wait is accurate to ~0.1 ms and costs nothing while idle.

:class:`ServiceQueue` ties them together for the server.

The profiles and their parameters are documented in ``docs/emulator.md``.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import math
import random
import statistics
import sys
import threading
import time
import weakref
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, TypeVar

__all__ = [
    "PROFILES",
    "DeadlineTimer",
    "Kind",
    "LatencyProfile",
    "Scheduler",
    "ServiceQueue",
    "ServiceTime",
    "resolve_profile",
    "tick_gate",
]

Kind = Literal["read", "write"]
T = TypeVar("T")


@dataclass(frozen=True, slots=True)
class ServiceTime:
    """``floor + LogNormal(ln(median), sigma)`` seconds; ``sigma == 0`` makes it constant."""

    floor: float
    median: float
    sigma: float = 0.0

    def __post_init__(self) -> None:
        if self.floor < 0 or self.median < 0 or self.sigma < 0:
            raise ValueError("service time parameters must not be negative")

    def sample(self, rng: random.Random) -> float:
        if self.median == 0.0 or self.sigma == 0.0:
            return self.floor + self.median
        return self.floor + rng.lognormvariate(math.log(self.median), self.sigma)

    @property
    def total_median(self) -> float:
        """Median of the whole distribution (the floor shifts the lognormal's median)."""
        return self.floor + self.median

    @property
    def mean(self) -> float:
        return self.floor + self.median * math.exp(self.sigma**2 / 2)


@dataclass(frozen=True, slots=True)
class LatencyProfile:
    """Service time per request kind, plus rare stalls (log-uniform in [stall_min, stall_max])."""

    name: str
    read: ServiceTime
    write: ServiceTime
    stall_probability: float = 0.0
    stall_min: float = 0.030
    stall_max: float = 0.600

    def sample(self, kind: Kind, rng: random.Random) -> float:
        """One service time in seconds for a ``"read"`` or ``"write"`` request."""
        seconds = (self.write if kind == "write" else self.read).sample(rng)
        if self.stall_probability and rng.random() < self.stall_probability:
            # Log-uniform: the field data has many 30-60 ms stalls and few near 600 ms.
            lo, hi = math.log(self.stall_min), math.log(self.stall_max)
            seconds += math.exp(rng.uniform(lo, hi))
        return seconds

    @classmethod
    def fixed(cls, seconds: float) -> LatencyProfile:
        """A constant service time for every request (tests of the global serialisation)."""
        constant = ServiceTime(floor=seconds, median=0.0)
        return cls(f"fixed:{seconds:g}", constant, constant)


def _fit(median: float, mean: float, floor: float) -> ServiceTime:
    """Lognormal body above ``floor`` with the given overall median and mean (milliseconds)."""
    body_median, body_mean = median - floor, mean - floor
    # For a lognormal, mean / median = exp(sigma² / 2).
    sigma = math.sqrt(2.0 * math.log(body_mean / body_median))
    return ServiceTime(floor / 1000.0, body_median / 1000.0, sigma)


PROFILES: dict[str, LatencyProfile] = {
    # KRC4 + KVP 9.0 as measured by ivareri/KUKAVARPROXY_tests (reference §6): reads median
    # 2.3 ms / mean 2.6 ms, writes median 3.3 ms / mean 3.6 ms, a ~1.5 ms CrossComm floor and
    # 30–600 ms stalls seen about once in 5000 requests.
    "kvp": LatencyProfile(
        "kvp",
        read=_fit(2.3, 2.6, 1.5),
        write=_fit(3.3, 3.6, 1.5),
        stall_probability=2e-4,
    ),
    # The JOpenShowVar chapter's "about 4–5 ms per access": median 4.2 ms, mean 4.3 ms.
    "thesis": LatencyProfile("thesis", read=_fit(4.2, 4.3, 0.0), write=_fit(4.2, 4.3, 0.0)),
}


def resolve_profile(spec: str | LatencyProfile | None) -> LatencyProfile | None:
    """``"none"``/None → None (no delay), a profile name, ``"fixed:SECONDS"`` or a profile."""
    if spec is None or isinstance(spec, LatencyProfile):
        return spec
    key = spec.strip().lower()
    if key in ("", "none"):
        return None
    if key.startswith("fixed:"):
        try:
            seconds = float(key.removeprefix("fixed:"))
        except ValueError:
            raise ValueError(f"bad fixed latency {spec!r}: expected fixed:SECONDS") from None
        if not seconds >= 0:
            raise ValueError(f"bad fixed latency {spec!r}: seconds must be >= 0")
        return LatencyProfile.fixed(seconds)
    try:
        return PROFILES[key]
    except KeyError:
        choices = ", ".join(["none", *PROFILES, "fixed:SECONDS"])
        raise ValueError(f"unknown latency profile {spec!r} (choose from {choices})") from None


class Scheduler:
    """Deadlines of the single proxy worker (pure: no clock, no sleeping).

    ``reserve(kind, arrival)`` is called when a request reaches the worker's queue, in arrival
    order. The worker starts it when it is free — at ``arrival`` if idle, else at the previous
    deadline — and answers it ``sample`` seconds later. So an isolated request's reply time is
    exactly its sample, whatever the client's pacing, and a busy worker's throughput is the
    profile's mean (no drift, no early reply).
    """

    def __init__(self, profile: LatencyProfile, rng: random.Random) -> None:
        self.profile = profile
        self.rng = rng
        self.free_at = -math.inf

    def reserve(self, kind: Kind, arrival: float, weight: int = 1) -> float:
        start = max(arrival, self.free_at)
        self.free_at = start + sum(self.profile.sample(kind, self.rng) for _ in range(weight))
        return self.free_at

    def answered(self, deadline: float, now: float) -> None:
        """The reply booked for ``deadline`` went out at ``now`` (a little early, when the timer
        compensates its overshoot): if nothing is booked after it, the worker is free now, so
        the client's next request does not wait for the rest of that deadline."""
        if self.free_at == deadline:
            self.free_at = min(deadline, now)


class _RunningLead:
    """How early to aim (s): the median of the last ``window`` observed delays, capped."""

    def __init__(self, cap: float, window: int) -> None:
        self.cap = cap
        self._seen: deque[float] = deque(maxlen=window)
        self.value = 0.0

    def add(self, delay: float) -> None:
        self._seen.append(delay)
        self.value = min(statistics.median(self._seen), self.cap)


class DeadlineTimer:
    """Completes asyncio futures at absolute ``time.monotonic()`` deadlines.

    One daemon thread waits on a condition with a timeout (a precise monotonic wait, unlike the
    selector's millisecond timeout) for the earliest deadline, then hands the future back to its
    loop with ``call_soon_threadsafe``, which wakes the loop at once. Waking a thread and then
    the loop still takes a little while (~0.1 ms on a quiet machine, more under load), so the
    timer measures that delay and aims early by its running median (overshoot compensation,
    at most ``MAX_LEAD``): the typical wake-up lands on the deadline instead of after it. The
    loop's own timer at the deadline is a backstop (a busy machine may schedule the thread
    late). The thread starts with the first deadline and stops after ``IDLE`` seconds idle.
    """

    IDLE = 5.0
    #: Never aim earlier than this before a deadline (s).
    MAX_LEAD = 0.0005
    #: Wake-ups the compensation's median is taken over.
    WINDOW = 64

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._heap: list[tuple[float, int, asyncio.AbstractEventLoop, asyncio.Future[None]]] = []
        self._seq = itertools.count()
        self._thread: threading.Thread | None = None
        #: How early the timer aims: the median delay of the recent wake-ups.
        self._lead = _RunningLead(self.MAX_LEAD, self.WINDOW)

    @property
    def lead(self) -> float:
        """How early the timer aims now (s)."""
        return self._lead.value

    async def wait_until(self, deadline: float) -> None:
        """Return at ``deadline`` (``time.monotonic()`` seconds); at once if it has passed."""
        aim = deadline - self.lead
        if aim <= time.monotonic():
            return
        loop = asyncio.get_running_loop()
        fut: asyncio.Future[None] = loop.create_future()
        with self._cond:
            heapq.heappush(self._heap, (aim, next(self._seq), loop, fut))
            if self._thread is None:
                self._thread = threading.Thread(
                    target=self._run, name="kvp-latency-timer", daemon=True
                )
                self._thread.start()
            self._cond.notify()
        # The loop's own timer as a backstop: on a busy machine, waking a second thread first
        # can take longer than the selector's millisecond; whichever comes first wins.
        backstop = loop.call_later(deadline - time.monotonic(), _wake, fut)
        try:
            await fut
        finally:
            backstop.cancel()
        self._lead.add(time.monotonic() - aim)

    def _run(self) -> None:
        with self._cond:
            while True:
                if not self._heap:
                    if not self._cond.wait(self.IDLE) and not self._heap:
                        self._thread = None
                        return
                    continue
                delay = self._heap[0][0] - time.monotonic()
                if delay > 0:
                    self._cond.wait(delay)
                    continue
                _, _, loop, fut = heapq.heappop(self._heap)
                try:
                    loop.call_soon_threadsafe(_wake, fut)
                except RuntimeError:  # the loop is closed: nobody waits any more
                    pass


def _wake(fut: asyncio.Future[None]) -> None:
    if not fut.done():  # a cancelled waiter (dropped connection) is simply skipped
        fut.set_result(None)


#: The process' timer: one thread serves every emulator and connection.
TIMER = DeadlineTimer()


class ServiceQueue:
    """The single proxy worker shared by every connection of one emulator.

    ``run`` books the request with the :class:`Scheduler` when it is handed over, waits for its
    deadline on the :class:`DeadlineTimer` and then computes the reply, so N busy clients each
    see about N times the single-client latency, as on the real controller, and a client's own
    pacing does not change the latency it sees.

    The simulated robot shares the event loop, so its IPO tick could make a reply late (a tick
    running at the deadline) or a request's deadline late (a tick running when the request
    arrives). The queues of a loop therefore publish their booked deadlines, :func:`tick_gate`
    lets a tick run only when the next reply is further away than the tick takes, and booking a
    request releases the ticks held meanwhile (``motion.clock.release``): they run in the
    shadow of the reply just booked, which is at least the profile's floor away.

    The profile's samples are round trips as a client measured them on a real controller, so
    the emulator's own part of a round trip is taken out of the wait, not added to it: the
    request is booked at the moment its bytes were read (``arrival``, before the worker task
    gets to it), and the timer aims the running median of the reply's computing time early,
    so the reply is handed to the socket at its deadline rather than that long after it.
    """

    def __init__(self, profile: LatencyProfile, rng: random.Random) -> None:
        self.profile = profile
        self.scheduler = Scheduler(profile, rng)
        self.served = 0
        #: Deadlines booked and not yet answered (time.monotonic()), earliest first.
        self.pending: deque[float] = deque()
        #: When the last reply was computed (time.monotonic()).
        self.last_reply = -math.inf
        self._loop: asyncio.AbstractEventLoop | None = None
        #: How late each recent reply was computed after its deadline (s; the benchmarks'
        #: view of what delays replies: a busy loop, a slow read).
        self.late: deque[float] = deque(maxlen=10_000)
        #: The lead taken from the recent computing times of a reply.
        self._compute = _RunningLead(MAX_COMPUTE_LEAD, DeadlineTimer.WINDOW)

    async def run(
        self,
        kind: Kind,
        compute: Callable[[], T],
        weight: int = 1,
        arrival: float | None = None,
    ) -> T:
        """Answer with ``compute()`` after ``weight`` sampled service times of ``kind``.

        ``weight`` > 1 is a request the controller serves with that many CrossComm calls in a
        row (a C3 Bridge read-multiple of N variables). ``arrival`` is when the request's bytes
        were read (``time.monotonic()``; default: now).
        """
        now = time.monotonic()
        start = now if arrival is None else min(arrival, now)
        deadline = self.scheduler.reserve(kind, start, weight)
        if self._loop is None:
            self._loop = asyncio.get_running_loop()
            _QUEUES.setdefault(self._loop, weakref.WeakSet()).add(self)
        self.pending.append(deadline)
        _release_ticks(self._loop)
        try:
            await TIMER.wait_until(deadline - self._compute.value)
        finally:
            self.pending.remove(deadline)
        woke = time.monotonic()
        self.scheduler.answered(deadline, woke)
        self.served += 1
        reply = compute()
        self.last_reply = done = time.monotonic()
        self.late.append(done - deadline)
        self._compute.add(done - woke)
        return reply


_QUEUES: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, weakref.WeakSet[ServiceQueue]] = (
    weakref.WeakKeyDictionary()
)
#: Never aim a reply earlier than this for its computing time (s): a slow reply (a whole array)
#: waits its full sample rather than let one outlier pull every reply early.
MAX_COMPUTE_LEAD = 0.0005
#: Room kept between a tick's expected end and the next reply (s).
TICK_MARGIN = 0.0003
#: A worker idle for less than this since its last reply expects the client's next request:
#: a tick waits for it (to run in its shadow) rather than delay its booking (s).
CLIENT_TURNAROUND = 0.003


def tick_gate(loop: asyncio.AbstractEventLoop) -> Callable[[float], bool]:
    """The gate of the IPO clocks on ``loop`` (see :class:`ServiceQueue`): ``gate(cost)`` is
    True when a tick taking ``cost`` seconds delays neither a reply nor a request's booking."""

    def gate(cost: float) -> bool:
        queues = _QUEUES.get(loop)
        if not queues:
            return True
        now = time.monotonic()
        earliest = min((q.pending[0] for q in queues if q.pending), default=None)
        if earliest is None:
            return all(now - q.last_reply >= CLIENT_TURNAROUND for q in queues)
        return earliest - now >= 1.5 * cost + TICK_MARGIN

    return gate


def _release_ticks(loop: asyncio.AbstractEventLoop) -> None:
    # late import: the motion package (numpy, the kernel) loads only when a robot runs
    clock = sys.modules.get("kukavarproxy_emu.motion.clock")
    if clock is not None:
        clock.release(loop)
