"""`kvp monitor` through Textual's pilot: live values, watch list, writes, lost connection, fast
typing into its dialogs, flat plots of a robot at rest."""

from __future__ import annotations

import asyncio
import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rich.console import Console

pytest.importorskip("textual")

from pyopenshowvar_apps.monitor.app import MonitorApp
from pyopenshowvar_apps.monitor.dialogs import ConfirmDialog, InputDialog
from pyopenshowvar_apps.monitor.plot import levels_of, noise
from pyopenshowvar_apps.monitor.state import RobotState
from pyopenshowvar_apps.monitor.watchlist import WatchList
from pyopenshowvar_apps.names import is_motion_variable
from textual import events
from textual.widgets import DataTable, Input, TabbedContent


async def _settled(min_sleep: float = 0.0, max_sleep: float = 1.0) -> None:
    """Two short sleeps: time for the keys' messages to be handled, without Textual's guess."""
    await asyncio.sleep(0.01)
    await asyncio.sleep(0)


@pytest.fixture(autouse=True)
def no_idle_guess(monkeypatch: pytest.MonkeyPatch) -> None:
    """Key presses without Textual's wait for an idle process (shared with test_monitor_layout).

    After each key the pilot waits until the process' CPU time stops advancing, up to 1 s. The
    emulator these tests talk to runs in the same process, ticking its robot and plant, so the
    process is never idle: every key cost a second and the file ran for a minute and a half.
    Each test waits for what it needs instead (``until``), so only that guess is replaced.
    """
    import textual.app

    monkeypatch.setattr(textual.app, "wait_for_idle", _settled)


async def until(pilot: Any, cond: Callable[[], bool], timeout: float = 8.0) -> None:
    """Wait until ``cond()`` holds, letting the app run (shared with test_monitor_layout)."""
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not cond():
        if loop.time() > end:
            raise AssertionError("condition not met in time")
        await pilot.pause(0.05)


def make_app(port: int, tmp_path: Path, **kw: Any) -> MonitorApp:
    return MonitorApp(
        "127.0.0.1", port, timeout=0.5, hz=10, watch_file=tmp_path / "watch.json", **kw
    )


def joints_text(app: MonitorApp) -> str:
    return str(app.query_one("#joints").plain)  # type: ignore[attr-defined]


async def test_values_appear_and_update(ideal_emulator: Any, tmp_path: Path) -> None:
    # the ideal plant: this test sets $AXIS_ACT itself, which a dynamic plant overwrites
    emulator = ideal_emulator
    app = make_app(emulator.port, tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await until(pilot, lambda: app.state.updates > 0 and "-190…45" in joints_text(app))
        assert "Nm" in joints_text(app)
        assert app.state.pose.get("S") == 2 or app.state.pose  # pose arrived
        assert app.state.override == 100
        assert "connected" in app.status_text().plain

        def moved() -> bool:  # re-set each time: a motion program may also drive $AXIS_ACT
            emulator.store.set_system("$AXIS_ACT.A1", 12.5)
            return "A1 12.50" in joints_text(app)

        await until(pilot, moved)
        emulator.store.set_system("$OV_PRO", 37)
        await until(pilot, lambda: app.state.override == 37)
        assert "override 37 %" in app.query_one("#program").plain  # type: ignore[attr-defined]
        assert len(app.state.joint_history[0]) > 2  # the plots have history
        await pilot.press("2")
        await until(pilot, lambda: "12.5" in str(app.query_one("#joints-A1-label").render()))
        await pilot.press("q")


async def test_add_remove_watch_is_saved_and_restored(emulator: Any, tmp_path: Path) -> None:
    app = make_app(emulator.port, tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await until(pilot, lambda: app.state.updates > 0)
        await pilot.press("a")
        await until(pilot, lambda: isinstance(app.screen, InputDialog))
        app.screen.query_one(Input).value = "$ov_jog"
        await pilot.press("enter")
        await until(pilot, lambda: app.state.watch.get("$ov_jog") == "100")
        table = app.query_one("#watch-table", DataTable)
        assert table.row_count == 3
        saved = json.loads((tmp_path / "watch.json").read_text())
        assert saved["watch"] == ["MYAXIS", "$OV_PRO", "$ov_jog"]
        # remove the first row (MYAXIS)
        table.move_cursor(row=0)
        await pilot.press("d")
        assert app.watchlist.names == ["$OV_PRO", "$ov_jog"]
        assert json.loads((tmp_path / "watch.json").read_text())["watch"] == ["$OV_PRO", "$ov_jog"]
    assert WatchList.load(tmp_path / "watch.json").names == ["$OV_PRO", "$ov_jog"]


async def test_write_asks_before_a_motion_variable(emulator: Any, tmp_path: Path) -> None:
    WatchList(tmp_path / "watch.json", ["MYINT", "MYAXIS"]).save()
    app = make_app(emulator.port, tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await until(pilot, lambda: app.state.watch.get("MYINT") == "0")
        table = app.query_one("#watch-table", DataTable)
        # a plain global: no confirmation
        table.move_cursor(row=0)
        await pilot.press("e")
        await until(pilot, lambda: isinstance(app.screen, InputDialog))
        assert app.screen.query_one(Input).value == "0"
        app.screen.query_one(Input).value = "41"
        await pilot.press("enter")
        await until(pilot, lambda: emulator.store.read("MYINT") == "41")
        await until(pilot, lambda: app.state.watch.get("MYINT") == "41")
        # a motion variable: confirmation, "n" cancels
        table.move_cursor(row=1)
        await pilot.press("e")
        await until(pilot, lambda: isinstance(app.screen, InputDialog))
        app.screen.query_one(Input).value = "{A1 5.0}"
        await pilot.press("enter")
        await until(pilot, lambda: isinstance(app.screen, ConfirmDialog))
        await pilot.press("n")
        await pilot.pause(0.2)
        assert emulator.store.read("MYAXIS.A1") == "0.0"
        # ... and "y" writes
        await pilot.press("e")
        await until(pilot, lambda: isinstance(app.screen, InputDialog))
        app.screen.query_one(Input).value = "{A1 5.0}"
        await pilot.press("enter")
        await until(pilot, lambda: isinstance(app.screen, ConfirmDialog))
        await pilot.press("y")
        await until(pilot, lambda: emulator.store.read("MYAXIS.A1") == "5.00000")


async def test_lost_connection_is_shown_and_recovered(
    emulator_factory: Any, tmp_path: Path
) -> None:
    emu = await emulator_factory()
    port = emu.port
    app = make_app(port, tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await until(pilot, lambda: app.connected)
        await emu.close()
        await until(pilot, lambda: not app.connected)
        assert "DISCONNECTED" in app.status_text().plain
        await pilot.pause(0.3)
        emu2 = await emulator_factory(port=port)
        emu2.store.set_system("$OV_PRO", 61)
        await until(pilot, lambda: app.connected and app.state.override == 61, timeout=8)
        assert app.client.reconnects >= 1
        assert "connected" in app.status_text().plain


async def test_starts_without_a_proxy_and_keeps_retrying(tmp_path: Path) -> None:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    app = make_app(port, tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await until(pilot, lambda: bool(app.last_error))
        assert "DISCONNECTED" in app.status_text().plain and str(port) in app.status_text().plain


def test_state_and_motion_list() -> None:
    state = RobotState()
    assert "$SOFTN_END[]" in state.names_to_read([])
    assert state.names_to_read(["$OV_PRO", "X"])[-1] == "X"
    assert is_motion_variable("MYAXIS") and is_motion_variable("mye6array[3].A1")
    assert is_motion_variable("$OV_PRO") and not is_motion_variable("MYINT")


def test_kvp_monitor_emulate_command_runs_in_80x24(tmp_path: Path) -> None:
    """The real command in a pseudo-terminal: a live embedded robot, then q quits cleanly."""
    import os
    import sys

    pexpect = pytest.importorskip("pexpect")
    kvp = str(Path(sys.executable).with_name("kvp"))
    env = {**os.environ, "KVP_MONITOR_FILE": str(tmp_path / "w.json"), "TERM": "xterm-256color"}
    child = pexpect.spawn(
        kvp, ["monitor", "--emulate"], env=env, encoding="utf-8", timeout=15, dimensions=(24, 80)
    )
    child.expect_exact("connected")
    child.expect_exact("Nm")
    child.send("q")
    child.expect(pexpect.EOF)
    child.close()
    assert child.exitstatus == 0


# ----------------------------------------------------- fast typing, plots at rest


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
        await until(pilot, lambda: app.screen is app.screen_stack[0], timeout=20.0)
        burst(app, "a", *"$OV_JOG", "enter")
        await until(pilot, lambda: app.watchlist.names == ["MYINT", "$OV_JOG"], timeout=20.0)
        # a read of $OV_JOG answered: any write the cancelled edit had sent went before it on
        # the same connection, so MYINT now shows whether Escape wrote (an event, not a pause)
        await until(pilot, lambda: app.state.watch.get("$OV_JOG") is not None, timeout=20.0)
        assert emulator.store.read("MYINT") == "79"


def test_the_noise_estimate_ignores_smooth_motion() -> None:
    rng = np.random.default_rng(3)
    still = 5.0 + rng.normal(0.0, 0.4, 200)
    ramp = np.linspace(0.0, 90.0, 200) + rng.normal(0.0, 0.4, 200)
    assert 0.3 < noise(list(still)) < 0.5 and 0.3 < noise(list(ramp)) < 0.5
    assert noise([1.0, 2.0]) == 0.0


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
