"""The monitor under fast typing and at rest: typed-ahead dialog input, flat noise plots."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from rich.console import Console

pytest.importorskip("textual")

from pyopenshowvar_apps.monitor.app import MonitorApp
from pyopenshowvar_apps.monitor.plot import levels_of
from pyopenshowvar_apps.monitor.watchlist import WatchList
from textual import events
from textual.widgets import TabbedContent


async def until(pilot: Any, cond: Callable[[], bool], timeout: float = 5.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not cond():
        if loop.time() > end:
            raise AssertionError("condition not met in time")
        await pilot.pause(0.05)


def drawn_columns(widget: Any) -> list[str]:
    """What a sparkline widget draws now, column by column (top to bottom)."""
    width, height = widget.size
    console = Console(width=width, height=height, color_system=None)
    lines = console.render_lines(widget.render(), console.options.update(height=height))
    rows = ["".join(segment.text for segment in line) for line in lines]
    return ["".join(row[x] for row in rows) for x in range(width)]


def burst(app: MonitorApp, *keys: str) -> None:
    """Keys posted all at once, as a fast typist's keys reach the app (pilot.press waits until
    each key was handled, which no terminal does)."""
    for key in keys:
        app.post_message(events.Key(key, key if len(key) == 1 else None))


async def test_fast_typing_into_the_edit_and_add_dialogs_loses_nothing(
    emulator: Any, tmp_path: Path
) -> None:
    WatchList(tmp_path / "w.json", ["MYINT"]).save()
    app = MonitorApp("127.0.0.1", emulator.port, timeout=1.0, hz=10, watch_file=tmp_path / "w.json")
    async with app.run_test(size=(80, 24)) as pilot:
        await until(pilot, lambda: app.state.watch.get("MYINT") == "0")
        await pilot.press("3")
        # e, the value and Enter in one burst, three times; "1"/"2"/"3" are also the tab keys
        for value in ("41", "312", "-23"):
            burst(app, "e", *value, "enter")
            await until(pilot, lambda v=value: emulator.store.read("MYINT") == v)  # type: ignore[misc]
            assert app.query_one(TabbedContent).active == "watch"
        # the first key replaces the value shown; Backspace deletes; Escape cancels
        burst(app, "e", "7", "8", "backspace", "9", "enter")
        await until(pilot, lambda: emulator.store.read("MYINT") == "79")
        burst(app, "e", "5", "escape")
        await pilot.pause(0.3)
        assert emulator.store.read("MYINT") == "79" and app.screen is app.screen_stack[0]
        burst(app, "a", *"$OV_JOG", "enter")
        await until(pilot, lambda: app.watchlist.names == ["MYINT", "$OV_JOG"])


def test_levels_draw_noise_flat_and_motion_full_height() -> None:
    noise = [12.0 + 0.3 * math.sin(1.7 * i) for i in range(200)]
    assert len(set(levels_of(noise, 2.0, 16))) == 1
    ramp = [float(i) for i in range(100)]
    assert levels_of(ramp, 2.0, 16) == sorted(levels_of(ramp, 2.0, 16))
    assert levels_of(ramp, 2.0, 16)[0] == 0 and levels_of(ramp, 2.0, 16)[-1] == 15
    # a change of a few resolution steps is drawn a few levels high, not the full height
    step = [0.0] * 50 + [6.0] * 50
    assert max(levels_of(step, 2.0, 16)) - min(levels_of(step, 2.0, 16)) == 3


async def test_plots_of_a_robot_at_rest_are_flat(emulator: Any, tmp_path: Path) -> None:
    """The dynamic plant publishes encoder and torque noise at rest: drawn flat, every axis."""
    app = MonitorApp("127.0.0.1", emulator.port, timeout=1.0, hz=50, watch_file=tmp_path / "w.json")
    async with app.run_test(size=(120, 40)) as pilot:
        # the history fills on the Robot tab (the plots draw only while they are shown)
        await until(pilot, lambda: app.state.updates > 0, timeout=15)
        await asyncio.sleep(0.5)  # the plant settles from its start (a transient, not noise)
        for history in (*app.state.joint_history, *app.state.torque_history):
            history.clear()
        await until(pilot, lambda: len(app.state.torque_history[0]) >= 20, timeout=20)
        noisy = max(app.state.torque_history[0]) - min(app.state.torque_history[0])
        assert noisy > 0.2  # there is noise to hide (σ ≈ 0.4 Nm on A1)
        await pilot.press("2")
        await pilot.pause(0.2)
        plots = list(app.query("#plot-panel Sparkline"))
        assert len(plots) == 12
        for plot in plots:
            columns = drawn_columns(plot)
            assert plot.size.height >= 2 and len(columns) == plot.size.width
            assert len(set(columns)) == 1, (plot.id, columns)
