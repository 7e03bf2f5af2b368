"""Typed pretty printing of KRL values for the terminal (rich renderables).

* a flat struct (E6AXIS, E6POS, FRAME, CP …) is a labelled row: member names over values;
* a struct with nested structs ($LOAD) is a two-column member/value table, nested tables inside;
* an array of up to 12 scalars is a row labelled 1..n, a longer one ``i=value`` text;
* a scalar prints as the proxy's text (``100``, ``#P_FREE``, ``"text"``).

Text that does not parse as a KRL value is shown as it came.
"""

from __future__ import annotations

from typing import Any

from rich import box
from rich.console import RenderableType
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


def _row(title: str | None, labels: list[str], cells: list[str]) -> Table:
    table = Table(title=title, title_justify="left", box=box.SIMPLE_HEAD, padding=(0, 1))
    for label in labels:
        table.add_column(label, justify="right", no_wrap=True)
    table.add_row(*cells)
    return table


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
