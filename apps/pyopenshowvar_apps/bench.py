"""``kvp bench``: access-time analysis like the thesis' Figure 4.17.

Sequential (one request at a time, never pipelined) reads of one variable and writes of
another, each round trip timed with ``perf_counter``. Prints count, mean, median, p99, max and
min per operation and a histogram drawn with block characters (range clipped at the p99 so one
stall does not squash every bar; the last bin counts everything above). ``--csv`` saves every
sample for your own plots. Writes put back the value read beforehand, so benchmarking
``$OV_PRO`` on a real controller changes nothing.
"""

from __future__ import annotations

import asyncio
import csv
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, TextIO

import typer

from pyopenshowvar import AccessStats
from pyopenshowvar_apps.common import EXIT_USAGE, fail, run

if TYPE_CHECKING:
    from rich.console import Console

    from pyopenshowvar import Client

BLOCKS = " ▏▎▍▌▋▊▉█"


def bar(fraction: float, width: int) -> str:
    """A horizontal bar of ``fraction`` (0..1) of ``width`` cells, in eighths."""
    eighths = round(max(0.0, min(1.0, fraction)) * width * 8)
    full, part = divmod(eighths, 8)
    return ("█" * full + (BLOCKS[part] if part else "")).ljust(width)


def histogram_lines(stats: AccessStats, bins: int = 12, width: int = 40) -> list[str]:
    """The histogram of ``stats`` as text lines: ``low–high ms | bar count``."""
    if stats.count == 0:
        return []
    p99 = stats.percentile(0.99)
    hist = stats.histogram(bins, upper=p99 if p99 < stats.maximum else None)
    peak = max(c for _, _, c in hist) or 1
    lines = []
    for i, (lo, hi, c) in enumerate(hist):
        label = f"{lo * 1e3:7.3f}–{hi * 1e3:7.3f}"
        if i == len(hist) - 1 and hi < stats.maximum:
            label = f"{lo * 1e3:7.3f}–   max "
        lines.append(f"{label} ms │{bar(c / peak, width)} {c}")
    return lines


def print_report(console: Console, results: dict[str, AccessStats], target: str) -> None:
    from rich.table import Table

    table = Table(title=f"access times, {target}", title_justify="left")
    for col in ("op", "count", "mean", "median", "p99", "max", "min"):
        table.add_column(col, justify="left" if col == "op" else "right")
    for op, st in results.items():
        if st.count == 0:
            continue
        s = st.snapshot()
        table.add_row(
            op,
            str(s.count),
            *(f"{v * 1e3:.3f} ms" for v in (s.mean, s.p50, s.p99, s.maximum, s.minimum)),
        )
    console.print(table)
    for op, st in results.items():
        if st.count:
            console.print(f"[bold]{op}[/] histogram ({st.count} samples)")
            for line in histogram_lines(st, width=min(40, max(10, console.width - 36))):
                console.print(line, highlight=False)


def bench(
    reads: Annotated[int, typer.Option("--reads", "-r", help="Number of timed reads.")] = 1000,
    writes: Annotated[int, typer.Option("--writes", "-w", help="Number of timed writes.")] = 0,
    var: Annotated[str, typer.Option("--var", help="Variable to read.")] = "$OV_PRO",
    write_var: Annotated[
        str, typer.Option("--write-var", help="Variable to write (its current value is kept).")
    ] = "$OV_PRO",
    csv_path: Annotated[
        Path | None, typer.Option("--csv", help="Save every sample: op,index,seconds.")
    ] = None,
) -> None:
    """Access-time analysis: count, mean, median, p99, max and a terminal histogram."""
    if reads < 0 or writes < 0 or reads + writes == 0:
        fail(EXIT_USAGE, "--reads/--writes must be >= 0 and not both 0")
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    err = Console(stderr=True)
    samples: dict[str, list[float]] = {"read": [], "write": []}

    async def job(kvp: Client) -> None:
        keep = await kvp.read(write_var) if writes else ""
        await kvp.read(var)  # warm-up, and an unknown variable fails before timing
        progress = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            console=err,
            transient=True,
        )
        with progress:
            for op, n in (("read", reads), ("write", writes)):
                if n == 0:
                    continue
                task = progress.add_task(f"{op} {var if op == 'read' else write_var}", total=n)
                for i in range(n):
                    t0 = time.perf_counter()
                    if op == "read":
                        await kvp.read(var)
                    else:
                        await kvp.write(write_var, keep)
                    samples[op].append(time.perf_counter() - t0)
                    if i % 50 == 49 or i == n - 1:
                        progress.update(task, completed=i + 1)
                        await asyncio.sleep(0)

    # Open the CSV first: a typo in its path must not cost a whole benchmark run.
    out = _open_csv(csv_path) if csv_path is not None else None
    try:
        run(job)
    except BaseException:
        if out is not None:
            out.close()
            csv_path.unlink(missing_ok=True)  # type: ignore[union-attr]
        raise
    results: dict[str, AccessStats] = {}
    for op, values in samples.items():
        st = AccessStats(window=max(1, len(values)))
        for v in values:
            st.record(v)
        results[op] = st
    print_report(Console(), results, f"{var} / {write_var}" if writes else var)
    if out is not None:
        with out:
            w = csv.writer(out)
            w.writerow(["op", "index", "seconds"])
            for op, values in samples.items():
                w.writerows((op, i, f"{v:.9f}") for i, v in enumerate(values, 1))


def _open_csv(path: Path) -> TextIO:
    try:
        return path.open("w", newline="", encoding="utf-8")
    except OSError as exc:
        fail(EXIT_USAGE, f"cannot write {path}: {exc.strerror or exc}")
