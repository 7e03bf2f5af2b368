"""One robot cannot take the gateway's event loop: the value size cap, the parse slices and
the per-robot budget (gateway/budget.py), alone and with a healthy robot beside two fake ones.

The fake robots are deliberately broken peers (:class:`pyopenshowvar.testing.FakeProxy`): one
answers every read with a ~60 KB nested STRUC, one with ~3 KB ones (under the cap, costly to
parse); the healthy robot is a real emulator.
"""

from __future__ import annotations

import asyncio
import logging
import time

import pytest

pytest.importorskip("asyncua")
from pyopenshowvar_apps.gateway.abuse import hostile_text
from pyopenshowvar_apps.gateway.budget import MAX_VALUE_CHARS, SHARE, SLICE, WorkBudget
from pyopenshowvar_apps.gateway.cell import CellError, parse_cell
from pyopenshowvar_apps.gateway.server import Gateway

from kukavarproxy_emu import Emulator, EmulatorConfig
from pyopenshowvar.protocol import Mode, Request
from pyopenshowvar.testing import FakeProxy, answer


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_parsing_hands_the_loop_back_after_each_slice() -> None:
    budget = WorkBudget("r", slice_=0.002, clock=Clock())
    budget.begin()
    budget.charge(0.0019)
    assert not budget.should_yield()
    budget.charge(0.0001)  # 2 ms in one go: yield
    assert budget.should_yield()
    budget.charge(0.001)  # the slice started anew
    assert not budget.should_yield()
    assert budget.used == pytest.approx(0.003)
    budget.begin()
    assert budget.used == 0.0
    budget.charge(0.0015)
    assert not budget.should_yield()  # begin() started a new slice too


def test_a_poll_over_budget_delays_the_next_one(caplog: pytest.LogCaptureFixture) -> None:
    budget = WorkBudget("r9", share=0.05, clock=Clock())
    budget.begin()
    budget.charge(0.005)  # 5 ms of a 100 ms period: exactly 5 %
    assert budget.earliest_next(10.0, 0.1) == 10.0
    budget.charge(0.001)  # 6 ms: the next poll 120 ms after this one started
    with caplog.at_level(logging.WARNING, logger="pyopenshowvar_apps.gateway.budget"):
        assert budget.earliest_next(10.0, 0.1) == pytest.approx(10.12)
        assert budget.earliest_next(11.0, 0.1) == pytest.approx(11.12)
    warnings = [r.getMessage() for r in caplog.records]
    assert len(warnings) == 1 and "robot r9" in warnings[0] and "6 ms" in warnings[0]
    budget.reset_warning()  # a new connection warns again
    with caplog.at_level(logging.WARNING, logger="pyopenshowvar_apps.gateway.budget"):
        budget.earliest_next(12.0, 0.1)
    assert len(caplog.records) == 2


def test_a_poll_exactly_at_its_budget_is_not_delayed(caplog: pytest.LogCaptureFixture) -> None:
    """At most SHARE of the time until the next poll: exactly that share is within budget
    (numbers exact in binary, so the comparison is at equality)."""
    budget = WorkBudget("r", share=0.5, clock=Clock())
    budget.begin()
    budget.charge(0.25)  # a quarter second of a half-second period at a 50 % share
    with caplog.at_level(logging.WARNING, logger="pyopenshowvar_apps.gateway.budget"):
        assert budget.earliest_next(10.0, 0.5) == 10.0
    assert not caplog.records


def test_the_budget_defaults_are_the_documented_ones() -> None:
    budget = WorkBudget("r")
    assert (budget.share, budget.slice, budget.clock) == (SHARE, SLICE, time.thread_time)
    # a new robot's budget has spent nothing yet: no slice is due, the next poll is on time
    assert budget.used == 0.0 and not budget.should_yield()
    assert budget.earliest_next(5.0, 0.1) == 5.0
    assert (SHARE, SLICE) == (0.05, 0.002)


def test_the_value_cap_is_configurable_within_bounds() -> None:
    def robot(**kw: object) -> dict[str, object]:
        return {"robot": [{"name": "r", "host": "127.0.0.1", **kw}]}

    assert parse_cell(robot()).robots[0].max_value_chars == MAX_VALUE_CHARS == 4096
    assert parse_cell(robot(max_value_chars=256)).robots[0].max_value_chars == 256
    assert parse_cell(robot(max_value_chars=65535)).robots[0].max_value_chars == 65535
    for bad in (255, 65536, 4096.0, True, "4096"):
        with pytest.raises(CellError, match="max_value_chars"):
            parse_cell(robot(max_value_chars=bad))


def _fake(size: int) -> FakeProxy:
    async def handler(req: Request, writer: asyncio.StreamWriter, n: int) -> None:
        value = hostile_text(n, size).encode() if req.mode == Mode.READ else None
        writer.write(answer(req, value))
        await writer.drain()

    return FakeProxy(handler)


def _run_queue_wait() -> float:
    """Seconds this thread (the event loop's) has waited for a core so far: the second field
    of its Linux schedstat."""
    with open("/proc/thread-self/schedstat") as f:
        return int(f.read().split()[1]) / 1e9


@pytest.mark.timeout(60)
async def test_fake_robots_with_huge_or_costly_values_do_not_starve_a_healthy_one(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="pyopenshowvar_apps.gateway")
    config = EmulatorConfig(port=0, discovery=False, idle_timeout=0, plant="ideal")
    async with Emulator(config) as emu, _fake(60_000) as huge, _fake(3_000) as heavy:
        cell = parse_cell(
            {
                "cell": {"endpoint": "opc.tcp://127.0.0.1:0"},
                "robot": [
                    {"name": "good", "host": "127.0.0.1", "port": emu.port, "poll_hz": 20},
                    {"name": "huge", "host": "127.0.0.1", "port": huge, "poll_hz": 50},
                    {"name": "heavy", "host": "127.0.0.1", "port": heavy, "poll_hz": 50},
                ],
            }
        )
        async with Gateway(cell) as gw:
            good, big, costly = (gw.pollers[n] for n in ("good", "huge", "heavy"))
            deadline = time.monotonic() + 20
            while costly.polls < 2 or good.polls < 20:
                assert time.monotonic() < deadline, (good.polls, costly.polls, big.last_error)
                await asyncio.sleep(0.05)
            polls = (good.polls, costly.polls)
            started, waited = time.monotonic(), _run_queue_wait()
            await asyncio.sleep(1.0)
            elapsed = time.monotonic() - started
            # the healthy robot's rate over the time the event loop had a core or did not want
            # one: while it waits for a core (a loaded machine) no robot is polled
            good_rate = (good.polls - polls[0]) / (elapsed - (_run_queue_wait() - waited))
            # the costly one's over the wall clock: its budget delays its polls on the loop's
            # clock, which a loaded machine only makes rarer
            costly_rate = (costly.polls - polls[1]) / elapsed
    # the 60 KB robot is never parsed: refused at its first reply, reconnected with backoff
    assert big.polls == 0 and not big.connected
    assert "over max_value_chars = 4096" in big.last_error
    # the costly one is polled far below its 50 Hz (its parsing is within 5 % of the loop)
    assert costly_rate < 10, costly_rate
    assert any("over its budget" in r.getMessage() for r in caplog.records)
    # while the healthy one keeps close to its 20 Hz
    assert good_rate > 10, good_rate
