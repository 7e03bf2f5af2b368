"""``kvp crane-head``: the three-axis compensator on a supply vessel, one sea state or a sweep.

A pure simulation (no robot, no emulator): the figures of eq. 61 for one H_s, or ``--sweep``
over H_s to find where the head's workspace is left. Heavy imports happen when it runs.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated, Any

import typer

__all__ = ["PAPER", "crane_head"]

#: the paper's figures and our target, as the summary table shows them
PAPER = {
    "ratio_rms_pct": "≤ 5",  # the target; the paper shows Fig. 11 only
    "e_c_rms_mm": "plots only",
    "e_s_rms_mm": "plots only",
    "saturated_pct": "0 up to H_s 3.0 m",
}
PAPER_TEXT = (
    "Henriksen et al.: compensation with the TAC alone works for H_s up to and including "
    "3.0 m (sea state 5, rough sea); above 3.0 m the workspace limits are reached (Figs. 8-12, "
    "no figures of e_c/e_s given; measurement noise neglected)."
)


def _heights(text: str) -> list[float]:
    try:
        lo, hi, step = (float(v) for v in text.split(":"))
    except ValueError:
        raise typer.BadParameter(f"expected FROM:TO:STEP in metres, got {text!r}") from None
    if not (0.0 <= lo <= hi and step > 0.0) or (hi - lo) / step > 200:
        raise typer.BadParameter(f"{text!r}: need 0 <= FROM <= TO, STEP > 0, at most 200 steps")
    n = round((hi - lo) / step) + 1
    return [round(lo + i * step, 6) for i in range(n)]


def crane_head(
    hs: Annotated[float, typer.Option("--hs", min=0.0, max=15.0, help="Significant wave height H_s (m).")] = 3.0,
    tp: Annotated[float | None, typer.Option(min=1.0, max=30.0, help="Peak period T_p (s); default 5·√H_s.")] = None,
    heading: Annotated[float, typer.Option(min=0.0, max=360.0, help="Wave direction β (deg; 180 head seas).")] = 150.0,
    spectrum: Annotated[str, typer.Option(help="'jonswap' (γ 3.3) or 'pm' (Pierson–Moskowitz).")] = "jonswap",
    duration: Annotated[float, typer.Option(min=10.0, max=3600.0, help="Recorded time (s).")] = 300.0,
    dt: Annotated[float, typer.Option(min=0.001, max=0.1, help="Control period (s).")] = 0.02,
    seed: Annotated[int, typer.Option(help="Seed of the sea and of the IMU errors.")] = 1,
    imu_scale: Annotated[float, typer.Option(min=0.0, max=100.0, help="IMU errors × this (0: ideal).")] = 1.0,
    sweep: Annotated[bool, typer.Option("--sweep", help="Sweep H_s (see --range).")] = False,
    range_: Annotated[str, typer.Option("--range", help="Sweep FROM:TO:STEP (m).")] = "0.5:6.0:0.5",
    out: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("out/crane_head"),
    plots: Annotated[bool, typer.Option("--plots/--no-plots", help="Write PNG figures.")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print the figures as one JSON object.")] = False,
) -> None:  # fmt: skip
    """Motion-compensated crane head (Henriksen et al.): e_c vs e_s of eq. 61, or --sweep H_s."""
    from .cranehead import CraneHeadConfig, simulate
    from .cranehead import sweep as run_sweep
    from .cranehead_report import write_run, write_sweep

    if spectrum not in ("jonswap", "pm"):
        raise typer.BadParameter(f"spectrum must be 'jonswap' or 'pm', got {spectrum!r}")
    cfg = CraneHeadConfig(hs=hs, tp=tp, heading=heading, spectrum=spectrum, duration=duration,
                          dt=dt, seed=seed, imu_scale=imu_scale)  # fmt: skip
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    if sweep:
        heights = _heights(range_)
        rows, limit = run_sweep(cfg, heights)
        files = write_sweep(rows, limit, out, plots=plots)
        doc: dict[str, Any] = {
            "sweep": rows, "workspace_limit_hs_m": limit, "paper_limit_hs_m": 3.0,
            "paper": PAPER_TEXT, "run_time_s": time.perf_counter() - started,
            "files": [str(f) for f in files],
        }  # fmt: skip
        _emit(doc, as_json, sweep=True)
        return
    run = simulate(cfg)
    files = write_run(run, out, plots=plots)
    doc = {
        "hs_m": hs, "tp_s": run.info["tp_s"], "heading_deg": heading, "spectrum": spectrum,
        "sea_state": run.info["sea_state"], "imu_scale": imu_scale, "seed": seed,
        **run.metrics, "x_d_m": run.info["x_d_m"],
        "workspace_margin_m": run.info["workspace_margin_m"],
        "target_ratio_rms_pct": 5.0, "target_met": run.metrics["ratio_rms_pct"] <= 5.0,
        "paper": PAPER_TEXT, "run_time_s": time.perf_counter() - started,
        "files": [str(f) for f in files],
    }  # fmt: skip
    _emit(doc, as_json, sweep=False)


def _emit(doc: dict[str, Any], as_json: bool, *, sweep: bool) -> None:
    if as_json:
        typer.echo(json.dumps(doc, indent=1))
        return
    from rich.console import Console

    from ..casestudies.common import CaseResult, summary_table

    console = Console()
    if sweep:
        from rich.table import Table

        table = Table(title="Crane head over H_s (same seed)")
        for col in ("H_s m", "sea state", "RMS e_c mm", "RMS e_s mm", "ratio %", "outside %"):
            table.add_column(col, justify="right")
        for r in doc["sweep"]:
            table.add_row(f"{r['hs_m']:g}", f"{r['sea_state']:.0f}", f"{r['e_c_rms_mm']:.1f}",
                          f"{r['e_s_rms_mm']:.0f}", f"{r['ratio_rms_pct']:.2f}",
                          f"{r['saturated_pct']:.2f}")  # fmt: skip
        console.print(table)
        limit = doc["workspace_limit_hs_m"]
        console.print(f"workspace limits reached from H_s = {limit} m (paper: above 3.0 m)")
    else:
        keys = ("e_c_rms_mm", "e_c_max_mm", "e_s_rms_mm", "e_s_max_mm", "ratio_rms_pct",
                "saturated_pct")  # fmt: skip
        result = CaseResult("crane head", {k: doc[k] for k in keys}, dict(PAPER))
        console.print(summary_table([result], title=f"Crane head, H_s = {doc['hs_m']:g} m"))
    console.print(PAPER_TEXT)
    for f in doc["files"]:
        typer.echo(f)
