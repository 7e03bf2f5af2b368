"""The ``kvp`` command line: read, write, watch, record, benchmark and discover KRL variables.

Subcommands live in small modules and are registered here; the heavy ones (the REPL's
prompt_toolkit, the monitor's Textual) are imported only when their command runs, so
``kvp read`` starts fast.

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

import json
import sys
from typing import Annotated, Any

import typer

from pyopenshowvar import Client
from pyopenshowvar_apps import bench as _bench
from pyopenshowvar_apps import demo as _demo
from pyopenshowvar_apps import discover as _discover
from pyopenshowvar_apps import live as _live
from pyopenshowvar_apps import sessions as _sessions
from pyopenshowvar_apps.casestudies import linefollow_cli as _linefollow
from pyopenshowvar_apps.casestudies import teleop_cli as _teleop_cli
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
    run,
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


@app.command()
def read(
    names: Annotated[list[str], typer.Argument(help="Variables, e.g. '$AXIS_ACT' '$OV_PRO'.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print typed values as JSON.")] = False,
) -> None:
    """Read variables; print each raw value on its own line (or --json typed)."""

    async def job(kvp: Client) -> dict[str, Any]:
        results = await kvp.read_many(names, typed=as_json)
        for r in results.values():
            if r.error is not None:
                raise r.error
        return {n: (to_jsonable(r.value) if as_json else r.text) for n, r in results.items()}

    values = run(job)
    if as_json:
        typer.echo(json.dumps(values, indent=None if len(values) == 1 else 2))
    else:
        for text in values.values():
            typer.echo(text)


@app.command()
def write(
    name: Annotated[str, typer.Argument(help="Variable, e.g. '$OV_PRO' or 'MYAXIS'.")],
    value: Annotated[str, typer.Argument(help="KRL literal, e.g. 50 or '{A1 10.0, A2 -80.0}'.")],
) -> None:
    """Write a KRL literal to a variable; prints the proxy's echo."""
    typer.echo(run(lambda kvp: kvp.write(name, value)))


app.command("watch")(_live.watch)
app.command("record")(_live.record)
app.command("bench")(_bench.bench)
app.command("discover")(_discover.discover)
app.command("repl")(_sessions.repl)
app.command("monitor")(_sessions.monitor)

app.command("demo")(_demo.demo)
app.command("linefollow")(_linefollow.linefollow)
app.command("teleop")(_teleop_cli.teleop)
app.command("haptic")(_teleop_cli.haptic)


@app.command(context_settings={"allow_extra_args": True, "ignore_unknown_options": True})
def emu(ctx: typer.Context) -> None:
    """Run the KUKAVARPROXY emulator in the foreground (options as kukavarproxy-emu)."""
    from kukavarproxy_emu.__main__ import main as emu_main

    raise typer.Exit(emu_main(list(ctx.args)))


def main() -> None:
    """Console-script entry point."""
    try:
        app()
    except KeyboardInterrupt:  # pragma: no cover - interactive
        sys.exit(EXIT_INTERRUPTED)
