"""The monitor's panels: joints with limit bars, pose, program/override, and history plots.

Each panel is a :class:`~textual.widgets.Static` re-rendered from :class:`RobotState` on every
refresh; ``plain`` keeps the last text shown, for tests and screen readers. The plots are
:class:`~.plot.Plot` sparklines, one per axis, that draw noise at rest flat.
"""

from __future__ import annotations

import math

from rich.console import RenderableType
from rich.table import Table
from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.widget import Widget
from textual.widgets import Label, Sparkline, Static

from pyopenshowvar import AccessStats

from .plot import Plot
from .state import AXES, RobotState

BAR_WIDTH = 11
#: The smallest change the history plots draw: the precision the panels print (each plot also
#: draws its sensor's noise flat, see :mod:`.plot`).
RESOLUTION = {"joints": 0.01, "torques": 0.1}


def limit_bar(
    value: float, lower: float | None, upper: float | None, width: int = BAR_WIDTH
) -> Text:
    """``├───●──────┤``: where ``value`` sits between the software limits; red near a limit."""
    if lower is None or upper is None or not upper > lower or math.isnan(value):
        return Text("·" * width, style="dim")
    frac = (value - lower) / (upper - lower)
    pos = min(width - 1, max(0, round(frac * (width - 1))))
    near = frac < 0.05 or frac > 0.95
    line = ["─"] * width
    line[pos] = "●"
    return Text("".join(line), style="bold red" if near else "green")


def fmt(value: float | int | None, digits: int = 2) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "—"
    if isinstance(value, int):
        return str(value)
    return f"{value:.{digits}f}"


class Panel(Static):
    """A bordered panel that remembers the plain text of its last render."""

    DEFAULT_CSS = "Panel { border: round $primary; padding: 0 1; height: auto; }"

    plain: str = ""

    def show(self, text: Text) -> None:
        self.plain = text.plain
        self.update(text)


class DetailPane(Static):
    """The selected watch value, whole; ``shown`` keeps the renderable (for tests)."""

    shown: RenderableType = ""

    def show(self, renderable: RenderableType) -> None:
        self.shown = renderable
        self.update(renderable)


class JointsPanel(Panel):
    """A1..A6: angle, bar within $SOFTN_END..$SOFTP_END, limits and torque.

    The bar takes the width the other columns leave (11 cells at 80 columns, more on a wider
    terminal).
    """

    #: Width of the columns besides the bar, with the grid's padding (axis, angle, limits, Nm).
    OTHER_COLUMNS = 31

    def refresh_from(self, state: RobotState) -> None:
        table = Table.grid(padding=(0, 1))
        for _ in range(5):
            table.add_column(justify="right", no_wrap=True)
        width = max(BAR_WIDTH, min(60, self.content_size.width - self.OTHER_COLUMNS))
        lines = []
        for i, axis in enumerate(AXES):
            lo = state.lower[i] if state.lower else None
            hi = state.upper[i] if state.upper else None
            angle = state.joints[i]
            limits = f"{fmt(lo, 0)}…{fmt(hi, 0)}"
            torque = f"{fmt(state.torques[i], 1)} Nm"
            table.add_row(axis, f"{fmt(angle)}°", limit_bar(angle, lo, hi, width), limits, torque)
            lines.append(f"{axis} {fmt(angle)} {limits} {torque}")
        self.update(table)
        self.plain = "\n".join(lines)


class PosePanel(Panel):
    """TCP pose X Y Z (mm), A B C (deg), S and T."""

    def refresh_from(self, state: RobotState) -> None:
        p = state.pose
        text = Text()
        for keys in (("X", "Y", "Z"), ("A", "B", "C")):
            text.append(" ".join(f"{k}{fmt(p.get(k), 1):>8}" for k in keys) + "\n")
        text.append(f"S {fmt(p.get('S'))}  T {fmt(p.get('T'))}")
        self.show(text)


class ProgramPanel(Panel):
    """Override, operating mode, program state and name, TCP speed."""

    def refresh_from(self, state: RobotState) -> None:
        ov = state.override
        text = Text()
        text.append(f"override {fmt(ov)} %  ")
        text.append(f"mode {state.mode or '—'}\n")
        style = "green" if state.program_state.upper().endswith("ACTIVE") else "yellow"
        text.append("program ")
        text.append(state.program_state or "—", style=style)
        text.append(f" {state.program_name or '—'}\n")
        text.append(f"TCP speed {fmt(state.velocity, 3)} m/s")
        self.show(text)


class PlotsPanel(Widget):
    """Recent history: one sparkline per joint angle and per torque."""

    DEFAULT_CSS = """
    PlotsPanel { height: 1fr; }
    PlotsPanel .plot-group { height: auto; }
    PlotsPanel .plot-row { height: 1; }
    PlotsPanel .plot-label { width: 22; }
    PlotsPanel Plot { width: 1fr; height: 1fr; }
    PlotsPanel .plot-title { text-style: bold; color: $accent; height: 1; }
    """

    def on_resize(self) -> None:
        # Equal, whole-line plot heights that fill the tab: 1 line at 24 rows, 2 at 40.
        rows = max(1, min(4, (self.size.height - 2) // (2 * len(AXES))))
        for row in self.query(".plot-row"):
            row.styles.height = rows

    def compose(self) -> ComposeResult:
        for kind, unit in (("joints", "deg"), ("torques", "Nm")):
            with Vertical(classes="plot-group"):
                yield Label(f"{kind} ({unit}), last 20 s", classes="plot-title")
                for axis in AXES:
                    with Horizontal(classes="plot-row"):
                        yield Label(axis, id=f"{kind}-{axis}-label", classes="plot-label")
                        yield Plot(resolution=RESOLUTION[kind], id=f"{kind}-{axis}")

    def refresh_from(self, state: RobotState) -> None:
        for kind, history in (("joints", state.joint_history), ("torques", state.torque_history)):
            for axis, samples in zip(AXES, history, strict=True):
                data = [x for x in samples if not math.isnan(x)]
                spark = self.query_one(f"#{kind}-{axis}", Plot)
                spark.data = data or [0.0]
                last = data[-1] if data else math.nan
                lo = min(data) if data else math.nan
                hi = max(data) if data else math.nan
                label = self.query_one(f"#{kind}-{axis}-label", Label)
                label.update(f"{axis} {fmt(last, 1):>7} [{fmt(lo, 0)}…{fmt(hi, 0)}]")


class StatsPanel(Widget):
    """Access-time statistics of the monitor's own requests, with a sparkline of the last ones."""

    DEFAULT_CSS = """
    StatsPanel { border: round $primary; padding: 0 1; height: 1fr; min-height: 6; }
    StatsPanel Static { height: 2; }
    StatsPanel Sparkline { height: 1fr; min-height: 2; }
    """

    plain: str = ""

    def compose(self) -> ComposeResult:
        yield Static(id="stats-text")
        yield Sparkline([], id="stats-spark")

    def refresh_from(self, stats: AccessStats, reconnects: int) -> None:
        s = stats.snapshot()
        self.plain = (
            f"Δt mean {s.mean * 1e3:.2f} ms  median {s.p50 * 1e3:.2f}  p99 {s.p99 * 1e3:.2f}  "
            f"max {s.maximum * 1e3:.2f} ms\nrequests {s.count}  reconnects {reconnects}"
        )
        self.query_one("#stats-text", Static).update(self.plain)
        self.query_one("#stats-spark", Sparkline).data = [x * 1e3 for x in stats.samples()[-120:]]
