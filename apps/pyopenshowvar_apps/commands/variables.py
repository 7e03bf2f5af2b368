"""``kvp read`` and ``kvp write``: one-shot access to KRL variables from a shell."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING, Annotated, Any

import typer

from pyopenshowvar_apps.common import (
    EXIT_INTERRUPTED,
    EXIT_STOPPED,
    EXIT_USAGE,
    STOP_WINDOW,
    STOP_WINDOW_HELP,
    Opts,
    check_window,
    fail,
    run,
    run_blocking,
    to_jsonable,
)

if TYPE_CHECKING:
    from pyopenshowvar import sync

ORDER = 10
COMMANDS = ("read", "write")


def read(
    names: Annotated[list[str], typer.Argument(help="Variables, e.g. '$AXIS_ACT' '$OV_PRO'.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print typed values as JSON.")] = False,
) -> None:
    """Read variables; print each raw value on its own line (or --json typed)."""

    def job(kvp: sync.Client) -> dict[str, Any]:
        results = kvp.read_many(names, typed=as_json)
        for r in results.values():
            if r.error is not None:
                raise r.error
        return {n: (to_jsonable(r.value) if as_json else r.text) for n, r in results.items()}

    # the blocking client: a one-shot read needs no event loop, and not importing asyncio
    # is a fifth of kvp read's start-up
    values = run_blocking(job)
    if as_json:
        typer.echo(json.dumps(values, indent=None if len(values) == 1 else 2))
    else:
        for text in values.values():
            typer.echo(text)


def write(
    name: Annotated[str, typer.Argument(help="Variable, e.g. '$OV_PRO' or 'MYAXIS'.")],
    value: Annotated[
        str,
        typer.Argument(help="KRL literal, e.g. 50, -5 or '{A1 10.0, A2 -80.0}'."),
    ],
    no_check: Annotated[
        bool, typer.Option("--no-check", help="Send VALUE as it is, without parsing it first.")
    ] = False,
    stop_window: Annotated[
        float, typer.Option("--stop-window", callback=check_window, help=STOP_WINDOW_HELP)
    ] = STOP_WINDOW,
) -> None:
    """Write a KRL literal to a variable; prints the proxy's echo.

    The literal is checked before it is sent; a refusal says its likely reason; a write that
    stops the running robot program (e.g. beyond a software limit) is reported, exit code 7.
    """
    from pyopenshowvar_apps.writecheck import WriteProgress, check_literal, checked_write

    if not no_check and (problem := check_literal(value)) is not None:
        lines = problem.lines(value)
        fail(EXIT_USAGE, "\n".join([f"{value!r} is not a KRL literal: {lines[0]}", *lines[1:]]))
    progress = WriteProgress()
    try:
        outcome = run(
            lambda kvp: checked_write(kvp, name, value, window=stop_window, progress=progress)
        )
    except KeyboardInterrupt:
        # Ctrl-C: the one thing the user must know now is whether the variable changed
        fail(EXIT_INTERRUPTED, f"interrupted: {progress.describe(name)} on {Opts.where()}")
    typer.echo(outcome.echo)
    if outcome.stop is not None:
        fail(
            EXIT_STOPPED,
            f"the robot program stopped right after writing {name!r} on {Opts.where()}: "
            f"{outcome.stop.describe()}",
        )


def register(app: typer.Typer) -> None:
    app.command("read")(read)
    # a value may start with "-" (kvp write '$OV_PRO' -5): unknown "options" are arguments
    app.command("write", context_settings={"ignore_unknown_options": True})(write)
