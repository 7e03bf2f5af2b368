"""kukavarproxy_emu.slices: long CPU work spread over event-loop iterations."""

from __future__ import annotations

import asyncio
import threading
import time

import pytest

from kukavarproxy_emu.slices import Checkpoint, run_sliced


def _burn(seconds: float, log: list[str], name: str) -> object:
    def work(checkpoint: Checkpoint) -> str:
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            checkpoint()
            log.append(name)
        return f"{name} done"

    return work


async def _ticks(stop: asyncio.Event) -> int:
    """Loop iterations that happened until ``stop`` was set."""
    n = 0
    while not stop.is_set():
        await asyncio.sleep(0)
        n += 1
    return n


async def test_the_loop_runs_between_slices_and_the_result_comes_back() -> None:
    log: list[str] = []
    stop = asyncio.Event()
    ticker = asyncio.create_task(_ticks(stop))
    result = await run_sliced(_burn(0.1, log, "a"))  # type: ignore[arg-type]
    stop.set()
    ticks = await ticker
    assert result == "a done"
    # 0.1 s of work in slices of SLICE (about 50, fewer on a loaded machine): the loop ran
    # between them, where one blocking call would let it run once
    assert ticks >= 5


async def test_calls_are_served_one_after_the_other_and_errors_are_raised() -> None:
    log: list[str] = []

    def fails(checkpoint: Checkpoint) -> None:
        checkpoint()
        raise ValueError("bad module")

    first = asyncio.create_task(run_sliced(_burn(0.03, log, "a")))  # type: ignore[arg-type]
    second = asyncio.create_task(run_sliced(_burn(0.03, log, "b")))  # type: ignore[arg-type]
    third = asyncio.create_task(run_sliced(fails))
    assert await first == "a done" and await second == "b done"
    with pytest.raises(ValueError, match="bad module"):
        await third
    # first come, first served: every step of "a" before any of "b"
    assert log.index("b") > len(log) - log[::-1].index("a") - 1


async def test_only_one_slice_per_loop_iteration_for_all_calls() -> None:
    tick = [0]
    ran: dict[int, set[str]] = {}

    async def count() -> None:
        while True:
            await asyncio.sleep(0)
            tick[0] += 1

    def work(name: str) -> object:
        def run(checkpoint: Checkpoint) -> None:
            end = time.perf_counter() + 0.03
            while time.perf_counter() < end:
                ran.setdefault(tick[0], set()).add(name)  # the iteration this slice runs in
                checkpoint()

        return run

    ticker = asyncio.create_task(count())
    await asyncio.gather(run_sliced(work("a")), run_sliced(work("b")))  # type: ignore[arg-type]
    ticker.cancel()
    assert len(ran) >= 4
    assert all(len(names) == 1 for names in ran.values()), ran


async def test_a_cancelled_caller_stops_the_work_at_its_next_checkpoint() -> None:
    steps: list[int] = []
    threads_before = threading.active_count()
    loop = asyncio.get_running_loop()
    started = asyncio.Event()

    def endless(checkpoint: Checkpoint) -> None:
        while True:
            steps.append(1)
            if len(steps) == 5:
                loop.call_soon_threadsafe(started.set)
            time.sleep(0.0005)
            checkpoint()

    task = asyncio.create_task(run_sliced(endless))
    await asyncio.wait_for(started.wait(), 5.0)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    for _ in range(100):  # the scheduler's next turn unwinds the worker
        await asyncio.sleep(0.001)
        if threading.active_count() <= threads_before:
            break
    assert threading.active_count() <= threads_before
    count = len(steps)
    await asyncio.sleep(0.02)
    assert len(steps) == count  # nothing runs any more
