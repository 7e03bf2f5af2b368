"""The ``kvp`` command line: read and write KRL variables from a terminal.

Exit codes (also in ``kvp --help``) let shell scripts react precisely:

====  ==========================================================
0     success
2     usage error (bad option or argument)
3     cannot connect / connection lost
4     timeout
5     unknown variable or refused write
6     protocol or value-parse error
====  ==========================================================

Errors are one line on stderr naming host, port and variable, never a traceback.
"""

from __future__ import annotations

import asyncio
import json
import math
import sys
from collections.abc import Awaitable, Callable
from typing import Annotated, Any, TypeVar

import typer

from pyopenshowvar import (
    Client,
    KrlEnum,
    KvpConnectionError,
    KvpError,
    KvpTimeoutError,
    ProtocolError,
    Struct,
    UnknownVariableError,
    WriteRefusedError,
)
from pyopenshowvar.errors import KrlValueError, ReadFailedError

EXIT_OK = 0
EXIT_USAGE = 2
EXIT_CONNECTION = 3
EXIT_TIMEOUT = 4
EXIT_VARIABLE = 5
EXIT_PROTOCOL = 6

T = TypeVar("T")

app = typer.Typer(
    name="kvp",
    help="Read and write KUKA KRL variables through KUKAVARPROXY (TCP 7000).\n\n"
    "Exit codes: 0 ok, 2 usage, 3 connection, 4 timeout, 5 unknown variable / refused write, "
    "6 protocol or parse error.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


class _Opts:
    host = "127.0.0.1"
    port = 7000
    timeout = 2.0
    emulator: Any = None


@app.callback()
def _global(
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
) -> None:
    _Opts.host, _Opts.port, _Opts.timeout = host, port, timeout
    if emulate:
        _start_embedded_emulator()


def _start_embedded_emulator() -> None:
    """An in-process emulator on an ephemeral port, stopped when the command ends."""
    import atexit

    from kukavarproxy_emu import EmulatorConfig, EmulatorThread

    thread = EmulatorThread(EmulatorConfig(host="127.0.0.1", port=0))
    thread.start()
    atexit.register(thread.stop)
    _Opts.emulator = thread
    _Opts.host, _Opts.port = "127.0.0.1", thread.port


def _fail(code: int, message: str) -> None:
    typer.echo(f"kvp: {message}", err=True)
    raise typer.Exit(code)


def _run(job: Callable[[Client], Awaitable[T]]) -> T:
    """Run ``job`` with a connected client, turning every library error into one line + exit code."""

    async def main() -> T:
        async with Client(_Opts.host, _Opts.port, timeout=_Opts.timeout, keepalive=None) as kvp:
            return await job(kvp)

    where = f"{_Opts.host}:{_Opts.port}"
    try:
        return asyncio.run(main())
    except KvpTimeoutError as exc:
        _fail(EXIT_TIMEOUT, f"timeout talking to {where}: {exc}")
    except KvpConnectionError as exc:
        _fail(EXIT_CONNECTION, str(exc) if where in str(exc) else f"{where}: {exc}")
    except (UnknownVariableError, WriteRefusedError, ReadFailedError) as exc:
        _fail(EXIT_VARIABLE, str(exc))
    except (ProtocolError, KrlValueError) as exc:
        _fail(EXIT_PROTOCOL, f"{where}: {exc}")
    except KvpError as exc:  # pragma: no cover - every subclass is handled above
        _fail(EXIT_PROTOCOL, f"{where}: {exc}")
    raise AssertionError("unreachable")  # pragma: no cover


def to_jsonable(value: Any) -> Any:
    """KRL values as plain JSON: structs become objects with a ``"type"`` key."""
    if isinstance(value, Struct):
        out: dict[str, Any] = {"type": value.type_name}
        out.update({k: to_jsonable(v) for k, v in value.members.items()})
        return out
    if isinstance(value, KrlEnum):
        return str(value)
    if isinstance(value, list):
        return [to_jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


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

    values = _run(job)
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
    typer.echo(_run(lambda kvp: kvp.write(name, value)))


@app.command()
def emu(ctx: typer.Context) -> None:
    """Run the KUKAVARPROXY emulator in the foreground (options as kukavarproxy-emu)."""
    from kukavarproxy_emu.__main__ import main as emu_main

    raise typer.Exit(emu_main(list(ctx.args)))


emu_cmd = app.registered_commands[-1]
emu_cmd.context_settings = {"allow_extra_args": True, "ignore_unknown_options": True}


def main() -> None:
    """Console-script entry point."""
    try:
        app()
    except KeyboardInterrupt:  # pragma: no cover - interactive
        sys.exit(130)
