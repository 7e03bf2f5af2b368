"""The latency model's parts as units: service-time distributions, profiles and their
parsing, the single worker's arithmetic, the running leads, the deadline timer's life cycle and
the service queue's bookkeeping.

No test here measures a delay against a fixed number of milliseconds: deadlines are checked as
arithmetic (the scheduler is pure) and waits only from below ("never early"), so a loaded
machine cannot fail them.
"""

from __future__ import annotations

import asyncio
import math
import random
import statistics
import time

import pytest

from kukavarproxy_emu import latency
from kukavarproxy_emu.latency import (
    PROFILES,
    DeadlineTimer,
    LatencyProfile,
    Scheduler,
    ServiceQueue,
    ServiceTime,
    resolve_profile,
)


# --- distributions ---------------------------------------------------------------------------------
@pytest.mark.parametrize("field", ["floor", "median", "sigma"])
def test_service_time_refuses_negative_parameters(field: str) -> None:
    good = {"floor": 0.0, "median": 0.0, "sigma": 0.0}
    ServiceTime(**good)  # zeros are fine
    with pytest.raises(ValueError, match=r"^service time parameters must not be negative$"):
        ServiceTime(**{**good, field: -1e-9})


def test_service_time_constant_cases_and_moments() -> None:
    rng = random.Random(1)
    assert ServiceTime(0.001, 0.002).sample(rng) == 0.003  # sigma 0: constant
    assert ServiceTime(0.001, 0.0, 0.5).sample(rng) == 0.001  # median 0: the floor alone
    assert len({ServiceTime(0.0, 0.002, 1.0).sample(rng) for _ in range(5)}) == 5  # random
    st = ServiceTime(0.001, 0.002, 0.4)
    assert st.total_median == pytest.approx(0.003)
    assert st.mean == pytest.approx(0.001 + 0.002 * math.exp(0.08))
    samples = [st.sample(rng) for _ in range(20_000)]
    assert min(samples) > 0.001  # never below the floor
    assert statistics.median(samples) == pytest.approx(0.003, rel=0.02)
    assert statistics.fmean(samples) == pytest.approx(st.mean, rel=0.02)


def test_documented_profiles_are_fitted_to_median_mean_and_floor() -> None:
    kvp = PROFILES["kvp"]
    assert kvp.read.floor == pytest.approx(0.0015) and kvp.write.floor == pytest.approx(0.0015)
    assert kvp.read.total_median == pytest.approx(0.0023)
    assert kvp.read.mean == pytest.approx(0.0026)
    assert kvp.write.total_median == pytest.approx(0.0033)
    assert kvp.write.mean == pytest.approx(0.0036)
    assert kvp.stall_probability == pytest.approx(2e-4)
    thesis = PROFILES["thesis"]
    assert thesis.read.floor == 0.0 and thesis.read.total_median == pytest.approx(0.0042)
    assert thesis.write.mean == pytest.approx(0.0043) and thesis.stall_probability == 0.0


def test_fit_takes_median_mean_and_floor_in_milliseconds() -> None:
    st = latency._fit(2.3, 2.6, 1.5)  # the kvp read profile's figures
    assert st.floor == pytest.approx(0.0015)
    assert st.median == pytest.approx(0.0008)  # the body above the floor
    assert st.sigma == pytest.approx(math.sqrt(2.0 * math.log(1.1 / 0.8)))
    assert st.total_median == pytest.approx(0.0023) and st.mean == pytest.approx(0.0026)
    no_floor = latency._fit(4.2, 4.3, 0.0)
    assert no_floor.floor == 0.0 and no_floor.mean == pytest.approx(0.0043)


def test_profile_samples_its_kind_and_adds_stalls_in_their_range() -> None:
    prof = LatencyProfile("t", ServiceTime(0.001, 0.0), ServiceTime(0.005, 0.0))
    rng = random.Random(2)
    assert prof.sample("read", rng) == 0.001 and prof.sample("write", rng) == 0.005
    stalling = LatencyProfile(
        "s", prof.read, prof.write, stall_probability=1.0, stall_min=0.030, stall_max=0.600
    )
    extra = [stalling.sample("read", rng) - 0.001 for _ in range(3000)]
    assert 0.030 <= min(extra) and max(extra) <= 0.600
    # log-uniform: as many stalls below the geometric middle (~134 ms) as above it
    middle = math.sqrt(0.030 * 0.600)
    below = sum(e < middle for e in extra) / len(extra)
    assert 0.45 < below < 0.55


def test_fixed_profile() -> None:
    prof = LatencyProfile.fixed(0.0025)
    assert prof.name == "fixed:0.0025"
    rng = random.Random(3)
    assert prof.sample("read", rng) == 0.0025 == prof.sample("write", rng)
    assert prof.stall_probability == 0.0


def test_resolve_profile_forms_and_errors() -> None:
    custom = LatencyProfile.fixed(0.1)
    assert resolve_profile(custom) is custom
    assert resolve_profile("") is None and resolve_profile("  None ") is None
    assert resolve_profile(" Thesis ") is PROFILES["thesis"]
    zero = resolve_profile("fixed:0")
    assert zero is not None and zero.sample("read", random.Random()) == 0.0
    with pytest.raises(ValueError, match=r"^bad fixed latency 'fixed:x': expected fixed:SECONDS$"):
        resolve_profile("fixed:x")
    for bad in ("fixed:-0.001", "fixed:nan"):
        with pytest.raises(ValueError, match=r"seconds must be >= 0$"):
            resolve_profile(bad)
    with pytest.raises(
        ValueError,
        match=r"^unknown latency profile 'fast' \(choose from none, kvp, thesis, fixed:SECONDS\)$",
    ):
        resolve_profile("fast")


# --- the single worker -----------------------------------------------------------------------------
def test_scheduler_weight_books_that_many_service_times() -> None:
    sched = Scheduler(LatencyProfile.fixed(0.002), random.Random(0))
    assert sched.free_at == -math.inf  # idle from the start
    assert sched.reserve("read", 1.0, weight=3) == pytest.approx(1.006)
    assert sched.reserve("write", 1.0) == pytest.approx(1.008)  # queued behind it


def test_answered_frees_the_worker_only_for_its_own_last_booking() -> None:
    sched = Scheduler(LatencyProfile.fixed(0.002), random.Random(0))
    d = sched.reserve("read", 0.0)
    sched.answered(d, d + 0.001)  # answered late: the worker was busy until its deadline
    assert sched.free_at == d
    d2 = sched.reserve("read", 0.0)
    assert d2 == pytest.approx(d + 0.002)
    sched.answered(d, d - 0.001)  # an older deadline: the chain behind it stays
    assert sched.free_at == d2
    sched.answered(d2, d2 - 0.0004)
    assert sched.free_at == pytest.approx(d2 - 0.0004)


def test_running_lead_is_the_capped_median_of_a_window() -> None:
    lead = latency._RunningLead(cap=0.01, window=3)
    assert lead.value == 0.0
    lead.add(0.004)
    assert lead.value == 0.004
    lead.add(0.001)
    lead.add(0.002)
    assert lead.value == pytest.approx(0.002)  # median of 4, 1, 2 ms
    lead.add(0.003)  # the 4 ms one leaves the window: median of 1, 2, 3
    assert lead.value == pytest.approx(0.002)
    lead.add(0.05)
    lead.add(0.06)
    assert lead.value == 0.01  # capped


# --- the timer ----------------------------------------------------------------------------------------
async def test_timer_returns_at_once_for_a_passed_deadline_without_a_thread() -> None:
    timer = DeadlineTimer()
    await timer.wait_until(time.monotonic() - 1.0)
    assert timer._thread is None and timer.lead == 0.0


async def test_timer_is_never_early_and_its_thread_stops_when_idle() -> None:
    timer = DeadlineTimer()
    timer.IDLE = 0.05  # instance override of the idle period
    for _ in range(5):
        deadline = time.monotonic() + 0.002
        await timer.wait_until(deadline)
        assert time.monotonic() >= deadline - DeadlineTimer.MAX_LEAD
    assert 0.0 <= timer.lead <= DeadlineTimer.MAX_LEAD
    # what it learnt are wake-up delays (seconds after the aim), not clock readings
    assert all(-1e-3 < delay < 10.0 for delay in timer._lead._seen)
    thread = timer._thread
    assert thread is not None and thread.daemon and thread.name == "kvp-latency-timer"
    await asyncio.to_thread(thread.join, 30.0)  # it ends by itself after IDLE seconds idle
    assert not thread.is_alive() and timer._thread is None
    await timer.wait_until(time.monotonic() + 0.001)  # and starts again on demand
    assert timer._thread is not None


async def test_timer_skips_a_cancelled_waiter() -> None:
    timer = DeadlineTimer()
    waiter = asyncio.ensure_future(timer.wait_until(time.monotonic() + 0.01))
    await asyncio.sleep(0)
    waiter.cancel()
    with pytest.raises(asyncio.CancelledError):
        await waiter
    later = time.monotonic() + 0.02
    await timer.wait_until(later)  # the timer thread went on past the cancelled future
    assert time.monotonic() >= later - DeadlineTimer.MAX_LEAD


# --- the service queue ---------------------------------------------------------------------------------
async def test_queue_books_from_the_arrival_and_keeps_its_books() -> None:
    prof = LatencyProfile("t", ServiceTime(0.05, 0.0), ServiceTime(0.07, 0.0))
    queue = ServiceQueue(prof, random.Random(0))
    assert queue.profile is prof
    assert queue.late.maxlen == 10_000  # bounded memory of reply lateness
    now = time.monotonic()
    # bytes read 1 s ago: the deadline passed long since, the reply is computed at once
    assert await queue.run("write", lambda: "x", arrival=now - 1.0) == "x"
    # a write's service time, not a read's (the clock reads ~1e5 s: compare the difference)
    assert queue.scheduler.free_at - (now - 1.0) == pytest.approx(0.07, abs=1e-9)
    assert queue.served == 1 and list(queue.pending) == []
    assert queue.last_reply >= now and len(queue.late) == 1 and 0.9 < queue.late[0] < 1.5
    # an arrival in the future is taken as now: never a reply before its service time
    start = time.monotonic()
    await queue.run("write", lambda: None, arrival=start + 10.0, weight=2)
    assert time.monotonic() - start >= 0.1 - DeadlineTimer.MAX_LEAD - latency.MAX_COMPUTE_LEAD
    assert queue.served == 2


async def test_queue_publishes_pending_deadlines_while_waiting() -> None:
    queue = ServiceQueue(LatencyProfile.fixed(0.2), random.Random(0))
    task = asyncio.ensure_future(queue.run("read", lambda: 1))
    await asyncio.sleep(0.01)
    assert len(queue.pending) == 1 and queue.pending[0] > time.monotonic()
    assert queue in latency._QUEUES[asyncio.get_running_loop()]
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert list(queue.pending) == [] and queue.served == 0  # cancelled: booked, never served
    # nothing pending and no reply ever sent: the worker is idle, a tick may run
    assert latency.tick_gate(asyncio.get_running_loop())(0.001)


async def test_queue_with_a_random_profile_and_its_computing_lead() -> None:
    queue = ServiceQueue(PROFILES["kvp"], random.Random(11))
    twin = Scheduler(PROFILES["kvp"], random.Random(11))
    past = time.monotonic() - 10.0
    for k in range(5):
        await queue.run("read", lambda: None, arrival=past + k)
        # the queue's scheduler draws from the rng it was given: the same deadlines as a twin
        assert queue.scheduler.free_at == pytest.approx(twin.reserve("read", past + k))
    # computing "None" takes microseconds: the lead stays far below its cap
    assert queue._compute.value < latency.MAX_COMPUTE_LEAD
    assert queue._compute._seen.maxlen == DeadlineTimer.WINDOW


async def test_a_reply_computed_early_frees_the_worker_then() -> None:
    queue = ServiceQueue(LatencyProfile.fixed(1.0), random.Random(0))
    queue._compute.value = 0.4  # replies take 0.4 s to compute: the wait aims that much early
    t0 = time.monotonic()
    await queue.run("read", lambda: None, arrival=t0)
    # booked until t0 + 1.0, answered ~0.4 s before: the next request need not wait for it
    assert queue.scheduler.free_at < t0 + 1.0 - 0.1
    assert queue.scheduler.free_at <= queue.last_reply


async def test_booking_a_request_releases_the_held_ticks() -> None:
    from kukavarproxy_emu.motion import IpoClock
    from kukavarproxy_emu.motion import clock as motion_clock

    ticks: list[float] = []
    clock = IpoClock(lambda: ticks.append(time.monotonic()), ipo=0.02, max_hold=30.0)
    clock.gate = lambda cost: False  # a reply is always imminent: every tick is held
    clock.start()
    try:
        loop = asyncio.get_running_loop()

        def held() -> bool:
            wheel = motion_clock._WHEELS.get(loop)
            return wheel is not None and bool(wheel.held)

        async with asyncio.timeout(10.0):
            while not held():  # noqa: ASYNC110 - the wheel has no event to wait on
                await asyncio.sleep(0.005)  # until the tick is due and held
        assert ticks == []
        queue = ServiceQueue(LatencyProfile.fixed(0.0), random.Random(0))
        await queue.run("read", lambda: None)  # the booking runs the held tick
        assert len(ticks) >= 1 and clock.held >= 1
    finally:
        await clock.stop()


def test_timer_remembers_a_bounded_window_of_wake_ups() -> None:
    assert DeadlineTimer()._lead._seen.maxlen == DeadlineTimer.WINDOW


async def test_tick_gate_keeps_one_and_a_half_ticks_and_a_margin_before_a_reply() -> None:
    loop = asyncio.get_running_loop()
    queue = ServiceQueue(LatencyProfile.fixed(5.0), random.Random(0))
    task = asyncio.ensure_future(queue.run("read", lambda: None))
    try:
        async with asyncio.timeout(10.0):
            while not queue.pending:  # noqa: ASYNC110 - booked inside run(): no event
                await asyncio.sleep(0)
        gate = latency.tick_gate(loop)
        remaining = queue.pending[0] - time.monotonic()  # ~5 s; only shrinks from here on
        # a tick whose 1.5-fold cost leaves less than the margin before the reply is held
        assert not gate((remaining - latency.TICK_MARGIN / 2) / 1.5)
        assert not gate(remaining)
        assert gate((remaining - 2.0) / 1.5)  # 3 s of 1.5-fold cost before a 5 s reply: runs
        # a tick costing half the time left: 1.5-fold it fits before the reply and runs
        assert gate(remaining / 2)
    finally:
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
