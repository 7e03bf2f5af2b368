"""The ``kvp`` command line: read, write, watch, record, benchmark and discover KRL variables.

Only the global options live here. Each subcommand group is a module of
:mod:`pyopenshowvar_apps.commands` with a ``register(app)`` function, found automatically (add
a command by adding a module there); the heavy imports (the REPL's prompt_toolkit, the
monitor's Textual) happen only when their command runs, so ``kvp read`` starts fast.

Exit codes (also in ``kvp --help``) let shell scripts react precisely:

====  ==========================================================
0     success
2     usage error (bad option or argument)
3     cannot connect / connection lost (``discover``: nothing answered)
4     timeout
5     unknown variable or refused write
6     protocol or value-parse error
====  ==========================================================

Errors are one line on stderr naming host, port and variable, never a traceback.
"""

from __future__ import annotations

import sys
from typing import Annotated

import typer

from pyopenshowvar_apps.commands import register_all
from pyopenshowvar_apps.common import (
    EXIT_CONNECTION,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_PROTOCOL,
    EXIT_TIMEOUT,
    EXIT_USAGE,
    EXIT_VARIABLE,
    Opts,
    plant_choice,
    start_embedded_emulator,
    to_jsonable,
)

__all__ = [
    "EXIT_CONNECTION",
    "EXIT_OK",
    "EXIT_PROTOCOL",
    "EXIT_TIMEOUT",
    "EXIT_USAGE",
    "EXIT_VARIABLE",
    "app",
    "main",
    "to_jsonable",
]

app = typer.Typer(
    name="kvp",
    help="Read, write, watch, record and benchmark KUKA KRL variables through KUKAVARPROXY "
    "(TCP 7000); an interactive console (repl) and a live monitor.\n\n"
    "Exit codes: 0 ok, 2 usage, 3 connection, 4 timeout, 5 unknown variable / refused write, "
    "6 protocol or parse error.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


@app.callback()
def _global(
    ctx: typer.Context,
    host: Annotated[
        str, typer.Option("--host", "-H", envvar="KVP_HOST", help="Proxy address.")
    ] = "127.0.0.1",
    port: Annotated[
        int, typer.Option("--port", "-p", envvar="KVP_PORT", help="Proxy TCP port.")
    ] = 7000,
    timeout: Annotated[float, typer.Option("--timeout", "-t", help="Seconds per request.")] = 2.0,
    emulate: Annotated[
        bool, typer.Option("--emulate", help="Start an embedded emulator and talk to it instead.")
    ] = False,
    plant: Annotated[
        str,
        typer.Option(
            "--plant",
            help="The embedded emulator's robot: dynamic (rigid-body arm, servos, noise) or"
            " ideal (measured = set-point, exact values).",
            callback=plant_choice,
        ),
    ] = "dynamic",
) -> None:
    Opts.host, Opts.port, Opts.timeout = host, port, timeout
    Opts.plant = plant
    Opts.emulator = None
    if emulate:
        start_embedded_emulator(ctx)


register_all(app)


def main() -> None:
    """Console-script entry point."""
    try:
        app()
    except KeyboardInterrupt:  # pragma: no cover - interactive
        sys.exit(EXIT_INTERRUPTED)
