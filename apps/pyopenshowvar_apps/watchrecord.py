"""``kvp watch`` (a live table) and ``kvp record`` (time-stamped CSV logging).

Both poll every name with one pipelined ``read_many`` per period, on a fixed schedule
(``t0 + k / hz``) so the rate does not drift; a late poll skips ahead instead of bursting.
The first poll must succeed (an unknown variable exits 5 at once); after that, lost
connections are retried with ``auto_reconnect`` and shown, so a long recording survives a
controller hiccup. Ctrl-C ends either command cleanly with exit code 0.
"""

from __future__ import annotations

import asyncio
import csv
import time
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from pyopenshowvar import KvpConnectionError, KvpError, KvpTimeoutError
from pyopenshowvar_apps.common import EXIT_USAGE, fail, fail_for, flatten, open_client

if TYPE_CHECKING:
    from rich.table import Table

    from pyopenshowvar import Client, ReadResult


def _check_rate(hz: float) -> None:
    if not 0 < hz <= 1000:
        fail(EXIT_USAGE, f"--hz must be in (0, 1000], got {hz:g}")


async def _first_poll(kvp: Client, names: list[str], typed: bool) -> dict[str, ReadResult]:
    results = await kvp.read_many(names, typed=typed)
    for r in results.values():
        if r.error is not None:
            raise r.error
    return results


class _Ticker:
    """Sleeps until the next slot of a fixed-rate schedule, skipping missed slots."""

    def __init__(self, hz: float) -> None:
        self.period = 1.0 / hz
        self.start = time.monotonic()
        self.k = 0

    async def wait(self) -> None:
        self.k += 1
        target = self.start + self.k * self.period
        now = time.monotonic()
        if now > target:  # late: skip to the next slot in the future
            self.k = int((now - self.start) / self.period) + 1
            target = self.start + self.k * self.period
        await asyncio.sleep(target - now)


# --------------------------------------------------------------------------------- watch


def _watch_table(
    names: list[str], values: dict[str, str], rtt: dict[str, float], status: str
) -> Table:
    from rich.table import Table

    table = Table(title=status, title_justify="left", expand=False)
    table.add_column("variable", style="bold cyan", no_wrap=True)
    table.add_column("value", overflow="fold")
    table.add_column("ms", justify="right", style="dim")
    for name in names:
        ms = rtt.get(name)
        table.add_row(name, values.get(name, ""), "" if ms is None else f"{ms:.1f}")
    return table


def watch(
    names: Annotated[list[str], typer.Argument(help="Variables to watch.")],
    hz: Annotated[float, typer.Option("--hz", help="Polls per second.")] = 2.0,
    count: Annotated[
        int, typer.Option("--count", hidden=True, help="Stop after N polls (tests).")
    ] = 0,
    duration: Annotated[
        float, typer.Option("--duration", help="Stop after S seconds (0: until Ctrl-C).")
    ] = 0.0,
) -> None:
    """Live-updating table of variables (raw values, round-trip ms) until Ctrl-C."""
    _check_rate(hz)
    from rich.console import Console
    from rich.live import Live

    console = Console()

    async def main() -> None:
        async with open_client(auto_reconnect=True) as kvp:
            values: dict[str, str] = {}
            rtt: dict[str, float] = {}
            t0 = time.perf_counter()
            first = await _first_poll(kvp, names, False)
            rtt_all = (time.perf_counter() - t0) * 1e3
            values.update({n: r.text or "" for n, r in first.items()})
            rtt.update(dict.fromkeys(names, rtt_all))
            polls = 1
            status = f"{kvp.endpoint}  {hz:g} Hz  poll 1"
            ticker = _Ticker(hz)
            end = time.monotonic() + duration if duration > 0 else None
            with Live(
                _watch_table(names, values, rtt, status), console=console, auto_refresh=False
            ) as live:
                while not (count and polls >= count) and not (end and time.monotonic() >= end):
                    await ticker.wait()
                    polls += 1
                    try:
                        t0 = time.perf_counter()
                        results = await kvp.read_many(names)
                        ms = (time.perf_counter() - t0) * 1e3
                        for n, r in results.items():
                            values[n] = r.text if r.ok and r.text else f"<{r.error}>"
                            rtt[n] = ms
                        status = f"{kvp.endpoint}  {hz:g} Hz  poll {polls}"
                    except (KvpConnectionError, KvpTimeoutError) as exc:
                        status = f"{kvp.endpoint}  LOST: {exc} (retrying)"
                    live.update(_watch_table(names, values, rtt, status), refresh=True)
            if not console.is_terminal:
                console.print()

    try:
        asyncio.run(main())
    except KeyboardInterrupt:
        return
    except KvpError as exc:
        fail_for(exc)


# -------------------------------------------------------------------------------- record


def record(
    names: Annotated[list[str], typer.Argument(help="Variables to record.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="CSV file to write.")],
    hz: Annotated[float, typer.Option("--hz", help="Samples per second.")] = 10.0,
    duration: Annotated[
        float, typer.Option("--duration", "-d", help="Seconds to record (0: until Ctrl-C).")
    ] = 0.0,
    split: Annotated[
        bool,
        typer.Option(
            "--split", help="Add one column per struct member / array element (typed values)."
        ),
    ] = False,
) -> None:
    """Record variables to CSV: t (s), wall time (ISO 8601), each raw value [and split columns]."""
    _check_rate(hz)
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    console = Console(stderr=True)
    stats = {"rows": 0, "missed": 0}

    async def main() -> None:
        async with open_client(auto_reconnect=True) as kvp:
            first = await _first_poll(kvp, names, split)
            extra: list[str] = []
            if split:
                for n, r in first.items():
                    extra += [c for c in flatten(n, r.value) if c != n]
            with out.open("w", newline="", encoding="utf-8") as fh:
                writer = csv.writer(fh)
                writer.writerow(["t", "wall", *names, *extra])
                progress = Progress(
                    TextColumn("[bold]recording[/] {task.fields[rows]} rows"),
                    BarColumn(),
                    TimeElapsedColumn(),
                    console=console,
                    transient=True,
                )
                t_start = time.monotonic()
                with progress:
                    task = progress.add_task("rec", total=duration or None, rows=0)
                    results: dict[str, ReadResult] | None = first
                    ticker = _Ticker(hz)
                    ticker.start = t_start
                    while True:
                        now = time.monotonic()
                        if results is not None:
                            _write_row(writer, now - t_start, names, extra, results, split)
                            stats["rows"] += 1
                        progress.update(task, completed=now - t_start, rows=stats["rows"])
                        await ticker.wait()
                        if duration and time.monotonic() - t_start >= duration:
                            break
                        try:
                            results = await kvp.read_many(names, typed=split)
                        except (KvpConnectionError, KvpTimeoutError):
                            results = None
                            stats["missed"] += 1
                    fh.flush()

    interrupted = False
    try:
        asyncio.run(main())
    except KeyboardInterrupt:
        interrupted = True
    except KvpError as exc:
        fail_for(exc)
    except OSError as exc:
        fail(EXIT_USAGE, f"cannot write {out}: {exc.strerror or exc}")
    why = " (interrupted)" if interrupted else ""
    missed = f", {stats['missed']} missed" if stats["missed"] else ""
    rows = f"{stats['rows']} row{'' if stats['rows'] == 1 else 's'}"
    variables = f"{len(names)} variable{'' if len(names) == 1 else 's'}"
    console.print(f"recorded {rows} of {variables} to {out}{missed}{why}", soft_wrap=True)


def _write_row(
    writer: Any,
    t: float,
    names: list[str],
    extra: list[str],
    results: dict[str, ReadResult],
    split: bool,
) -> None:
    wall = datetime.now().astimezone().isoformat(timespec="milliseconds")
    raw = [results[n].text if results[n].ok else "" for n in names]
    cells: list[Any] = []
    if extra:
        flat: dict[str, Any] = {}
        for n in names:
            if split and results[n].ok:
                flat.update(flatten(n, results[n].value))
        cells = [flat.get(c, "") for c in extra]
    writer.writerow([f"{t:.4f}", wall, *raw, *cells])
