"""``kvp gateway CELL.toml``: serve a cell of KRCs as one OPC UA server (docs/gateway.md).

The first line on stdout, flushed, is ``serving opc.tcp://HOST:PORT`` with the real port (the
cell file may ask for port 0), so scripts and tests can start it and read where it went; with
security on, the second is the server certificate's SHA-256 fingerprint. SIGINT and SIGTERM
stop it cleanly (exit 0). A bad cell file is exit 2 with one line naming the key.
``kvp gateway --hash-password`` reads a password (twice, hidden) and prints the hash for the
cell file's ``[security]`` users.
"""

from __future__ import annotations

import gc
import logging
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from pyopenshowvar_apps.common import EXIT_USAGE, fail

if TYPE_CHECKING:
    from pyopenshowvar_apps.gateway.server import Gateway

ORDER = 70
COMMANDS = ("gateway",)


def gateway(
    cell: Annotated[
        Path | None, typer.Argument(help="Cell file (TOML): robots, endpoint, security.")
    ] = None,
    hash_password: Annotated[
        bool,
        typer.Option(
            "--hash-password", help="Read a password and print its hash for the cell file."
        ),
    ] = False,
    log_level: Annotated[
        str, typer.Option("--log-level", help="debug, info, warning or error (stderr).")
    ] = "info",
) -> None:
    """Poll the cell's controllers over KVP and serve them over OPC UA (OPC 40010-1 Robotics)."""
    if hash_password:
        _print_hash()
        return
    if cell is None:
        fail(EXIT_USAGE, "gateway needs a cell file (see docs/gateway.md), or --hash-password")
    level = getattr(logging, log_level.upper(), None)
    if not isinstance(level, int):
        fail(EXIT_USAGE, f"--log-level {log_level!r}: use debug, info, warning or error")
    # without asyncua this raises ModuleNotFoundError, which kvp's entry point turns into one
    # line naming the `gateway` extra
    from pyopenshowvar_apps.gateway.cell import CellError, load_cell
    from pyopenshowvar_apps.gateway.server import Gateway

    try:
        config = load_cell(cell)
    except CellError as exc:
        fail(EXIT_USAGE, str(exc))
    logging.basicConfig(level=level, stream=sys.stderr, format="%(asctime)s %(name)s: %(message)s")
    # asyncua logs every session and request at INFO; its warnings and errors still show.
    logging.getLogger("asyncua").setLevel(max(level, logging.WARNING))
    import asyncio  # here: every kvp call imports this module (kvp read runs without asyncio)

    try:
        asyncio.run(_serve(Gateway(config)))
    except OSError as exc:
        fail(3, f"cannot serve {config.endpoint}: {exc.strerror or exc}")


async def _serve(gw: Gateway) -> None:
    import asyncio

    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    async with gw:
        # the address space lives as long as the process: keep it out of every later garbage
        # collection (a full one over it would pause the polls for a good fraction of a second)
        gc.freeze()
        print(f"serving {gw.url}", flush=True)
        if gw.fingerprint:
            print(f"certificate SHA-256 {gw.fingerprint}", flush=True)
        await stop.wait()


def _print_hash() -> None:
    from pyopenshowvar_apps.gateway.security import hash_password

    first = typer.prompt("password", hide_input=True)
    if typer.prompt("again", hide_input=True) != first:
        fail(EXIT_USAGE, "the passwords differ")
    if len(first) < 8:
        fail(EXIT_USAGE, "use at least 8 characters")
    typer.echo(hash_password(first))


def register(app: typer.Typer) -> None:
    app.command("gateway")(gateway)
