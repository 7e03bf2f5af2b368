"""The ``kvp`` command line: read, write, watch, record, benchmark and discover KRL variables.

Only the global options live here. Each subcommand group is a module of
:mod:`pyopenshowvar_apps.commands` with a ``register(app)`` function, found automatically (add
a command by adding a module there). The group is lazy (:class:`~.commands.LazyCommands`):
``kvp read`` builds and imports the ``read`` command only, never the case studies, the
monitor's Textual, the web stack or numpy, so a shell loop of ``kvp read`` starts fast.

Exit codes (also in ``kvp --help``) let shell scripts react precisely:

====  ==========================================================
0     success
1     unexpected internal error (a bug; ``KVP_DEBUG=1`` shows the traceback)
2     usage error (bad option or argument, a VALUE that is not a KRL literal, a missing extra)
3     cannot connect / connection lost (``discover``: nothing answered)
4     timeout
5     unknown variable or refused write
6     protocol or value-parse error
7     write accepted, but the robot program stopped right after it
====  ==========================================================

Errors are one line on stderr naming host, port and variable (a bad literal adds a caret
line), never a traceback.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from typing import Annotated, Any

import typer
from typer.core import TyperGroup

from pyopenshowvar.extras import explain
from pyopenshowvar_apps.commands import LazyCommands
from pyopenshowvar_apps.common import (
    EXIT_BUG,
    EXIT_CONNECTION,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_PROTOCOL,
    EXIT_STOPPED,
    EXIT_TIMEOUT,
    EXIT_USAGE,
    EXIT_VARIABLE,
    Opts,
    check_port,
    check_seconds,
    plant_choice,
    robot_choice,
    stop_embedded_emulator,
    to_jsonable,
)
from pyopenshowvar_apps.fastparams import speed_up

__all__ = [
    "EXIT_CONNECTION",
    "EXIT_OK",
    "EXIT_PROTOCOL",
    "EXIT_STOPPED",
    "EXIT_TIMEOUT",
    "EXIT_USAGE",
    "EXIT_VARIABLE",
    "app",
    "hoist_global_options",
    "main",
    "to_jsonable",
]

#: The global options that take a value, and the global flags.
GLOBAL_VALUED = frozenset({"-H", "--host", "-p", "--port", "-t", "--timeout", "--plant", "--robot"})
GLOBAL_FLAGS = frozenset({"--emulate"})


def _option_key(token: str) -> tuple[str, bool]:
    """``--port=7001`` → (``--port``, True); ``-p7001`` → (``-p``, True); ``-p`` → (``-p``, False)."""
    if token.startswith("--") and "=" in token:
        return token.split("=", 1)[0], True
    if token[:2] in GLOBAL_VALUED and len(token) > 2 and not token.startswith("--"):
        return token[:2], True
    return token, False


def hoist_global_options(
    args: Sequence[str], command_options: dict[str, bool] | None, command_index: int
) -> list[str]:
    """Move global options written after the subcommand in front of it.

    ``args[command_index]`` is the subcommand; ``command_options`` maps each of its own
    option names to whether it takes a value (its own names win: ``discover --timeout`` stays
    discover's), or is None for a pass-through command (``emu``) whose arguments all belong to
    it. Values of the command's own options are skipped, never taken for global options, and
    nothing after ``--`` moves.
    """
    args = list(args)
    if command_options is None:
        return args
    moved: list[str] = []
    kept: list[str] = []
    i = command_index + 1
    while i < len(args):
        token = args[i]
        if token == "--":
            kept += args[i:]
            break
        key, inline = _option_key(token)
        if key in command_options:
            takes_value = command_options[key] and not inline
            kept += args[i : i + (2 if takes_value else 1)]
            i += 2 if takes_value else 1
        elif key in GLOBAL_VALUED:
            width = 1 if inline else 2
            if i + width > len(args):
                raise typer.BadParameter("needs a value", param_hint=f"'{key}'")
            moved += args[i : i + width]
            i += width
        elif key in GLOBAL_FLAGS:
            moved.append(token)
            i += 1
        else:
            kept.append(token)
            i += 1
    return [*args[:command_index], *moved, args[command_index], *kept]


GLOBAL_EPILOG = (
    "Global options (-H/--host, -p/--port, -t/--timeout, --emulate, --plant, --robot) may come"
    " before or "
    "after the command name; see kvp --help."
)


class KvpGroup(TyperGroup):
    """The ``kvp`` group: subcommands built on first use; global options also after them."""

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        # the commands are built with the app's settings, as typer builds an eager group's
        settings: dict[str, object] = {"rich_markup_mode": self.rich_markup_mode}
        if hasattr(self, "suggest_commands"):  # typer >= 0.16
            settings["suggest_commands"] = self.suggest_commands
        lazy = LazyCommands(**settings)
        lazy.update(self.commands)  # commands added to ``app`` directly, if any
        self.commands = lazy
        speed_up(self)

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        command = super().get_command(ctx, cmd_name)
        if command is not None and _own_options(command) is not None and not command.epilog:
            command.epilog = GLOBAL_EPILOG
        return speed_up(command)

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        index = _command_index(args)
        if index is not None:
            command = self.get_command(ctx, args[index])
            if command is not None:
                args = hoist_global_options(args, _own_options(command), index)
        return super().parse_args(ctx, args)


def _command_index(args: Sequence[str]) -> int | None:
    """Where the subcommand name is: the first token that is not a global option or its value."""
    i = 0
    while i < len(args):
        key, inline = _option_key(args[i])
        if key in GLOBAL_VALUED:
            i += 1 if inline else 2
        elif args[i].startswith("-"):
            i += 1  # a flag (--emulate, --help) or a mistake click will report
        else:
            return i
    return None


def _own_options(command: Any) -> dict[str, bool] | None:
    """The command's option names → takes a value; None when it passes every argument on."""
    settings = getattr(command, "context_settings", None) or {}
    if settings.get("allow_extra_args") and settings.get("ignore_unknown_options"):
        return None
    names: dict[str, bool] = {}
    for param in getattr(command, "params", []):
        if getattr(param, "param_type_name", "") != "option":
            continue
        takes_value = not (getattr(param, "is_flag", False) or getattr(param, "count", False))
        for name in [*param.opts, *getattr(param, "secondary_opts", [])]:
            names[name] = takes_value
    return names


app = typer.Typer(
    name="kvp",
    cls=KvpGroup,
    help="Read, write, watch, record and benchmark KUKA KRL variables through KUKAVARPROXY "
    "(TCP 7000); an interactive console (repl) and a live monitor. The options below may "
    "also follow the command (kvp read '$OV_PRO' --port 7001).\n\n"
    "Exit codes: 0 ok, 2 usage, 3 connection, 4 timeout, 5 unknown variable / refused write, "
    "6 protocol or parse error, 7 write accepted but the robot program stopped.",
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
        int,
        typer.Option(
            "--port", "-p", envvar="KVP_PORT", callback=check_port, help="Proxy TCP port."
        ),
    ] = 7000,
    timeout: Annotated[
        float,
        typer.Option(
            "--timeout",
            "-t",
            envvar="KVP_TIMEOUT",
            callback=check_seconds,
            help="Seconds per request (> 0), and for connecting: a proxy that refuses is asked"
            " again until then (one started a moment before is still loading).",
        ),
    ] = 2.0,
    emulate: Annotated[
        bool,
        typer.Option(
            "--emulate",
            help="Talk to an embedded emulator instead (the case studies start one running "
            "the program they need).",
        ),
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
    robot: Annotated[
        str,
        typer.Option(
            "--robot",
            metavar="NAME|FILE",
            help="Which KUKA arm: the embedded emulator's (--emulate; default the KR 6 R900"
            " sixx), and the one the web pad, monitor and gateway draw (default: the one the"
            " robot's $MODEL_NAME[] names). A catalogue name (kvp arms list) or an arm file.",
            callback=robot_choice,
        ),
    ] = "",
) -> None:
    Opts.reset(host, port, timeout, emulate)
    Opts.plant = plant
    Opts.robot = robot
    ctx.call_on_close(stop_embedded_emulator)


def main() -> None:
    """Console-script entry point.

    Every expected failure already ends in one ``kvp:`` line and a documented exit code; an
    exception that still arrives here is a bug. It too gets one line (exit 1) instead of a
    traceback, unless ``KVP_DEBUG`` is set.
    """
    try:
        app()
    except KeyboardInterrupt:  # pragma: no cover - interactive
        sys.exit(EXIT_INTERRUPTED)
    except Exception as exc:
        if os.environ.get("KVP_DEBUG"):
            raise
        # a command whose optional extra is not installed (kvp gateway without asyncua, an
        # --emulate run without MuJoCo) is a setup step to name, not a bug
        missing = explain(exc) if isinstance(exc, ModuleNotFoundError) else None
        if missing is not None:
            print(f"kvp: {missing}", file=sys.stderr)
            sys.exit(EXIT_USAGE)
        print(
            f"kvp: unexpected error {type(exc).__name__}: {exc} "
            "(a bug: KVP_DEBUG=1 shows the traceback for a report)",
            file=sys.stderr,
        )
        sys.exit(EXIT_BUG)
