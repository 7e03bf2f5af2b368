"""`kvp monitor` (issue 14): keys act on what is seen selected, values are shown whole, the
layout fills 80×24 and 120×40, Ctrl-C quits, writes are checked (Textual pilot, real emulator)."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("textual")

from pyopenshowvar_apps.monitor.app import MonitorApp
from pyopenshowvar_apps.monitor.dialogs import InputDialog
from pyopenshowvar_apps.monitor.watchlist import WatchList
from rich.console import Console
from test_monitor import no_idle_guess, until  # noqa: F401 (no_idle_guess: autouse fixture)
from textual.widgets import DataTable, Input, TabbedContent

WATCH = ["MYAXIS", "$OV_PRO", "$POS_ACT", "MYINT"]


def make_app(port: int, tmp_path: Path) -> MonitorApp:
    WatchList(tmp_path / "watch.json", WATCH).save()
    return MonitorApp(
        "127.0.0.1",
        port,
        timeout=1.0,
        hz=2,  # every refresh keeps the pilot busy: few of them keep key presses fast
        watch_file=tmp_path / "watch.json",
    )


def shown_text(widget: Any) -> str:
    """What the detail pane shows, rendered at its own width."""
    console = Console(width=widget.content_size.width, record=True, file=io.StringIO())
    console.print(widget.shown)
    return console.export_text()


async def test_arrows_select_d_deletes_the_row_seen_and_the_pane_shows_it_whole(
    emulator_factory: Any, tmp_path: Path
) -> None:
    emulator = await emulator_factory(robot=False)
    emulator.store.set_system("$POS_ACT.X", 412.345612)
    app = make_app(emulator.port, tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await until(pilot, lambda: "$POS_ACT" in app.state.watch)
        await pilot.press("d")  # from the Robot tab: shows the list, deletes nothing
        assert app.query_one(TabbedContent).active == "watch"
        assert app.watchlist.names == WATCH
        table = app.query_one("#watch-table", DataTable)
        await until(pilot, lambda: app.focused is table)  # ↑/↓ work at once, no Tab needed
        await pilot.press("down", "down")
        assert table.cursor_row == 2
        # the pane below shows the selected struct whole at 80 columns
        detail = app.query_one("#watch-detail")
        await until(pilot, lambda: "$POS_ACT (E6POS)" in shown_text(detail))
        text = shown_text(detail)
        assert "…" not in text and "412.3456" in text
        for member in ("X", "Y", "Z", "A", "B", "C", "S", "T", "E1", "E6"):
            assert f" {member} " in f" {text} ".replace("\n", " "), member
        assert detail.region.bottom <= app.screen.region.bottom - 1  # above the footer
        await pilot.press("d")
        assert app.watchlist.names == ["MYAXIS", "$OV_PRO", "MYINT"]  # $POS_ACT, the row seen
        await pilot.press("up", "d")
        assert app.watchlist.names == ["MYAXIS", "MYINT"]
        await pilot.press("1", "3")  # back to the list: focus follows
        await until(pilot, lambda: app.focused is table)


async def test_the_layout_fills_80x24_and_120x40(emulator_factory: Any, tmp_path: Path) -> None:
    emulator = await emulator_factory(robot=False)
    app = make_app(emulator.port, tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await until(pilot, lambda: app.state.updates > 0)
        for (width, height), plot_rows, tabs in (((80, 24), 1, "321"), ((120, 40), 2, "21")):
            await pilot.resize_terminal(width, height)
            for tab in tabs:
                await pilot.press(tab)
                await pilot.pause(0.1)
                assert not app.screen.show_vertical_scrollbar, tab  # nothing below the fold
                pane = app.query_one(f"#{app.query_one(TabbedContent).active}")
                assert pane.region.bottom == height - 1 and pane.region.width == width, tab
                for widget in pane.query("*"):
                    assert widget.region.right <= width, widget
                if tab == "2":
                    assert app.query_one("#joints-A1").region.height == plot_rows
            joints, stats = app.query_one("#joints"), app.query_one("#stats")
            assert app.query_one("#right").region.right == width
            assert stats.region.bottom == height - 1  # the access-time panel takes what is left
            if width > 80:
                assert joints.region.width > 46 and stats.region.height > 10


async def test_ctrl_c_quits(emulator_factory: Any, tmp_path: Path) -> None:
    emulator = await emulator_factory(robot=False)
    app = make_app(emulator.port, tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await until(pilot, lambda: app.state.updates > 0)
        await pilot.press("ctrl+c")
        await pilot.pause(0.1)
        assert app.return_code == 0 and not app.is_running


async def test_writes_are_checked(emulator_factory: Any, tmp_path: Path) -> None:
    """A bad literal is not sent; a refusal says why (kvp write's checks, tested there too)."""
    emulator = await emulator_factory(robot=False)
    app = make_app(emulator.port, tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await until(pilot, lambda: app.state.updates > 0)
        await pilot.press("3", "down", "down", "down", "e")  # MYINT: no confirmation
        await until(pilot, lambda: isinstance(app.screen, InputDialog))
        app.screen.query_one(Input).value = "{A1 1O}"
        await pilot.press("enter")

        def notes(word: str) -> list[Any]:
            return [n for n in app._notifications if word in f"{n.title} {n.message}"]

        await until(pilot, lambda: bool(notes("not a KRL literal")))
        assert "^" in notes("not a KRL literal")[0].message
        app._write("MYINT", "5.5")
        await until(pilot, lambda: bool(notes("wrong type")))
        assert emulator.store.read("MYINT") == "0"
