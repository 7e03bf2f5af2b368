"""Typed pretty printing of KRL values for the terminal (rich renderables).

* a flat struct (E6AXIS, E6POS, FRAME, CP …) is a labelled row: member names over values,
  when that fits the width it is drawn in; otherwise ``member value`` pairs, as many to a line
  as fit (an E6POS at 80 columns: three), so no value is ever cut to "…";
* a struct with nested structs ($LOAD) is a two-column member/value table, nested tables inside;
* an array of up to 12 scalars is a row labelled 1..n (pairs when it does not fit), a longer
  one ``i=value`` text;
* a scalar prints as the proxy's text (``100``, ``#P_FREE``, ``"text"``).

Text that does not parse as a KRL value is shown as it came.
"""

from __future__ import annotations

from typing import Any

from rich import box
from rich.console import Console, ConsoleOptions, RenderableType, RenderResult
from rich.measure import Measurement
from rich.table import Table
from rich.text import Text

from pyopenshowvar import KrlEnum, Struct, parse_value
from pyopenshowvar.errors import KrlValueError


def fmt_scalar(value: Any) -> str:
    """Compact text of one scalar: REALs with at most 4 decimals, enums with ``#``."""
    if isinstance(value, bool):
        return "TRUE" if value else "FALSE"
    if isinstance(value, float):
        text = f"{value:.4f}".rstrip("0").rstrip(".")
        return "0" if text in ("-0", "") else text
    if isinstance(value, KrlEnum):
        return f"#{value}" if not str(value).startswith("#") else str(value)
    if isinstance(value, str):
        return f'"{value}"'
    return str(value)


def _is_scalar(value: Any) -> bool:
    return not isinstance(value, Struct | list)


class Row:
    """Labels over values when the row fits the width it is drawn in, else ``label value``
    pairs, as many to a line as fit. The choice is made at render time, so the same value
    prints as one row on a wide terminal and as a block on a narrow one (or in a table cell).
    """

    def __init__(self, title: str | None, labels: list[str], cells: list[str]) -> None:
        self.title = title
        self.labels = labels
        self.cells = cells

    def wide(self) -> Table:
        table = Table(title=self.title, title_justify="left", box=box.SIMPLE_HEAD, padding=(0, 1))
        for label in self.labels:
            table.add_column(label, justify="right", no_wrap=True)
        table.add_row(*self.cells)
        return table

    def _pair_width(self) -> int:
        label = max((len(x) for x in self.labels), default=0)
        cell = max((len(x) for x in self.cells), default=0)
        return label + 1 + cell

    def narrow(self, width: int) -> Table:
        gap = 3
        per_line = max(1, (width + gap) // (self._pair_width() + gap))
        grid = Table.grid(padding=(0, 1))
        grid.title, grid.title_justify = self.title, "left"
        for i in range(per_line):
            grid.add_column(style="bold cyan", no_wrap=True, justify="left")
            grid.add_column(justify="right", no_wrap=True)
            if i < per_line - 1:
                grid.add_column(width=gap - 2)  # with the padding: ``gap`` blanks between pairs
        pairs = list(zip(self.labels, self.cells, strict=True))
        for start in range(0, len(pairs), per_line):
            row: list[str] = []
            for i, (label, cell) in enumerate(pairs[start : start + per_line]):
                row += [label, cell] + ([""] if i < per_line - 1 else [])
            grid.add_row(*row)
        return grid

    def _natural(self, console: Console, options: ConsoleOptions, table: Table) -> int:
        # measured without the width limit (Measurement.get clamps to it)
        return Measurement.get(console, options.update_width(1 << 16), table).maximum

    def __rich_measure__(self, console: Console, options: ConsoleOptions) -> Measurement:
        wide = self._natural(console, options, self.wide())
        return Measurement(min(wide, self._pair_width()), wide).clamp(max_width=options.max_width)

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        wide = self.wide()
        if self._natural(console, options, wide) <= options.max_width:
            yield wide
        else:
            yield self.narrow(options.max_width)


def _row(title: str | None, labels: list[str], cells: list[str]) -> Row:
    return Row(title, labels, cells)


def render_value(value: Any, title: str | None = None) -> RenderableType:
    """A renderable for one typed KRL value."""
    if isinstance(value, Struct):
        members = dict(value.members)
        kind = value.type_name or "struct"
        caption = f"{title} ({kind})" if title else kind
        if all(_is_scalar(v) for v in members.values()):
            return _row(caption, list(members), [fmt_scalar(v) for v in members.values()])
        table = Table(title=caption, title_justify="left", box=box.SIMPLE, show_header=False)
        table.add_column("member", style="bold cyan")
        table.add_column("value")
        for key, member in members.items():
            table.add_row(key, render_value(member))
        return table
    if isinstance(value, list):
        if len(value) <= 12 and all(_is_scalar(v) for v in value):
            labels = [str(i) for i in range(1, len(value) + 1)]
            return _row(title, labels, [fmt_scalar(v) for v in value])
        parts = [f"{i}={fmt_scalar(v)}" for i, v in enumerate(value, 1)]
        return Text("  ".join(parts))
    return Text(fmt_scalar(value))


def render_text(name: str, text: str) -> RenderableType:
    """Parse the proxy's ``text`` and render it; unparsable text is shown as it is."""
    try:
        value = parse_value(text)
    except (KrlValueError, ValueError):
        return Text(text)
    if _is_scalar(value):
        return Text(text)
    return render_value(value, name)
