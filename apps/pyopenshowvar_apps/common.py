"""Shared plumbing of the ``kvp`` tools: options, exit codes, error lines, the embedded emulator.

Every subcommand goes through :func:`run` (or :func:`fail_for` for long-running loops), so
each library error becomes exactly one line on stderr that names host, port and variable,
and a documented exit code — never a traceback:

====  ==========================================================
0     success
1     unexpected internal error (a bug; ``KVP_DEBUG=1`` shows the traceback)
2     usage error (bad option or argument)
3     cannot connect / connection lost (also: ``discover`` found nothing)
4     timeout
5     unknown variable or refused write
6     protocol or value-parse error
7     write accepted, but the robot program stopped right after it
====  ==========================================================

This module must stay cheap to import: ``kvp read`` is on the hot path of shell scripts.
"""

from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from contextlib import asynccontextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn, TypeVar

import typer

from pyopenshowvar import (
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

if TYPE_CHECKING:
    from pyopenshowvar import Client, sync

EXIT_OK = 0
EXIT_BUG = 1  # an unexpected exception reached the entry point: a bug, reported in one line
EXIT_USAGE = 2
EXIT_CONNECTION = 3
EXIT_TIMEOUT = 4
EXIT_VARIABLE = 5
EXIT_PROTOCOL = 6
EXIT_STOPPED = 7
EXIT_INTERRUPTED = 130

#: Seconds a write is watched for a program stop (a few interpolation cycles of 12 ms; the
#: emulator stops a PTP beyond a software limit within two of them). Here, not in
#: :mod:`.writecheck`, so the ``kvp write`` signature does not import it for ``kvp read``.
STOP_WINDOW = 0.2
STOP_WINDOW_HELP = (
    "Seconds to watch $PRO_STATE1/$STOPMESS for a program stop after a write (0: do not watch)."
)

#: Seconds between two attempts to connect to a proxy that refuses (see connect_blocking).
CONNECT_RETRY = 0.1

T = TypeVar("T")


class Opts:
    """The global options of one ``kvp`` invocation (set by the typer callback).

    ``--emulate`` only records the wish (:attr:`emulate`): a command that talks to "the robot"
    asks :meth:`endpoint`, which starts the default embedded emulator on first use, while the
    case studies start one running the program they need. So ``kvp --emulate CMD`` and
    ``kvp CMD --emulate`` mean the same for every command.
    """

    host = "127.0.0.1"
    port = 7000
    timeout = 2.0
    emulate = False
    emulator: Any = None
    #: The embedded emulator's plant (``--plant``): "dynamic" or "ideal".
    plant = "dynamic"
    #: ``--robot NAME|FILE``: the embedded emulator's arm, and the arm the views draw
    #: instead of the one ``$MODEL_NAME[]`` names ("" = the connected robot's own).
    robot = ""
    #: Undoes the quieter log of the embedded emulator (see ``_quiet_emulator_log``).
    log_restore: Callable[[], None] | None = None

    @classmethod
    def reset(cls, host: str, port: int, timeout: float, emulate: bool) -> None:
        cls.host, cls.port, cls.timeout, cls.emulate = host, port, timeout, emulate
        cls.emulator = None

    @classmethod
    def where(cls) -> str:
        return f"{cls.host}:{cls.port}"

    @classmethod
    def endpoint(cls) -> tuple[str, int]:
        """Host and port to talk to; starts the embedded emulator when ``--emulate`` asked."""
        if cls.emulate and cls.emulator is None:
            start_embedded_emulator()
        return cls.host, cls.port


def plant_choice(value: str) -> str:
    """Validate a ``--plant`` option (typer callback)."""
    if value not in ("dynamic", "ideal"):
        raise typer.BadParameter(f"{value!r} is not one of 'dynamic', 'ideal'")
    return value


def robot_choice(value: str) -> str:
    """Validate a ``--robot`` option (typer callback): a KUKA six-axis arm the emulator can
    be and the views can draw (a catalogue name or an arm file); "" passes through."""
    if not value:
        return value
    from kukavarproxy_emu.robots import resolve_robot

    try:
        resolve_robot(value)
    except ValueError as exc:
        raise typer.BadParameter(str(exc).removeprefix(f"--robot {value}: ")) from None
    return value


def calibration_choice(value: str | None) -> str | None:
    """Validate a ``--calibration-error`` option (typer callback): a seed (an integer >= 0) or
    ``off``; None (not given) passes through. :func:`calibration_seed` converts it."""
    if value is None or value.lower() in ("off", "none"):
        return value
    try:
        seed = int(value)
    except ValueError:
        seed = -1
    if seed < 0:
        raise typer.BadParameter(f"{value!r} is not a seed (an integer >= 0) or 'off'")
    return value


def calibration_seed(value: str | None, default: int | None = None) -> int | None:
    """The calibration-error seed of a validated ``--calibration-error`` (None: the nominal
    robot, a perfect model); ``default`` when the option was not given."""
    if value is None:
        return default
    return None if value.lower() in ("off", "none") else int(value)


#: ``--calibration-error`` of the case-study commands (used with ``--emulate``).
CALIBRATION_HELP = (
    "With --emulate: the physical robot differs from the nominal model (geometry, masses, "
    "inertia, friction) by a realistic error drawn with this seed; 'off': a perfect model."
)


def calibration_option(help_text: str = CALIBRATION_HELP) -> Any:
    """The ``--calibration-error SEED|off`` option (for ``Annotated[str | None, ...]``)."""
    return typer.Option(
        "--calibration-error", metavar="SEED|off", callback=calibration_choice, help=help_text
    )


def check_port(value: int) -> int:
    """typer callback: a TCP/UDP port a client can connect to (1..65535)."""
    if not 1 <= value <= 0xFFFF:
        raise typer.BadParameter(f"{value} is not a port (1..65535)")
    return value


def check_seconds(value: float) -> float:
    """typer callback: a finite, positive number of seconds."""
    if not (math.isfinite(value) and value > 0):
        raise typer.BadParameter(f"{value:g} is not a positive number of seconds")
    return value


def check_window(value: float) -> float:
    """typer callback: a finite number of seconds >= 0 (0: off)."""
    if not (math.isfinite(value) and value >= 0):
        raise typer.BadParameter(f"{value:g} is not a number of seconds >= 0")
    return value


def start_embedded_emulator(
    ctx: typer.Context | None = None,
    *,
    program: str | None = None,
    config_files: Sequence[Path] = (),
) -> Any:
    """An in-process emulator on an ephemeral port; :func:`stop_embedded_emulator` ends it.

    Idempotent: ``kvp --emulate monitor --emulate`` starts one emulator only. It answers UDP
    discovery on an ephemeral port too (to the asker's own port), so ``kvp --emulate
    discover`` finds it. ``ctx`` (optional) stops it when that command ends; under ``kvp`` the
    top-level command always does. A command that needs its own robot program (``kvp
    --emulate web`` runs KVP_JOG) passes ``program`` and the ``$CONFIG.DAT`` files it needs;
    an emulator already running another program is replaced.
    """
    if Opts.emulator is not None:
        if program is None or Opts.emulator.config.program == program:
            return Opts.emulator
        Opts.emulator.stop()
        Opts.emulator = None
    from kukavarproxy_emu import EmulatorConfig, EmulatorThread

    extra: dict[str, Any] = {}
    if program is not None:
        extra = {"program": program, "config_files": tuple(config_files)}
    config = EmulatorConfig(
        host="127.0.0.1",
        port=0,
        discovery=True,
        udp_port=0,
        udp_reply_port=0,
        plant=Opts.plant,
        arm=Opts.robot,
        **extra,
    )
    _quiet_emulator_log()
    Opts.emulator = EmulatorThread(config).start()
    Opts.host, Opts.port = "127.0.0.1", Opts.emulator.port
    if ctx is not None:
        ctx.find_root().call_on_close(stop_embedded_emulator)
    return Opts.emulator


class _EmulatorErrors(logging.Handler):
    """The embedded emulator's errors on stderr as ``kvp: emulator: ...`` lines."""

    def __init__(self) -> None:
        super().__init__(logging.ERROR)

    def emit(self, record: logging.LogRecord) -> None:
        typer.echo(f"kvp: emulator: {record.getMessage()}", err=True)


def _quiet_emulator_log() -> None:
    """Show only the embedded emulator's errors (all of its log with ``KVP_DEBUG=1``), until
    :func:`stop_embedded_emulator`.

    It stands in for the robot, and a robot prints nothing on your terminal: the commands
    report what it does themselves (``kvp write`` says that the program stopped and why), so
    its own warnings only said the same twice (the stop message), and would break the
    monitor's screen. What it would warn about stays readable: ``$PRO_STATE1``, ``$STOPMESS``,
    ``$EMU_MESSAGE[]``.
    """
    logger = logging.getLogger("kukavarproxy_emu")
    if os.environ.get("KVP_DEBUG") or any(isinstance(h, _EmulatorErrors) for h in logger.handlers):
        return
    handler, propagate = _EmulatorErrors(), logger.propagate
    logger.addHandler(handler)
    logger.propagate = False

    def restore() -> None:  # the CLI also runs in-process (tests): leave logging as it was
        logger.removeHandler(handler)
        logger.propagate = propagate

    Opts.log_restore = restore


def stop_embedded_emulator() -> None:
    """Stop the emulator :func:`start_embedded_emulator` started, if any (idempotent).

    Called when the command ends, not at interpreter exit: the CLI also runs in-process
    (typer's CliRunner, scripts calling the app), where an atexit hook would leave the emulator
    and its robot ticking in a background thread for the rest of the process.
    """
    thread, Opts.emulator = Opts.emulator, None
    if thread is not None:
        thread.stop()
    restore, Opts.log_restore = Opts.log_restore, None
    if restore is not None:
        restore()


def fail(code: int, message: str) -> NoReturn:
    """Print ``kvp: message`` on stderr and exit with ``code``."""
    typer.echo(f"kvp: {message}", err=True)
    raise typer.Exit(code)


def classify(exc: BaseException) -> tuple[int, str]:
    """The exit code and the one-line message for a library error."""
    where = Opts.where()
    if isinstance(exc, KvpTimeoutError):
        return EXIT_TIMEOUT, f"timeout talking to {where}: {exc}"
    if isinstance(exc, KvpConnectionError):
        text = str(exc)
        return EXIT_CONNECTION, text if where in text else f"{where}: {text}"
    if isinstance(exc, UnknownVariableError | WriteRefusedError | ReadFailedError):
        return EXIT_VARIABLE, str(exc)
    if isinstance(exc, ProtocolError | KrlValueError):
        return EXIT_PROTOCOL, f"{where}: {exc}"
    if isinstance(exc, OSError):
        return EXIT_CONNECTION, f"{where}: {exc.strerror or exc}"
    return EXIT_PROTOCOL, f"{where}: {exc}"


def fail_for(exc: BaseException) -> NoReturn:
    """Exit with the code and line :func:`classify` gives for ``exc``."""
    code, message = classify(exc)
    fail(code, message)


def make_client(**kw: Any) -> Client:
    """A client for the global host/port/timeout (no keep-alive unless asked)."""
    from pyopenshowvar import Client

    kw.setdefault("keepalive", None)
    host, port = Opts.endpoint()
    return Client(host, port, timeout=Opts.timeout, **kw)


def _refused(exc: KvpConnectionError) -> bool:
    return isinstance(exc.__cause__, ConnectionRefusedError)


@asynccontextmanager
async def open_client(**kw: Any) -> AsyncIterator[Client]:
    """:func:`make_client`, connected: a proxy that refuses the connection is asked again
    every ``CONNECT_RETRY`` seconds until ``--timeout`` (see :func:`connect_blocking`)."""
    import asyncio

    client = make_client(**kw)
    deadline = time.monotonic() + Opts.timeout
    try:
        while True:
            try:
                await client.connect()
                break
            except KvpConnectionError as exc:
                if not _refused(exc) or time.monotonic() + CONNECT_RETRY > deadline:
                    raise
            await asyncio.sleep(CONNECT_RETRY)
        yield client
    finally:
        await client.close()


def connect_blocking(client: sync.Client) -> None:
    """Connect ``client``, asking a proxy that refuses again until ``--timeout``.

    A refused connection is an answer, but often a passing one: an emulator started in the
    background a moment before (``kukavarproxy-emu ... &`` and then ``kvp read`` on the next
    line of a script) refuses until it has loaded, which takes about a second. Other failures
    (no route, a timeout) are reported at once.
    """
    deadline = time.monotonic() + Opts.timeout
    while True:
        try:
            client.connect()
            return
        except KvpConnectionError as exc:
            if not _refused(exc) or time.monotonic() + CONNECT_RETRY > deadline:
                raise
        time.sleep(CONNECT_RETRY)


def run(job: Callable[[Client], Awaitable[T]], **client_kw: Any) -> T:
    """Run ``job`` with a connected client; every library error becomes one line + exit code."""

    async def main() -> T:
        async with open_client(**client_kw) as kvp:
            return await job(kvp)

    import asyncio  # not at module level: kvp read runs without it (run_blocking)

    try:
        return asyncio.run(main())
    except KvpError as exc:
        fail_for(exc)


def run_blocking(job: Callable[[sync.Client], T]) -> T:
    """:func:`run` with the blocking client: for one-shot commands (``kvp read``).

    Same endpoint, timeout, exceptions and exit codes; no event loop, so the command does not
    pay for importing asyncio (a shell loop of ``kvp read`` pays every import on every call).
    """
    from pyopenshowvar import sync

    host, port = Opts.endpoint()
    try:
        kvp = sync.Client(host, port, timeout=Opts.timeout, keepalive=None)
        connect_blocking(kvp)
        with kvp:
            return job(kvp)
    except KvpError as exc:
        fail_for(exc)


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


def flatten(name: str, value: Any) -> dict[str, Any]:
    """Split a typed value into columns: ``NAME.MEMBER`` for structs, ``NAME[i]`` for arrays."""
    if isinstance(value, Struct):
        out: dict[str, Any] = {}
        for key, member in value.members.items():
            out.update(flatten(f"{name}.{key}", member))
        return out
    if isinstance(value, list):
        base = name[:-2] if name.endswith("[]") else name
        out = {}
        for i, element in enumerate(value, start=1):
            out.update(flatten(f"{base}[{i}]", element))
        return out
    if isinstance(value, KrlEnum):
        return {name: str(value)}
    return {name: value}
