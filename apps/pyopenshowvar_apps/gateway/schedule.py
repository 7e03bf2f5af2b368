"""When each robot of the gateway polls: a shared grid on the event loop's clock.

Every robot polls at ``(k + phase) * period`` (:func:`next_slot`): the gateway gives robots
one of a few phases, so a cell's polls are spread evenly over the period and the robots of one
slot wake in the same event-loop iteration (:func:`sleep_until` wakes at an absolute time).
"""

from __future__ import annotations

import asyncio
import math

__all__ = ["next_slot", "sleep_until"]


def next_slot(after: float, period: float, phase: float) -> float:
    """The first time later than ``after`` on the grid ``(k + phase) * period``.

    The grid is the event loop's clock, not the time a robot connected: robots given
    different phases (the gateway spreads them over a few slots) never poll in one burst, and
    robots sharing a slot wake at exactly the same instant, in one event-loop iteration. A
    late poll skips the slots it missed instead of bunching polls.
    """
    when = (math.floor(after / period - phase) + 1 + phase) * period
    if when - after < period * 1e-6:  # ``after`` on the grid itself, and rounded below it
        when += period
    return when


async def sleep_until(loop: asyncio.AbstractEventLoop, when: float) -> None:
    """``asyncio.sleep`` to an absolute time (asyncio.sleep adds the clock read at the call,
    a few microseconds apart for robots of one slot, which then wake one by one)."""
    waiter = loop.create_future()
    handle = loop.call_at(when, _wake, waiter)
    try:
        await waiter
    finally:
        handle.cancel()


def _wake(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)
