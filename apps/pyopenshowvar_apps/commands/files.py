"""``kvp files``: list, download, upload and delete files on the controller (C3 Bridge).

::

    kvp files ls 'KRC:\\R1\\Program' [-r] [--long]
    kvp files get 'KRC:\\R1\\Program\\CELL.src' [LOCAL]     # LOCAL '-' = stdout
    kvp files put LOCAL 'KRC:\\R1\\Program\\CELL.src' [--no-overwrite]
    kvp files rm 'KRC:\\R1\\Program\\OLD.src' [--force]

Paths are the controller's (``KRC:\\...``; ``/`` works too). Needs C3 Bridge (exit 6 before
sending anything on KUKAVARPROXY); refusals by the controller exit 5.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from pyopenshowvar_apps.c3cli import run_c3
from pyopenshowvar_apps.common import EXIT_USAGE, fail

if TYPE_CHECKING:
    from pyopenshowvar import Client

ORDER = 36
COMMANDS = ("files",)
#: Largest file ``put`` sends and ``get`` accepts by default.
MAX_FILE = 16 * 1024 * 1024

files_app = typer.Typer(
    name="files",
    help="List, download, upload and delete files on the controller (needs C3 Bridge).",
    no_args_is_help=True,
    add_completion=False,
    rich_markup_mode=None,
)


@files_app.command("ls")
def ls(
    path: Annotated[str, typer.Argument(help="Controller directory.")] = "KRC:\\R1\\Program",
    recursive: Annotated[bool, typer.Option("--recursive", "-r", help="Descend.")] = False,
    long: Annotated[
        bool, typer.Option("--long", "-l", help="Add the size (from each item's properties).")
    ] = False,
) -> None:
    """List a directory (directories end with a backslash)."""

    async def job(kvp: Client) -> list[str]:
        listing = await kvp.file_list(path, recursive=recursive)
        if not long:
            return list(listing.names)
        lines = []
        for name in listing.names:
            if name.endswith("\\"):
                lines.append(f"{'<DIR>':>10}  {name}")
                continue
            props = await kvp.file_properties(name)
            lines.append(f"{props.size:>10}  {name}")
        return lines

    for line in run_c3(job):
        typer.echo(line)


@files_app.command("get")
def get(
    remote: Annotated[str, typer.Argument(help="Controller file.")],
    local: Annotated[
        str | None, typer.Argument(help="Local file (default: its name here; - for stdout).")
    ] = None,
    max_size: Annotated[
        int, typer.Option("--max-size", help="Refuse files larger than this (bytes).")
    ] = MAX_FILE,
) -> None:
    """Download a file."""
    data = run_c3(lambda kvp: kvp.file_read(remote, max_size=max_size))
    if local == "-":
        sys.stdout.buffer.write(data)
        sys.stdout.flush()
        return
    target = Path(local) if local else Path(remote.replace("\\", "/").rsplit("/", 1)[-1])
    try:
        target.write_bytes(data)
    except OSError as exc:
        fail(EXIT_USAGE, f"cannot write {target}: {exc.strerror or exc}")
    typer.echo(f"{remote} -> {target} ({len(data)} bytes)")


@files_app.command("put")
def put(
    local: Annotated[Path, typer.Argument(help="Local file.")],
    remote: Annotated[str, typer.Argument(help="Controller file, e.g. KRC:\\R1\\Program\\X.src.")],
    overwrite: Annotated[
        bool, typer.Option("--overwrite/--no-overwrite", help="Replace an existing file.")
    ] = True,
) -> None:
    """Upload a file."""
    try:
        data = local.read_bytes()
    except OSError as exc:
        fail(EXIT_USAGE, f"cannot read {local}: {exc.strerror or exc}")
    if len(data) > MAX_FILE:
        fail(EXIT_USAGE, f"{local} is {len(data)} bytes; files over {MAX_FILE} are refused")
    size = run_c3(lambda kvp: kvp.file_write(remote, data, overwrite=overwrite))
    typer.echo(f"{local} -> {remote} ({size} bytes)")


@files_app.command("rm")
def rm(
    remote: Annotated[str, typer.Argument(help="Controller file or empty directory.")],
    force: Annotated[bool, typer.Option("--force", help="Delete a read-only file too.")] = False,
) -> None:
    """Delete a file."""
    run_c3(lambda kvp: kvp.file_delete(remote, always=force))
    typer.echo(f"deleted {remote}")


def register(app: typer.Typer) -> None:
    app.add_typer(files_app)
