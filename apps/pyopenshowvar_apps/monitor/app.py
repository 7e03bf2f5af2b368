"""The monitor application: layout, key bindings, the polling loop and the watch list.

One asyncio task polls every ``1/hz`` seconds with ONE ``read_many`` (panels + watch list).
A lost connection or a timeout is shown in the status line and retried once a second
(``Client(auto_reconnect=True)``), so the monitor recovers by itself when the controller or
the emulator comes back. Writes go through the same client, checked like ``kvp write``
(:mod:`pyopenshowvar_apps.writecheck`); writing a motion variable
(:data:`pyopenshowvar_apps.names.MOTION_VARIABLES`) asks for confirmation first.

The layout grows with the terminal: at 80×24 everything fits, and a larger terminal gives the
joint bars, the access-time sparkline, the plots and the watch table more room. On the Watch
tab the table has the focus, so ↑/↓ move the selection that ``d`` and ``e`` act on, and the
pane below the table shows the selected value whole (typed, wrapped to the width).
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import ClassVar

from rich.console import RenderableType
from rich.text import Text
from textual import events
from textual.app import App, ComposeResult
from textual.binding import Binding, BindingType
from textual.containers import Horizontal, Vertical
from textual.widgets import DataTable, Footer, Static, TabbedContent, TabPane
from textual.widgets.data_table import ColumnKey

from pyopenshowvar import Client, KvpConnectionError, KvpError, KvpTimeoutError
from pyopenshowvar_apps.armpick import ArmChoice
from pyopenshowvar_apps.names import is_motion_variable
from pyopenshowvar_apps.pretty import render_text
from pyopenshowvar_apps.writecheck import STOP_WINDOW, check_literal, checked_write

from .dialogs import ConfirmDialog, InputDialog
from .state import RobotState
from .watchlist import WatchList
from .widgets import DetailPane, JointsPanel, PlotsPanel, PosePanel, ProgramPanel, StatsPanel

RETRY_SECONDS = 1.0
NAME_WIDTH = 22


class MonitorApp(App[None]):
    """``kvp monitor``: live robot panels, plots and an editable watch list."""

    TITLE = "kvp monitor"
    ENABLE_COMMAND_PALETTE = False
    CSS = """
    #status { height: 1; background: $boost; padding: 0 1; }
    #status.lost { background: $error 40%; }
    #robot-top { height: auto; }
    JointsPanel { width: 1fr; min-width: 46; }
    #right { width: 34; height: auto; }
    #watch-table { height: 1fr; min-height: 3; }
    #watch-detail { height: auto; max-height: 50%; border-top: solid $primary; padding: 0 1; }
    #watch-hint { height: 1; color: $text-muted; }
    TabbedContent, ContentSwitcher { height: 1fr; }
    TabPane { padding: 0; height: 1fr; }
    """
    BINDINGS: ClassVar[list[BindingType]] = [
        Binding("q", "quit", "Quit"),
        # Ctrl-C quits as in any terminal program (Textual's default only says how to quit).
        Binding("ctrl+c", "quit", "Quit", show=False, priority=True),
        Binding("1", "tab('robot')", "Robot"),
        Binding("2", "tab('plots')", "Plots"),
        Binding("3", "tab('watch')", "Watch"),
        Binding("a", "add_watch", "Add"),
        Binding("d", "remove_watch", "Del"),
        Binding("e", "edit_watch", "Edit"),
        Binding("r", "reconnect", "Retry"),
    ]

    def __init__(
        self,
        host: str,
        port: int,
        *,
        timeout: float = 1.0,
        hz: float = 10.0,
        watch_file: Path | None = None,
        emulated: bool = False,
        stop_window: float = STOP_WINDOW,
        arm: ArmChoice | None = None,
    ) -> None:
        super().__init__()
        self.stop_window = stop_window
        self.host, self.port, self.hz = host, port, hz
        self.client = Client(host, port, timeout=timeout, auto_reconnect=True, keepalive=None)
        self.state = RobotState(given=arm)
        self.watchlist = WatchList.load(watch_file)
        self.emulated = emulated
        self.connected = False
        self.last_error = ""
        self.polls = 0
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None

    # ------------------------------------------------------------------ layout
    def compose(self) -> ComposeResult:
        yield Static("connecting…", id="status")
        with TabbedContent(initial="robot"):
            with TabPane("Robot", id="robot"):
                with Horizontal(id="robot-top"):
                    yield JointsPanel(id="joints")
                    with Vertical(id="right"):
                        yield PosePanel(id="pose")
                        yield ProgramPanel(id="program")
                yield StatsPanel(id="stats")
            with TabPane("Plots", id="plots"):
                yield PlotsPanel(id="plot-panel")
            with TabPane("Watch", id="watch"):
                yield DataTable(id="watch-table", cursor_type="row", zebra_stripes=True)
                yield DetailPane("", id="watch-detail")
                yield Static(
                    "↑↓ select · a add · d remove · e edit & write · saved automatically",
                    id="watch-hint",
                )
        yield Footer()

    def on_mount(self) -> None:
        self.query_one("#joints").border_title = self.joints_title()
        self.query_one("#pose").border_title = "TCP pose $POS_ACT"
        self.query_one("#program").border_title = "program"
        self.query_one("#stats").border_title = "access time (this monitor)"
        table = self.query_one("#watch-table", DataTable)
        table.add_column("variable", key="name", width=NAME_WIDTH)
        table.add_column("value", key="value", width=20)
        for name in self.watchlist.names:
            table.add_row(name, "…", key=name)
        self._task = asyncio.get_running_loop().create_task(self._poll_loop())

    async def on_unmount(self) -> None:
        if self._task is not None:
            self._task.cancel()
        await self.client.close()

    async def on_event(self, event: events.Event) -> None:
        # Keys pressed right after ``a`` or ``e`` went to the watch table before the binding
        # opened the dialog; they come back here unhandled: they belong to the dialog.
        if isinstance(event, events.Key) and event.is_forwarded:
            screen = self.screen_stack[-1] if self.screen_stack else None
            if isinstance(screen, InputDialog) and screen.type_ahead(event):
                return
        await super().on_event(event)

    # ------------------------------------------------------------------ polling
    async def _poll_loop(self) -> None:
        period = 1.0 / self.hz
        while True:
            started = time.monotonic()
            wait = period
            try:
                await self.poll_once()
            except (KvpConnectionError, KvpTimeoutError, OSError) as exc:
                self._lost(exc)
                wait = RETRY_SECONDS
            except KvpError as exc:  # protocol trouble: show it, keep going
                self._lost(exc)
                wait = RETRY_SECONDS
            self._wake.clear()
            try:
                await asyncio.wait_for(
                    self._wake.wait(), max(0.0, wait - (time.monotonic() - started))
                )
            except TimeoutError:
                pass

    async def poll_once(self) -> None:
        """One refresh: ONE read_many for every panel variable and the watch list."""
        was_connected = self.client.connected
        watch = list(self.watchlist.names)
        results = await self.client.read_many(self.state.names_to_read(watch))
        if not was_connected and self.polls:
            self.state.forget_limits()  # maybe another controller: re-read the limits next time
        self.state.update(results, watch)
        self.polls += 1
        if not self.connected:
            self.connected = True
            if self.polls > 1 or self.last_error:
                self.notify(f"connected to {self.client.endpoint}", timeout=3)
        self.last_error = ""
        self._refresh_view()

    def _lost(self, exc: BaseException) -> None:
        first = self.connected or not self.last_error
        self.connected = False
        self.last_error = str(exc) or type(exc).__name__
        if first:
            self.notify(f"connection problem: {self.last_error}", severity="error", timeout=4)
        self._refresh_status()

    # ------------------------------------------------------------------ drawing
    def status_text(self) -> Text:
        s = self.client.stats.snapshot()
        text = Text()
        if self.connected:
            text.append("● connected ", style="bold green")
        else:
            text.append("● DISCONNECTED ", style="bold red")
        text.append(f"{self.client.endpoint}{' (emulator)' if self.emulated else ''}  ")
        if self.connected:
            text.append(f"{self.hz:g} Hz  Δt mean {s.mean * 1e3:.2f} p99 {s.p99 * 1e3:.2f} ms")
            if self.client.reconnects:
                text.append(f"  reconnects {self.client.reconnects}")
        else:
            text.append(f"retrying… {self.last_error}", style="red")
        return text

    def _refresh_status(self) -> None:
        status = self.query_one("#status", Static)
        status.update(self.status_text())
        status.set_class(not self.connected, "lost")

    def joints_title(self) -> str:
        """The joints panel's title: with the arm, and where its limits come from."""
        title = "joints (deg) · limits · torque"
        arm = self.state.arm
        if arm is None:
            return title
        name = arm.model.name if arm.key else f"{arm.model.name}?"
        limits = " (catalogue limits)" if self.state.limits_from == "catalogue" else ""
        return f"{title} · {name}{limits}"

    def _refresh_view(self) -> None:
        """Redraw the status line and the panels of the visible tab only (cheap at 10 Hz)."""
        self._refresh_status()
        joints = self.query_one("#joints")
        title = self.joints_title()
        if joints.border_title != title:
            joints.border_title = title
        active = self.query_one(TabbedContent).active
        if active == "robot":
            self.query_one(JointsPanel).refresh_from(self.state)
            self.query_one(PosePanel).refresh_from(self.state)
            self.query_one(ProgramPanel).refresh_from(self.state)
            self.query_one(StatsPanel).refresh_from(self.client.stats, self.client.reconnects)
        elif active == "plots":
            self.query_one(PlotsPanel).refresh_from(self.state)
        elif active == "watch":
            table = self.query_one("#watch-table", DataTable)
            width = self._fit_watch_columns()
            for name in self.watchlist.names:
                value = self.state.watch.get(name, "…")
                if len(value) > width:  # whole in the pane below
                    value = value[: width - 1] + "…"
                try:
                    table.update_cell(name, "value", value)
                except Exception:  # row just removed by the user
                    pass
            self._refresh_detail()

    def _fit_watch_columns(self) -> int:
        """Give the value column the table's remaining width; returns that width."""
        table = self.query_one("#watch-table", DataTable)
        # each column has one cell of padding on either side; keep one cell for a scrollbar
        width = max(10, table.size.width - NAME_WIDTH - 2 * table.cell_padding * 2 - 1)
        column = table.columns.get(ColumnKey("value"))
        if column is not None and column.width != width:
            column.width = width
            column.auto_width = False
            table.refresh_column(table.get_column_index("value"))
        return width

    def _refresh_detail(self) -> None:
        """The selected watch value, whole: typed and laid out to the pane's width."""
        name = self._selected()
        text = self.state.watch.get(name) if name is not None else None
        shown: RenderableType
        if name is None:
            shown = Text("the watch list is empty: press a to add a variable")
        elif text is None:
            shown = Text(f"{name}: waiting for the first value…")
        elif text.startswith("<"):
            shown = Text(f"{name}: {text}", style="yellow")
        else:
            typed = render_text(name, text)
            shown = Text(f"{name} = {text}") if isinstance(typed, Text) else typed
        self.query_one("#watch-detail", DetailPane).show(shown)

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        self._refresh_detail()

    def on_tabbed_content_tab_activated(self, event: TabbedContent.TabActivated) -> None:
        if event.pane.id == "watch":
            # ↑/↓ must move the selection that d and e act on, without a Tab first
            self.query_one("#watch-table", DataTable).focus()
        if self.state.updates:
            self._refresh_view()

    # ------------------------------------------------------------------ actions
    def action_tab(self, tab: str) -> None:
        self.query_one(TabbedContent).active = tab

    def action_reconnect(self) -> None:
        self._wake.set()

    def action_add_watch(self) -> None:
        self.action_tab("watch")

        def done(name: str | None) -> None:
            if name and self.watchlist.add(name):
                self.watchlist.save()
                self.query_one("#watch-table", DataTable).add_row(name, "…", key=name)
                self._wake.set()

        self.push_screen(
            InputDialog("Add a variable to the watch list:", placeholder="$OV_PRO"), done
        )

    def _selected(self) -> str | None:
        """The watch row the table shows selected (its cursor row)."""
        table = self.query_one("#watch-table", DataTable)
        if not self.watchlist.names or table.row_count == 0:
            return None
        row = table.coordinate_to_cell_key(table.cursor_coordinate).row_key
        return str(row.value) if row.value is not None else None

    def action_remove_watch(self) -> None:
        if self.query_one(TabbedContent).active != "watch":
            self.action_tab("watch")  # show the list first: never delete a row unseen
            return
        name = self._selected()
        if name and self.watchlist.remove(name):
            self.watchlist.save()
            self.query_one("#watch-table", DataTable).remove_row(name)
            self.state.watch.pop(name, None)
            self.notify(f"removed {name} from the watch list", timeout=2)
            self._refresh_detail()

    def action_edit_watch(self) -> None:
        self.action_tab("watch")  # the dialog names the variable it edits
        name = self._selected()
        if name is None:
            self.notify("the watch list is empty: press a to add a variable", severity="warning")
            return
        current = self.state.watch.get(name, "")
        current = "" if current.startswith("<") else current

        def got_value(value: str | None) -> None:
            if value is None:
                return
            if is_motion_variable(name):
                question = (
                    f"{name} is a motion variable: writing it may move the robot.\nWrite {value}?"
                )
                self.push_screen(
                    ConfirmDialog(question), lambda ok: self._write(name, value) if ok else None
                )
            else:
                self._write(name, value)

        self.push_screen(
            InputDialog(f"New value for {name} (KRL literal):", value=current), got_value
        )

    def _write(self, name: str, value: str) -> None:
        problem = check_literal(value)
        if problem is not None:
            self.notify(
                "\n".join(problem.lines(value)), title="not a KRL literal", severity="error"
            )
            return

        async def job() -> None:
            try:
                outcome = await checked_write(self.client, name, value, window=self.stop_window)
            except KvpError as exc:
                self.notify(f"write failed: {exc}", severity="error", timeout=8)
                return
            self.notify(f"wrote {name} = {outcome.echo}", timeout=3)
            if outcome.stop is not None:
                self.notify(
                    outcome.stop.describe(),
                    title="the robot program stopped right after the write",
                    severity="error",
                    timeout=10,
                )
            self._wake.set()

        self.run_worker(job(), group="writes")
