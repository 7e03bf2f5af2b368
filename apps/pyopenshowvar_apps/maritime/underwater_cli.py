"""``kvp underwater-plan``: GA path and posture planning for a 7-DOF underwater arm.

Plans the scenario (default: Tables 1 and 2 of Ishibashi et al. with our arm and obstacle
placement, docs/maritime.md) twice on the same GA_p path: with the drag term of eq. 3 and
without it, so the figures show what the term buys.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import Annotated, Any

import typer

__all__ = ["PAPER_TEXT", "underwater_plan"]

PAPER_TEXT = (
    "Ishibashi et al.: both experiments (two stationary obstacles) reached the goal with "
    "every posture secure; the path takes the shortest route away from the obstacles; "
    "e1 kept the posture changes small; without e3 the projected area became larger "
    "(Figs. 10, 11; no figures given). Planning time was their open problem."
)


def underwater_plan(
    scenario: Annotated[Path | None, typer.Option("--scenario", help="Scenario TOML (default: the paper's Table 1/2 set-up).")] = None,
    seed: Annotated[int | None, typer.Option(help="Seed of both GAs (overrides the file's).")] = None,
    out: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("out/underwater"),
    plots: Annotated[bool, typer.Option("--plots/--no-plots", help="Write the 3D figure.")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print the figures as one JSON object.")] = False,
) -> None:  # fmt: skip
    """Underwater manipulator planning (Ishibashi et al.): GA_p path, GA_m postures, drag term."""
    import numpy as np

    from pyopenshowvar_apps.common import EXIT_USAGE, fail

    from .underwater import PlanningError, plan, plan_path
    from .underwater_report import write_plans
    from .uw_scenario import PAPER, load_scenario

    try:
        sc = load_scenario(scenario) if scenario is not None else PAPER
        if seed is not None:
            sc = dataclasses.replace(sc, seed=seed)
        sc.load_arm()
    except (ValueError, OSError) as exc:
        fail(EXIT_USAGE, str(exc))
    started = time.perf_counter()
    try:
        t0 = time.perf_counter()
        planes = plan_path(sc, np.random.default_rng(sc.seed))
        path_s = time.perf_counter() - t0
        plans = [plan(sc, drag=True, planes=planes), plan(sc, drag=False, planes=planes)]
    except PlanningError as exc:
        fail(EXIT_USAGE, f"planning failed: {exc}")
    out.mkdir(parents=True, exist_ok=True)
    files = write_plans(plans, out, plots=plots)
    with_drag, without = plans[0].metrics(), plans[1].metrics()
    a1, a0 = with_drag["drag_area_integral_m2"], without["drag_area_integral_m2"]
    doc: dict[str, Any] = {
        "scenario": {
            "start": sc.start,
            "goal": sc.goal,
            "cube_mm": sc.cube,
            "arm": sc.arm,
            "base_mm": sc.base,
            "link_radius_mm": sc.link_radius,
            "obstacle_cubes": [b.cubes for b in sc.obstacles],
            "seed": sc.seed,
            "planes": len(planes),
        },
        "with_drag": with_drag,
        "without_drag": without,
        "drag_area_reduction_pct": 100.0 * (a0 - a1) / a0 if a0 > 0 else 0.0,
        "path_planning_s": path_s,
        "run_time_s": time.perf_counter() - started,
        "paper": PAPER_TEXT,
        "files": [str(f) for f in files],
    }
    if as_json:
        typer.echo(json.dumps(doc, indent=1))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="Underwater planning: with vs without the drag term e3")
    table.add_column("metric")
    table.add_column("with e3", justify="right")
    table.add_column("without e3", justify="right")
    for key, value in with_drag.items():
        table.add_row(key, f"{value:.3g}", f"{without[key]:.3g}")
    console = Console()
    console.print(table)
    console.print(f"drag area reduced by {doc['drag_area_reduction_pct']:.1f} % with e3")
    console.print(PAPER_TEXT)
    for f in files:
        typer.echo(f)
