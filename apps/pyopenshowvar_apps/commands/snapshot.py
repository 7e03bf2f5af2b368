"""``kvp snapshot krl`` and ``kvp snapshot read``: many variables from one SPS pass, in one request.

``krl`` writes the KRL to install on the controller (``DIR/<NAME>.dat``, ``DIR/<NAME>.sub``);
``read`` reads the installed snapshot once and prints each variable under its own name. A
variable is ``NAME`` (a system variable whose type is known) or ``NAME:TYPE`` (``MYPOS:POS``,
``MYARR[]:REAL[10]``). See docs/snapshots.md.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from pyopenshowvar_apps.common import EXIT_USAGE, fail, run, to_jsonable

ORDER = 15
COMMANDS = ("snapshot",)

snapshot_app = typer.Typer(
    help="Consistent snapshots: KRL that copies many variables in one SPS pass, read in one"
    " request (docs/snapshots.md).",
    no_args_is_help=True,
)

_VARS_HELP = "Variables: NAME (system variable) or NAME:TYPE, e.g. '$AXIS_ACT' MYPOS:POS."


def _snapshot(name: str, variables: list[str], max_text: int | None, struc_line: int | None) -> Any:
    from pyopenshowvar.snapshot import Snapshot, SnapshotLimits

    items: list[str | tuple[str, str]] = []
    for spec in variables:
        var, sep, type_name = spec.partition(":")
        items.append((var, type_name) if sep else var)
    kw: dict[str, int] = {}
    if max_text is not None:
        kw["max_text"] = max_text
    if struc_line is not None:
        kw["struc_line"] = struc_line
    try:
        return Snapshot(name, items, limits=SnapshotLimits(**kw))
    except ValueError as exc:
        fail(EXIT_USAGE, str(exc))


def krl(
    name: Annotated[str, typer.Argument(help="Snapshot name: the global the PC reads, e.g. CELL.")],
    variables: Annotated[list[str], typer.Argument(help=_VARS_HELP)],
    out: Annotated[Path, typer.Option("--out", help="Directory for NAME.dat and NAME.sub.")],
    max_text: Annotated[
        int | None,
        typer.Option(help="Most reply characters per read (default 4096); more splits."),
    ] = None,
    struc_line: Annotated[
        int | None,
        typer.Option(help="Longest STRUC line (default 480); longer ones nest group types."),
    ] = None,
) -> None:
    """Write the KRL of a snapshot: NAME.dat ($CONFIG.DAT lines) and NAME.sub (the SPS)."""
    snap = _snapshot(name, variables, max_text, struc_line)
    try:
        dat, sub = snap.write_krl(out)
    except OSError as exc:
        fail(EXIT_USAGE, f"cannot write into {str(out)!r}: {exc.strerror or exc}")
    slots = sum(len(p.paths) for p in snap.parts)
    typer.echo(f"wrote {dat} and {sub}")
    if len(snap.parts) == 1:
        typer.echo(
            f"{len(snap.variables)} variables in {slots} members of {snap.parts[0].variable}:"
            " one request per snapshot"
        )
    else:
        typer.echo(
            f"{len(snap.variables)} variables in {slots} members, split by the size limits into"
            f" {len(snap.parts)} structures ({', '.join(snap.read_names)}): one request each,"
            " pipelined, checked to come from one SPS pass"
        )
    typer.echo(f"try it: kukavarproxy-emu --config {dat} --sps {sub}")


def read(
    name: Annotated[str, typer.Argument(help="Snapshot name, as given to 'kvp snapshot krl'.")],
    variables: Annotated[list[str], typer.Argument(help=_VARS_HELP)],
    as_json: Annotated[bool, typer.Option("--json", help="Print typed values as JSON.")] = False,
    max_text: Annotated[int | None, typer.Option(help="As given to 'kvp snapshot krl'.")] = None,
    struc_line: Annotated[int | None, typer.Option(help="As given to 'kvp snapshot krl'.")] = None,
) -> None:
    """Read an installed snapshot once: every variable from one SPS pass, plus the pass number."""
    from pyopenshowvar import Client, format_krc4

    snap = _snapshot(name, variables, max_text, struc_line)

    async def job(kvp: Client) -> Any:
        return await kvp.read_snapshot(snap)

    reading = run(job)
    if as_json:
        values = {n: to_jsonable(v) for n, v in reading.items()}
        typer.echo(json.dumps({"cycle": reading.cycle, "values": values}, indent=2))
        return
    typer.echo(f"CYCLE {reading.cycle}")
    for var, value in reading.items():
        text = " ".join(map(format_krc4, value)) if isinstance(value, list) else format_krc4(value)
        typer.echo(f"{var} {text}")


def register(app: typer.Typer) -> None:
    snapshot_app.command("krl")(krl)
    snapshot_app.command("read")(read)
    app.add_typer(snapshot_app, name="snapshot")
