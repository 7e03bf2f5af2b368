"""``kvp web``: serve the phone-friendly jog pad with a live 3D view of the robot.

The first line printed is ``serving on http://HOST:PORT/``. Bound beyond loopback, a token
is required; it is printed with the page's address and a QR code of it for a phone. Only
typer is imported at module level: the web stack loads when the command runs.
"""

from __future__ import annotations

import asyncio
import contextlib
import secrets
import shutil
from pathlib import Path
from typing import Annotated

import typer

from pyopenshowvar_apps.common import EXIT_USAGE, Opts, fail, start_embedded_emulator

__all__ = ["web"]

_KRL_FILES = ("kvp_jog.src", "kvp_jog_config.dat")


def web(
    ctx: typer.Context,
    bind: Annotated[
        str,
        typer.Option("--bind", help="Address to serve on; beyond loopback a token is required."),
    ] = "127.0.0.1",
    http_port: Annotated[
        int, typer.Option("--http-port", help="HTTP port (0 picks a free one).")
    ] = 8080,
    token: Annotated[
        str | None,
        typer.Option(
            "--token",
            envvar="KVP_WEB_TOKEN",
            help="Require this token (default: a random one when bound beyond loopback).",
        ),
    ] = None,
    hz: Annotated[float, typer.Option("--hz", help="Live updates per second.")] = 20.0,
    allow_motion_writes: Annotated[
        bool,
        typer.Option(
            "--allow-motion-writes",
            help="Let the watch list write variables that can move the robot or change how it"
            " moves ($OV_PRO, $ system variables, the CLI's motion variables). Off by default;"
            " the jog program's own variables are never writable from a page.",
        ),
    ] = False,
    krl_dir: Annotated[
        Path | None,
        typer.Option(
            "--krl-dir",
            help="Write the KVP_JOG program and its $CONFIG.DAT globals to this folder and exit.",
        ),
    ] = None,
) -> None:
    """Phone-friendly web jog pad: live 3D view, hold-to-move jog, watch list.

    With the global --emulate, an embedded emulator runs the KVP_JOG program.
    """
    from pyopenshowvar_apps.hosts import is_loopback
    from pyopenshowvar_apps.web.runner import KRL_DIR

    if krl_dir is not None:
        krl_dir.mkdir(parents=True, exist_ok=True)
        for name in _KRL_FILES:
            shutil.copyfile(KRL_DIR / name, krl_dir / name)
            typer.echo(str(krl_dir / name))
        return
    if not 0 < hz <= 50:
        fail(EXIT_USAGE, f"--hz must be in (0, 50], got {hz:g}")
    if not 0 <= http_port <= 65535:
        fail(EXIT_USAGE, f"--http-port must be 0..65535, got {http_port}")
    if token is not None and len(token) < 8:
        fail(EXIT_USAGE, "--token must be at least 8 characters")
    if Opts.emulate:
        start_embedded_emulator(
            ctx,
            program=str(KRL_DIR / "kvp_jog.src"),
            config_files=[KRL_DIR / "kvp_jog_config.dat"],
        )
    if token is None and not is_loopback(bind):
        token = secrets.token_urlsafe(12)

    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(_serve(bind, http_port, token, hz, allow_motion_writes))


async def _serve(
    bind: str, http_port: int, token: str | None, hz: float, allow_motion_writes: bool
) -> None:
    """Serve the pad until Ctrl-C, saying where and how to open it."""
    from pyopenshowvar_apps.armpick import given_arm
    from pyopenshowvar_apps.hosts import is_loopback
    from pyopenshowvar_apps.web.runner import WebServer, lan_address

    try:
        server = WebServer(
            Opts.host,
            Opts.port,
            bind=bind,
            http_port=http_port,
            token=token,
            hz=hz,
            timeout=Opts.timeout,
            emulated=Opts.emulator is not None,
            allow_motion_writes=allow_motion_writes,
            arm=given_arm(Opts.robot) if Opts.robot else None,
        )
    except OSError as exc:
        fail(EXIT_USAGE, f"cannot serve on {bind}:{http_port}: {exc.strerror or exc}")
    async with server:
        typer.echo(f"serving on {server.url}")
        host = lan_address() if bind in ("0.0.0.0", "::") else bind
        typer.echo(f"robot: KVP {Opts.where()}" + (" (embedded emulator)" if Opts.emulator else ""))
        if allow_motion_writes:
            typer.echo("the watch list may write variables that move the robot")
        if token is not None:
            typer.echo(f"token: {token}")
        typer.echo(f"open {server.page_url(host)}")
        if token is not None and not is_loopback(bind):
            _print_qr(server.page_url(host))
        typer.echo("Ctrl-C stops the server (and any jog).")
        await server.wait()


def _print_qr(url: str) -> None:
    import segno

    segno.make(url, error="m").terminal(compact=True)
