"""``kvp program``: upload, select, start, stop, reset and watch KRL programs (C3 Bridge).

::

    kvp program upload CELL.src [CELL.dat] [--select] [--start --allow-motion]
    kvp program select 'KRC:\\R1\\Program\\CELL.src'      # or /R1/CELL
    kvp program start --allow-motion                       # stop | reset | cancel | status
    kvp program run /R1/CELL --allow-motion                # select and start in one message

Needs C3 Bridge on the controller (docs/c3bridge.md); against KUKAVARPROXY every command says
so (exit 6) before sending anything. Starting moves the robot: ``--allow-motion`` is required.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from pyopenshowvar_apps.c3cli import run_c3
from pyopenshowvar_apps.common import EXIT_USAGE, fail

if TYPE_CHECKING:
    from pyopenshowvar import Client

ORDER = 35
COMMANDS = ("program",)

program_app = typer.Typer(
    name="program",
    help="Upload, select, start, stop and watch KRL programs (needs C3 Bridge on the controller;"
    " starting needs --allow-motion).",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,
)

AllowMotion = Annotated[
    bool,
    typer.Option(
        "--allow-motion", help="Confirm that the robot may move (required to start a program)."
    ),
]
Submit = Annotated[
    bool, typer.Option("--submit", help="Act on the submit interpreter (SPS) instead.")
]
#: Largest file ``upload`` sends (a KRL module is a few KiB; C3 Bridge holds it in memory).
MAX_UPLOAD = 16 * 1024 * 1024


def _read_local(path: Path) -> bytes:
    try:
        data = path.read_bytes()
    except OSError as exc:
        fail(EXIT_USAGE, f"cannot read {path}: {exc.strerror or exc}")
    if len(data) > MAX_UPLOAD:
        fail(EXIT_USAGE, f"{path} is {len(data)} bytes; a KRL module over {MAX_UPLOAD} is refused")
    return data


async def _explain(kvp: Client) -> str:
    """The controller's reason, where it tells one (the emulator's $EMU_MESSAGE[])."""
    try:
        state = await kvp.program_state()
    except Exception:  # the explanation is best effort; the refusal itself is reported
        return ""
    return state.message or ""


@program_app.command("upload")
def upload(
    src: Annotated[Path, typer.Argument(help="The module's .src file.")],
    dat: Annotated[
        Path | None, typer.Argument(help="Its .dat (default: the .dat beside the .src, if any).")
    ] = None,
    folder: Annotated[str, typer.Option("--to", help="Controller folder.")] = "KRC:\\R1\\Program",
    select: Annotated[bool, typer.Option("--select", help="Select it after uploading.")] = False,
    start: Annotated[
        bool, typer.Option("--start", help="Select and start it (needs --allow-motion).")
    ] = False,
    allow_motion: AllowMotion = False,
    overwrite: Annotated[
        bool, typer.Option("--overwrite/--no-overwrite", help="Replace an existing module.")
    ] = True,
) -> None:
    """Upload a KRL module (.src and .dat) to the controller."""
    if start and not allow_motion:
        fail(EXIT_USAGE, "--start moves the robot: add --allow-motion")
    if dat is None and src.with_suffix(".dat").is_file():
        dat = src.with_suffix(".dat")
    src_data = _read_local(src)
    dat_data = _read_local(dat) if dat is not None else None

    async def job(kvp: Client) -> str:
        target = await kvp.program_upload(
            src_data, src.name, dat_data, folder=folder, overwrite=overwrite
        )
        typer.echo(f"uploaded {target} ({len(src_data)} bytes)")
        if dat_data is not None:
            typer.echo(f"uploaded {target[:-4]}.dat ({len(dat_data)} bytes)")
        if select or start:
            await _select(kvp, target, force=False)
        if start:
            await kvp.program_start(allow_motion=True)
            typer.echo("started")
        return target

    run_c3(job)


async def _select(kvp: Client, name: str, *, force: bool) -> None:
    from pyopenshowvar.c3 import C3CommandError

    try:
        await kvp.program_select(name, force=force)
    except C3CommandError as exc:
        reason = await _explain(kvp)
        raise C3CommandError(exc.what, exc.code, endpoint=exc.endpoint, detail=reason) from None
    typer.echo(f"selected {name}")


@program_app.command("select")
def select(
    name: Annotated[str, typer.Argument(help="KRC:\\R1\\Program\\NAME.src or /R1/NAME.")],
    force: Annotated[bool, typer.Option("--force", help="C3 Bridge's force flag.")] = False,
) -> None:
    """Select a module for the robot interpreter (it stands at its first line)."""
    run_c3(lambda kvp: _select(kvp, name, force=force))


@program_app.command("run")
def run_program(
    name: Annotated[str, typer.Argument(help="KRC:\\R1\\Program\\NAME.src or /R1/NAME.")],
    allow_motion: AllowMotion = False,
) -> None:
    """Select and start a module in one message (needs --allow-motion)."""

    async def job(kvp: Client) -> None:
        await kvp.program_run(name, allow_motion=allow_motion)
        typer.echo(f"running {name}")

    run_c3(job)


#: Why the controller refuses a command in a state (the refusal's code says only "failed").
_HINTS = {
    ("start", "P_FREE"): "no program is selected (kvp program select)",
    ("start", "P_END"): "the program ended: kvp program reset, then start",
    ("start", "P_STOP"): "acknowledge the message first (kvp program confirm)",
    ("start", "P_ACTIVE"): "it is running already",
    ("stop", "P_FREE"): "no program is selected",
    ("stop", "P_RESET"): "it is not running",
    ("stop", "P_END"): "it ended already",
    ("reset", "P_ACTIVE"): "stop it first (kvp program stop)",
    ("reset", "P_FREE"): "no program is selected",
    ("cancel", "P_ACTIVE"): "stop it first (kvp program stop)",
}


def _control(action: str, submit: bool, allow_motion: bool = False) -> None:
    from pyopenshowvar.c3 import C3CommandError

    async def job(kvp: Client) -> None:
        interpreter = 0 if submit else 1
        try:
            if action == "start":
                await kvp.program_start(interpreter, allow_motion=allow_motion)
            else:
                await getattr(kvp, f"program_{action}")(interpreter)
        except C3CommandError as exc:
            state = await kvp.program_state()
            hint = _HINTS.get((action, state.state), "")
            if not hint:
                hint = state.message or f"the program is {state.state}"
            raise C3CommandError(exc.what, exc.code, endpoint=exc.endpoint, detail=hint) from None
        typer.echo(_DONE[action])

    run_c3(job)


_DONE = {"start": "started", "stop": "stopped", "reset": "reset", "cancel": "cancelled"}


@program_app.command("start")
def start(allow_motion: AllowMotion = False, submit: Submit = False) -> None:
    """Start the selected program, or resume a stopped one (needs --allow-motion)."""
    _control("start", submit, allow_motion)


@program_app.command("stop")
def stop(submit: Submit = False) -> None:
    """Stop the running program (the robot brakes on its path; start resumes)."""
    _control("stop", submit)


@program_app.command("reset")
def reset(submit: Submit = False) -> None:
    """Reset the stopped or ended program to its first line."""
    _control("reset", submit)


@program_app.command("cancel")
def cancel(submit: Submit = False) -> None:
    """Deselect the program (it must not be running)."""
    _control("cancel", submit)


@program_app.command("confirm")
def confirm() -> None:
    """Acknowledge the controller's messages (the smartPAD's "Confirm all")."""

    async def job(kvp: Client) -> None:
        await kvp.confirm_all()
        typer.echo("confirmed")

    run_c3(job)


@program_app.command("status")
def status(
    as_json: Annotated[bool, typer.Option("--json", help="Print the state as JSON.")] = False,
) -> None:
    """The robot interpreter's program and state, and why it stopped (works on KVP too)."""
    state = run_c3(lambda kvp: kvp.program_state())
    if as_json:
        typer.echo(json.dumps(asdict(state), indent=2))
        return
    name = state.name or "(none)"
    typer.echo(f"{name} {state.state}" + (" (stop message active)" if state.stop_message else ""))
    if state.message:
        typer.echo(f"message: {state.message}")


def register(app: typer.Typer) -> None:
    app.add_typer(program_app)


__all__ = ["program_app", "register"]
