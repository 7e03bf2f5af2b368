"""The interactive ``kvp`` commands: ``repl`` and ``monitor``.

Only typer is imported here; prompt_toolkit and Textual are imported when the command runs,
so the other subcommands start fast. ``--emulate`` is the global flag (before or after the
command name).
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Annotated

import typer

from pyopenshowvar import KvpError
from pyopenshowvar_apps.common import EXIT_USAGE, Opts, check_window, fail, fail_for
from pyopenshowvar_apps.writecheck import STOP_WINDOW, STOP_WINDOW_HELP


def repl(
    config: Annotated[
        list[Path] | None,
        typer.Option("--config", help="$CONFIG.DAT whose globals are offered for completion."),
    ] = None,
    history: Annotated[
        Path | None,
        typer.Option(
            "--history", envvar="KVP_HISTORY", help="History file [~/.local/share/kvp/history]."
        ),
    ] = None,
    raw: Annotated[bool, typer.Option("--raw", help="Print raw text instead of tables.")] = False,
    stop_window: Annotated[
        float, typer.Option("--stop-window", callback=check_window, help=STOP_WINDOW_HELP)
    ] = STOP_WINDOW,
) -> None:
    """Interactive console: NAME reads, NAME VALUE writes, :watch, :help, :quit (Tab completes)."""
    host, port = Opts.endpoint()
    from pyopenshowvar_apps.names import completion_names
    from pyopenshowvar_apps.repl import default_history_path, run_repl

    store = Opts.emulator.store if Opts.emulator is not None else None
    try:
        names = completion_names(store, config or [])
    except (OSError, ValueError) as exc:
        fail(EXIT_USAGE, f"cannot read --config: {exc}")
    try:
        code = asyncio.run(
            run_repl(
                host,
                port,
                Opts.timeout,
                names=names,
                history=history or default_history_path(),
                raw=raw,
                stop_window=stop_window,
            )
        )
    except KvpError as exc:
        fail_for(exc)
    raise typer.Exit(code)


def monitor(
    hz: Annotated[float, typer.Option("--hz", help="Refreshes per second.")] = 10.0,
    watch_file: Annotated[
        Path | None,
        typer.Option(
            "--watch-file",
            envvar="KVP_MONITOR_FILE",
            help="Watch-list JSON [~/.config/kvp/monitor.json].",
        ),
    ] = None,
    stop_window: Annotated[
        float, typer.Option("--stop-window", callback=check_window, help=STOP_WINDOW_HELP)
    ] = STOP_WINDOW,
) -> None:
    """Live Textual dashboard: joints, pose, torques, plots, status and a watch list."""
    if not 0 < hz <= 50:
        fail(EXIT_USAGE, f"--hz must be in (0, 50], got {hz:g}")
    host, port = Opts.endpoint()
    from pyopenshowvar_apps.armpick import given_arm
    from pyopenshowvar_apps.monitor.app import MonitorApp
    from pyopenshowvar_apps.monitor.watchlist import default_watch_file

    app = MonitorApp(
        host,
        port,
        timeout=Opts.timeout,
        hz=hz,
        watch_file=watch_file or default_watch_file(),
        emulated=Opts.emulator is not None,
        stop_window=stop_window,
        arm=given_arm(Opts.robot) if Opts.robot else None,
    )
    app.run()
