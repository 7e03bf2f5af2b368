"""``kvp crane-bench``: the crane benchmark suite (thesis §5.2) on a profile, per solver.

A pure simulation (no robot, no emulator): every run of the profile flown by each solver on
the hydraulic crane plant, calm and on a ship; the figures as a table or one JSON object,
per-step CSVs and PNG plots like the thesis' Figs. 5.5–5.12. Heavy imports happen when it runs.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated, Any

import typer

__all__ = ["THESIS_TABLE_5_1", "crane_bench"]

#: the thesis' Table 5.1: joint efforts by eq. 5.6 (printed unit "Nm"; ∫½τ² dt is N²·m²·s)
THESIS_TABLE_5_1 = {
    "ga": {"slew": 0.0, "boom": 7.9078e12, "jib": 0.0878e12},
    "pso": {"slew": 0.0, "boom": 7.6934e12, "jib": 0.0773e12},
}
THESIS_TEXT = (
    "Thesis §5.2.2 (GA vs PSO, 500 kg, container lift): PSO shows smaller position errors "
    "with smaller spikes (Figs. 5.7/5.8, no numbers); joint efforts in Table 5.1; both methods "
    "compensate the heave similarly (Figs. 5.11/5.12, no numbers)."
)


def crane_bench(
    profile: Annotated[Path | None, typer.Option("--profile", help="Operational profile (TOML); default the thesis' container lift.")] = None,
    solvers: Annotated[str, typer.Option("--solvers", help="Comma-separated: closed-form, dls, ga, pso.")] = "ga,pso,dls,closed-form",
    seed: Annotated[int, typer.Option("--seed", help="Seed of the solvers, the sea and the IMU.")] = 1,
    max_runs: Annotated[int, typer.Option("--max-runs", min=1, max=64, help="Fly the N most probable runs of the profile.")] = 8,
    heave: Annotated[bool, typer.Option("--heave/--no-heave", help="Run the heave-compensation test.")] = True,
    out: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("out/crane_bench"),
    plots: Annotated[bool, typer.Option("--plots/--no-plots", help="Write PNG figures.")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print the figures as one JSON object.")] = False,
) -> None:  # fmt: skip
    """Crane benchmark suite (thesis §5.2): profiles × solvers on a hydraulic knuckle-boom crane."""
    from pyopenshowvar.universal import SOLVERS

    from .profiles import ProfileError, builtin_profile, load_profile
    from .report import write_outputs
    from .suite import run_suite

    names = [s.strip().lower() for s in solvers.split(",") if s.strip()]
    unknown = [n for n in names if n not in SOLVERS]
    if not names or unknown:
        raise typer.BadParameter(f"unknown solver(s) {unknown}: use {', '.join(SOLVERS)}")
    started = time.perf_counter()
    try:
        from pyopenshowvar.arms import load_arm

        path = profile or builtin_profile()
        prof = load_profile(path, ())
        arm = load_arm(prof.crane)
        prof = load_profile(path, arm.joint_names)
        result = run_suite(prof, names, seed=seed, max_runs=max_runs, heave=heave)
    except (ProfileError, ValueError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    out.mkdir(parents=True, exist_ok=True)
    files = write_outputs(result, out, plots=plots)
    doc: dict[str, Any] = {
        "profile": prof.name, "crane": prof.crane, "seed": seed,
        "runs": [{"name": r.run.name, "probability": r.run.probability, "mode": r.run.mode,
                  "payload_kg": r.run.payload_kg, "solvers": r.metrics} for r in result.runs],
        "coverage": result.coverage, "solvers": result.solvers,
        "thesis_table_5_1": THESIS_TABLE_5_1, "thesis": THESIS_TEXT,
        "run_time_s": time.perf_counter() - started, "files": [str(f) for f in files],
    }  # fmt: skip
    _emit(doc, as_json)


def _emit(doc: dict[str, Any], as_json: bool) -> None:
    if as_json:
        typer.echo(json.dumps(doc, indent=1))
        return
    from rich.console import Console
    from rich.table import Table

    console = Console()
    table = Table(title=f"{doc['profile']}: {len(doc['runs'])} run(s), "
                  f"{100 * doc['coverage']:.0f} % of the profile")  # fmt: skip
    cols = ("solver", "eq. 5.2 rms/max mm", "actual rms/max mm", "T slew", "T boom", "T jib",
            "heave off/on rms mm", "solve ms")  # fmt: skip
    for c in cols:
        table.add_column(c, justify="right")
    for name, m in doc["solvers"].items():
        pe, ae, eff = m["position_error_mm"], m["actual_error_mm"], m["joint_effort"]
        hv = m.get("heave")
        table.add_row(name, f"{pe['rms']:.1f} / {pe['max']:.1f}", f"{ae['rms']:.1f} / {ae['max']:.1f}",
                      f"{eff['slew']:.3g}", f"{eff['boom']:.3g}", f"{eff['jib']:.3g}",
                      f"{hv['uncompensated_rms_mm']:.0f} / {hv['compensated_rms_mm']:.0f}" if hv else "–",
                      f"{m['solve_ms']['mean']:.1f}")  # fmt: skip
    for name, t in doc["thesis_table_5_1"].items():
        table.add_row(f"thesis {name}", "plots", "plots", f"{t['slew']:.3g}", f"{t['boom']:.3g}",
                      f"{t['jib']:.3g}", "plots", "20 budget")  # fmt: skip
    console.print(table)
    console.print(doc["thesis"])
    for f in doc["files"]:
        typer.echo(f)
