"""``kvp arms bench``: the thesis' 512-target accuracy test for one arm and one solver.

Prints a summary (or ``--json``), writes the per-target CSV (``--dump``) and the 3D scatter
plot of the errors like the thesis' Fig. 3.8 (``--plot``). The test itself is
:func:`pyopenshowvar.universal.accuracy.accuracy_test`.
"""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from pyopenshowvar.arms import Arm
from pyopenshowvar.universal.accuracy import AccuracyReport, accuracy_test

__all__ = ["plot_report", "run_bench", "summary_lines"]


def run_bench(
    arm: Arm, solver: str, *, targets: int, budget_ms: float, clock: str, seed: int
) -> AccuracyReport:
    per_axis = round(targets ** (1.0 / 3.0))
    if per_axis**3 != targets or per_axis < 2:
        raise ValueError(
            f"--targets must be a cube of at least 8 (8, 27, 64, ..., 512), got {targets}"
        )
    return accuracy_test(
        arm, solver, per_axis=per_axis, budget=budget_ms / 1e3, seed=seed,
        clock=time.process_time if clock == "cpu" else time.perf_counter,
    )  # fmt: skip


def summary_lines(report: AccuracyReport) -> list[str]:
    s = report.summary()
    e, p, t = s["error_mm"], s["error_pct"], s["time_ms"]

    def num(v: Any, unit: str = "") -> str:
        return "-" if v is None else f"{v:.3g}{unit}"

    ws = s["workspace_mm"]
    return [
        f"{report.arm.name} ({s['arm']}), solver {s['solver']}, {s['clock']}-clock budget "
        f"{s['budget_ms']:g} ms",
        f"workspace box  {ws['lower']} .. {ws['upper']} mm (scale {ws['scale']:.0f} mm)",
        f"targets        {s['targets']}, reachable {s['reachable']} ({s['reach_check']})",
        f"error (reachable)   p50 {num(e['p50'], ' mm')} ({num(p['p50'], ' %')})  "
        f"p95 {num(e['p95'], ' mm')} ({num(p['p95'], ' %')})  max {num(e['max'], ' mm')} "
        f"({num(p['max'], ' %')})",
        f"time per target     p50 {num(t['p50'], ' ms')}  p99 {num(t['p99'], ' ms')}  "
        f"(load average {s['load_average'][0]:.1f})",
    ]


def write_dump(report: AccuracyReport, path: Path) -> None:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(report.dump_header())
        w.writerows(report.rows())


def write_json(report: AccuracyReport) -> str:
    return json.dumps(report.summary(), indent=2)


def plot_report(report: AccuracyReport, path: Path) -> None:
    """A 3D scatter of the targets coloured by error (% of the workspace), like Fig. 3.8;
    unreachable targets as small grey crosses."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x, r = report.targets / 1000.0, report.reachable
    fig = plt.figure(figsize=(6.4, 5.2), dpi=120)
    ax = fig.add_subplot(projection="3d")
    pts = ax.scatter(x[r, 0], x[r, 1], x[r, 2], c=report.error_pct[r], cmap="viridis", s=18,
                     vmin=0.0, vmax=max(float(np.max(report.error_pct[r], initial=0.0)), 1e-3))  # fmt: skip
    ax.scatter(x[~r, 0], x[~r, 1], x[~r, 2], c="0.7", marker="x", s=6, label="unreachable")
    fig.colorbar(pts, ax=ax, shrink=0.7, pad=0.1, label="error (% of the workspace)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    s = report.summary()
    ax.set_title(f"{report.arm.name}: {s['solver']}, {s['reachable']}/{s['targets']} reachable,\n"
                 f"error p50 {s['error_pct']['p50']} %, p95 {s['error_pct']['p95']} %",
                 fontsize=9)  # fmt: skip
    ax.legend(loc="upper left", fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
