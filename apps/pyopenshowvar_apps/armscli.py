"""``kvp arms``: the arm catalogue shipped with pyopenshowvar, and any arm file.

::

    kvp arms list [--json]                 # name, axes, family, IK, source of every entry
    kvp arms show kr210_r2700_2 [--json]   # joints, limits, speeds, masses, source, licence
    kvp arms show my_crane.toml            # a TOML or URDF file works the same way
    kvp arms bench knuckle_boom_crane --solver ga --targets 512 [--json] [--dump F.csv] [--plot F.png]

A name that is neither a catalogue entry nor a file, or a file that cannot be used, is one
line on stderr and exit code 2.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from pyopenshowvar_apps.common import EXIT_USAGE, fail

if TYPE_CHECKING:
    from pyopenshowvar.arms import Arm

arms_app = typer.Typer(
    name="arms",
    help="The arm catalogue (KUKA arms, the thesis' crane, SCARA and youBot) and arm files.",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,
)

Json = Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")]


def _load(name: str) -> Arm:
    from pyopenshowvar.arms import ArmFileError, UnknownArmError, load_arm

    try:
        return load_arm(name)
    except (ArmFileError, UnknownArmError) as exc:
        fail(EXIT_USAGE, str(exc))


def _ik_kind(arm: Arm) -> str:
    return "closed form" if arm.kuka is not None else "numeric"


def _short_source(arm: Arm) -> str:
    text = (arm.source.url or arm.source.text).removeprefix("https://github.com/")
    return text if len(text) <= 60 else text[:57] + "..."


@arms_app.command("list")
def list_arms(as_json: Json = False) -> None:
    """List the catalogue: name, axes, family, IK method and where the numbers come from."""
    from pyopenshowvar.arms import catalogue, load_arm

    arms = [load_arm(name) for name in catalogue()]
    if as_json:
        rows = [
            {"name": a.key, "title": a.name, "dof": a.dof, "family": a.family,
             "ik": _ik_kind(a), "source": a.source.url or a.source.text, "licence": a.source.licence}
            for a in arms
        ]  # fmt: skip
        typer.echo(json.dumps(rows, indent=2))
        return
    header = ("NAME", "AXES", "FAMILY", "IK", "SOURCE")
    table = [header] + [(a.key, str(a.dof), a.family, _ik_kind(a), _short_source(a)) for a in arms]
    widths = [max(len(r[i]) for r in table) for i in range(4)]
    for row in table:
        typer.echo(
            "  ".join(c.ljust(w) for c, w in zip(row[:4], widths, strict=True)) + "  " + row[4]
        )


def _num(v: float | None, digits: int = 3) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    return f"{v:.{digits}f}".rstrip("0").rstrip(".")


@arms_app.command("show")
def show(
    name: Annotated[
        str, typer.Argument(help="Catalogue name (kvp arms list) or a .toml/.urdf file.")
    ],
    as_json: Json = False,
) -> None:
    """Show one arm: joints, limits, speeds, accelerations, torques, masses, source, licence."""
    arm = _load(name)
    info: dict[str, Any] = arm.describe()
    if arm.kuka is not None:
        info["kuka_dh"] = [[float(v) for v in row] for row in arm.kuka.dh]
    if as_json:
        typer.echo(json.dumps(info, indent=2))
        return
    out = typer.echo
    out(f"{arm.name}" + (f"  ({arm.key})" if arm.key else ""))
    if arm.family:
        out(f"family       {arm.family}")
    out(f"axes         {arm.dof}  ({', '.join(arm.joint_types)})")
    out(f"IK           {_ik_kind(arm)}")
    if arm.model_name:
        out(f"$MODEL_NAME  {arm.model_name}")
    out(f"home         {' '.join(_num(v) for v in info['home'])}")
    out(f"flange@home  X Y Z A B C = {' '.join(_num(v) for v in info['flange_at_home'])}")
    out("")
    header = ("JOINT", "TYPE", "LOWER", "UPPER", "SPEED", "ACCEL", "EFFORT", "MASS")
    rows = [header] + [
        (j["name"], j["type"], _num(j["lower"]), _num(j["upper"]), _num(j["max_speed"]),
         _num(j["max_accel"]), _num(j["max_effort"]), _num(j["mass"]))
        for j in info["joints"]
    ]  # fmt: skip
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    for row in rows:
        out(
            "  ".join(
                c.rjust(w) if i >= 2 else c.ljust(w)
                for i, (c, w) in enumerate(zip(row, widths, strict=True))
            )
        )
    out("units: deg, deg/s, deg/s² (mm, mm/s, mm/s² for prismatic joints), Nm (N), kg; - = unknown")
    if arm.kuka is not None:
        out("")
        out("closed-form D-H (a mm, alpha deg, d mm, theta offset deg, sign):")
        for i, row in enumerate(arm.kuka.dh):
            out(f"  A{i + 1}  " + "  ".join(_num(float(v)) for v in row))
    src = info["source"]
    out("")
    out(f"source       {src['text']}")
    for label, key in (
        ("url", "url"),
        ("commit", "commit"),
        ("licence", "licence"),
        ("notes", "notes"),
    ):
        if src[key]:
            out(f"{label:<12} {src[key]}")


@arms_app.command("bench")
def bench(
    name: Annotated[str, typer.Argument(help="Catalogue name or a .toml/.urdf file.")],
    solver: Annotated[str, typer.Option("--solver", help="closed-form, dls, ga or pso.")] = "dls",
    targets: Annotated[
        int, typer.Option("--targets", help="Targets: a cube (the thesis: 512 = 8 × 8 × 8).")
    ] = 512,
    as_json: Json = False,
    dump: Annotated[
        Path | None, typer.Option("--dump", help="Write every target, solution and error as CSV.")
    ] = None,
    plot: Annotated[
        Path | None, typer.Option("--plot", help="Write a 3D scatter PNG of the errors (Fig. 3.8).")
    ] = None,
    budget_ms: Annotated[
        float, typer.Option("--budget-ms", help="Time budget per target (the thesis: 20 ms).")
    ] = 20.0,
    clock: Annotated[
        str, typer.Option("--clock", help="wall (the thesis) or cpu (this process's CPU time).")
    ] = "wall",
    seed: Annotated[int, typer.Option("--seed", help="Random seed of the GA and PSO.")] = 0,
) -> None:
    """The thesis' accuracy test (§3.2.1.1): solve targets spaced evenly in the box around the
    workspace in position mode; error (mm, % of the workspace), reachable, time per target."""
    from pyopenshowvar.universal import SOLVERS, NoClosedFormError
    from pyopenshowvar_apps.universal.armsbench import (
        plot_report,
        run_bench,
        summary_lines,
        write_dump,
        write_json,
    )

    arm = _load(name)
    if solver not in SOLVERS:
        fail(EXIT_USAGE, f"--solver must be one of {', '.join(SOLVERS)}, not {solver!r}")
    if clock not in ("wall", "cpu"):
        fail(EXIT_USAGE, f"--clock must be wall or cpu, not {clock!r}")
    if not 0.1 <= budget_ms <= 10_000:
        fail(EXIT_USAGE, f"--budget-ms must be 0.1..10000, got {budget_ms:g}")
    try:
        report = run_bench(
            arm, solver, targets=targets, budget_ms=budget_ms, clock=clock, seed=seed
        )
    except NoClosedFormError as exc:
        fail(EXIT_USAGE, str(exc))
    except ValueError as exc:
        fail(EXIT_USAGE, str(exc))
    if dump is not None:
        write_dump(report, dump)
    if plot is not None:
        plot_report(report, plot)
    typer.echo(write_json(report) if as_json else "\n".join(summary_lines(report)))
