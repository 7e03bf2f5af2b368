"""Shared helpers of the case studies: result type, output folder, CSV, PNG plots, summary table.

Everything here is deliberately small and dependency-light: matplotlib is imported lazily (and
forced onto the non-interactive ``Agg`` backend, because case studies run in tests, CI and over
SSH where no display exists), and rich only renders the final table.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover - typing only
    from matplotlib.figure import Figure
    from rich.table import Table

__all__ = [
    "CaseResult",
    "new_figure",
    "output_dir",
    "save_figure",
    "save_plot",
    "summary_table",
    "verdict",
    "write_csv",
]


@dataclass
class CaseResult:
    """Outcome of one case study.

    ``metrics`` are our measured numbers (name -> value, units in the name, e.g.
    ``"max_error_mm"``); ``thesis`` holds the thesis figure for the same metric key as text
    (e.g. ``"< 5"``, ``"≈ 10"``) so the demo table can show them side by side; ``files`` are the
    artefacts written (CSV, PNG).
    """

    name: str
    metrics: dict[str, float] = field(default_factory=dict)
    thesis: dict[str, str] = field(default_factory=dict)
    files: list[Path] = field(default_factory=list)

    def add_file(self, path: Path) -> Path:
        """Record a written artefact and return it (so calls can be chained)."""
        self.files.append(Path(path))
        return Path(path)


def output_dir(base: str | Path | None = None, name: str | None = None) -> Path:
    """The folder a case study writes to, created if missing.

    ``base`` defaults to ``./out``; ``name`` adds a sub-folder per case study so that
    ``kvp demo --out DIR`` keeps each study's files apart.
    """
    path = Path(base) if base is not None else Path("out")
    if name:
        path = path / name
    path.mkdir(parents=True, exist_ok=True)
    return path


def write_csv(
    path: str | Path,
    rows: Iterable[Sequence[Any] | Mapping[str, Any]],
    header: Sequence[str] | None = None,
) -> Path:
    """Write rows (sequences, or mappings keyed by ``header``) to a CSV file; return its path.

    Floats are written with ``repr`` precision by the csv module, so files round-trip exactly.
    When rows are mappings and no header is given, the first row's keys are the header.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = list(rows)
    if header is None and rows and isinstance(rows[0], Mapping):
        header = list(rows[0].keys())
    with path.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        if header is not None:
            writer.writerow(header)
        for row in rows:
            if isinstance(row, Mapping):
                assert header is not None
                writer.writerow([row.get(key, "") for key in header])
            else:
                writer.writerow(list(row))
    return path


def _pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (no display needed, thread-safe enough for tests)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def new_figure(nrows: int = 1, ncols: int = 1, **kw: Any) -> tuple[Figure, Any]:
    """A new figure and its axes (``plt.subplots`` on the Agg backend)."""
    plt = _pyplot()
    kw.setdefault("figsize", (6.4 * ncols, 4.8 * nrows))
    fig, axes = plt.subplots(nrows, ncols, **kw)
    return fig, axes


def save_figure(fig: Figure, path: str | Path, dpi: int = 120) -> Path:
    """Save ``fig`` as PNG and close it (figures are not garbage collected while pyplot tracks
    them, so closing matters in long demo runs)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    _pyplot().close(fig)
    return path


def save_plot(
    path: str | Path,
    draw: Callable[[Any], None] | None = None,
    *,
    x: Sequence[float] | None = None,
    ys: Mapping[str, Sequence[float]] | None = None,
    title: str = "",
    xlabel: str = "",
    ylabel: str = "",
    dpi: int = 120,
) -> Path:
    """Save a one-axes PNG plot.

    Either pass ``draw(ax)`` to draw anything, or ``x`` and ``ys`` (label -> values) for the
    common case of a few lines over a shared x axis. Returns the PNG path.
    """
    fig, ax = new_figure()
    if draw is not None:
        draw(ax)
    if ys:
        for label, values in ys.items():
            xs = list(x) if x is not None else list(range(len(values)))
            ax.plot(xs, list(values), label=label)
        ax.legend()
    if title:
        ax.set_title(title)
    if xlabel:
        ax.set_xlabel(xlabel)
    if ylabel:
        ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    return save_figure(fig, path, dpi=dpi)


def _fmt(value: float) -> str:
    """A compact number; ``n/a`` for NaN/inf (a metric that could not be measured)."""
    if not math.isfinite(value):
        return "n/a"
    if isinstance(value, int) or float(value).is_integer():
        return f"{value:.0f}"
    return f"{value:.3g}" if abs(value) < 100 else f"{value:.1f}"


#: A reference value within this fraction of ours is "similar".
TOLERANCE = 0.25


def _lower_is_better(metric: str) -> bool | None:
    """Errors, delays and times are better small; None when the name says nothing."""
    name = metric.lower()
    if any(k in name for k in ("err", "_ms", "lag", "overhead", "rms", "max_")):
        return True
    return None


def verdict(ours: float, thesis: str, lower_is_better: bool | None = None) -> str:
    """``better`` / ``worse`` / ``similar`` / ``differs`` / ``""`` for ``ours`` against a
    thesis figure.

    ``"< 5"`` is an upper bound (lower is better), ``"> 20"`` a lower bound; ``"≈ 4.27"`` a
    measured value: within :data:`TOLERANCE` it is ``similar``; beyond it ``better`` or
    ``worse`` when the metric has a direction (``lower_is_better``), else ``differs``. A thesis
    figure without a number (``"plots only"``) or a metric we could not measure gets ``""``.
    """
    match = re.search(r"[-+]?\d+(?:\.\d+)?", thesis)
    if match is None or not math.isfinite(ours):
        return ""
    bound = float(match.group())
    text = thesis.strip()
    if text.startswith(("<", "≤")):
        return "better" if ours < bound else "worse"
    if text.startswith((">", "≥")):
        return "better" if ours > bound else "worse"
    if abs(ours - bound) <= TOLERANCE * abs(bound):
        return "similar"
    if lower_is_better is None:
        return "differs"
    return "better" if (ours < bound) == lower_is_better else "worse"


def summary_table(
    results: Iterable[CaseResult], title: str = "Case studies", *, width: int = 80
) -> Table:
    """One rich table that fits ``width`` columns: case study, metric, ours, thesis, verdict.

    A result whose metrics are empty but which has a ``status`` thesis entry (e.g. "not
    available") is shown as one row with that status, so the demo lists every case study.
    Long metric names wrap instead of being cut.
    """
    from rich.table import Table

    table = Table(title=title, width=width, pad_edge=False, collapse_padding=True)
    table.add_column("study", ratio=2, overflow="fold")
    table.add_column("metric", ratio=5, overflow="fold")
    table.add_column("ours", justify="right", ratio=2, no_wrap=True)
    table.add_column("thesis", justify="right", ratio=2, overflow="fold")
    table.add_column("verdict", ratio=2, no_wrap=True)
    for result in results:
        first = True
        if not result.metrics:
            table.add_row(result.name, "-", "-", result.thesis.get("status", "-"), "")
            continue
        for key, value in result.metrics.items():
            thesis = result.thesis.get(key, "")
            table.add_row(
                result.name if first else "",
                key,
                _fmt(value),
                thesis or "-",
                verdict(value, thesis, _lower_is_better(key)) if thesis else "",
            )
            first = False
    return table
