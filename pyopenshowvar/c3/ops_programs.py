"""C3 Bridge program operations (#10, #20..#28) and the module upload, written once for both clients.

See :mod:`pyopenshowvar.c3.ops` for the contract. Programs: ``program_select`` a module by
KRC path (``KRC:\\R1\\Program\\CELL.SRC``) or module path (``/R1/CELL``), ``program_start`` /
``stop`` / ``reset`` / ``cancel`` one interpreter, ``program_run`` = select and start,
``program_state`` reads ``$PRO_STATE1`` & co. in one snapshot; ``program_upload`` writes a
module's ``.src`` and ``.dat`` with :mod:`.ops_files`' file operations.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import PurePosixPath, PureWindowsPath
from typing import Any

from ..core import Op
from ..errors import KvpError, ProtocolError
from .constants import Command, Interpreter, ProgramCommand
from .errors import RequestTooLargeError
from .messages import ProgramControl, ProgramSelect
from .ops import (
    _need_motion,
    check,
    read_multiple,
    send,
    server_info,
)
from .ops_files import file_write

__all__ = [
    "ProgramState",
    "program_cancel",
    "program_reset",
    "program_run",
    "program_select",
    "program_start",
    "program_state",
    "program_stop",
    "program_upload",
]

PROGRAM_FOLDER = "KRC:\\R1\\Program"
_STATE_NAMES = ("$PRO_STATE1", "$PRO_NAME1[]", "$PRO_STATE0", "$STOPMESS", "$EMU_MESSAGE[]")


@dataclass(frozen=True)
class ProgramState:
    """The robot interpreter's program as the controller reports it (one snapshot)."""

    #: ``P_FREE`` (none selected), ``P_RESET`` (selected), ``P_ACTIVE``, ``P_STOP``, ``P_END``.
    state: str
    #: ``$PRO_NAME1[]`` without quotes ("" when none).
    name: str
    #: The submit interpreter's state (``$PRO_STATE0``), None if unreadable.
    submit_state: str | None = None
    #: ``$STOPMESS``: a stop message is active (the program was stopped by an error).
    stop_message: bool | None = None
    #: The emulator's ``$EMU_MESSAGE[]`` (why it stopped); None on a real controller.
    message: str | None = None

    @property
    def running(self) -> bool:
        return self.state == "P_ACTIVE"


# --------------------------------------------------------------------------- programs


def _control(
    client: Any, command: ProgramCommand, interpreter: int, timeout: float | None
) -> Op[None]:
    what = f"program {command.name.lower()} ({Interpreter(interpreter).name.lower()} interpreter)"
    message = ProgramControl(command, interpreter)
    out = yield from send(client, message, f"program_{command.name.lower()}", what, timeout)
    check(client, out, what)


def program_start(
    client: Any,
    interpreter: int = Interpreter.ROBOT,
    *,
    allow_motion: bool = False,
    timeout: float | None = None,
) -> Op[None]:
    """Start (or resume) the selected program (#10 command 2). The robot interpreter's program
    moves the robot: ``allow_motion=True`` is required for it."""
    if interpreter == Interpreter.ROBOT:
        _need_motion(allow_motion, "starting the robot program")
    yield from _control(client, ProgramCommand.START, interpreter, timeout)


def program_stop(
    client: Any, interpreter: int = Interpreter.ROBOT, *, timeout: float | None = None
) -> Op[None]:
    """Stop the running program (#10 command 3); the robot halts on its path."""
    yield from _control(client, ProgramCommand.STOP, interpreter, timeout)


def program_reset(
    client: Any, interpreter: int = Interpreter.ROBOT, *, timeout: float | None = None
) -> Op[None]:
    """Reset the selected program to its first line (#10 command 1)."""
    yield from _control(client, ProgramCommand.RESET, interpreter, timeout)


def program_cancel(
    client: Any, interpreter: int = Interpreter.ROBOT, *, timeout: float | None = None
) -> Op[None]:
    """Deselect the program (#10 command 4)."""
    yield from _control(client, ProgramCommand.CANCEL, interpreter, timeout)


def _select(
    client: Any,
    command: ProgramCommand,
    name: str,
    parameters: str,
    force: bool,
    timeout: float | None,
) -> Op[None]:
    if not name.strip():
        raise ValueError("program name is empty")
    message = ProgramSelect(name, parameters, force, command)
    what = f"program {command.name.lower()} {name}"
    out = yield from send(client, message, f"program_{command.name.lower()}", what, timeout)
    check(client, out, what)


def program_select(
    client: Any,
    name: str,
    parameters: str = "",
    *,
    force: bool = False,
    timeout: float | None = None,
) -> Op[None]:
    """Select a program (#10 command 5): ``KRC:\\R1\\Program\\CELL.SRC`` or ``/R1/CELL``."""
    yield from _select(client, ProgramCommand.SELECT, name, parameters, force, timeout)


def program_run(
    client: Any,
    name: str,
    parameters: str = "",
    *,
    force: bool = False,
    allow_motion: bool = False,
    timeout: float | None = None,
) -> Op[None]:
    """Select and start a program in one message (#10 command 6): ``allow_motion=True``."""
    _need_motion(allow_motion, f"running {name}")
    yield from _select(client, ProgramCommand.RUN, name, parameters, force, timeout)


def program_state(client: Any, *, timeout: float | None = None) -> Op[ProgramState]:
    """``$PRO_STATE1``, ``$PRO_NAME1[]``, ``$PRO_STATE0``, ``$STOPMESS`` (and the emulator's
    ``$EMU_MESSAGE[]``) in one read-multiple on C3 Bridge, pipelined reads on KUKAVARPROXY."""
    info = yield from server_info(client, timeout=timeout)
    names = list(_STATE_NAMES)
    if info.supports(Command.READ_MULTIPLE):
        results = yield from read_multiple(client, names, timeout=timeout)
    else:
        results = yield ("read_many", (names,), {"timeout": timeout})
    text = {n: (r.text if r.ok else None) for n, r in results.items()}
    state = text["$PRO_STATE1"]
    if state is None:
        error = results["$PRO_STATE1"].error
        raise error if isinstance(error, KvpError) else ProtocolError("no $PRO_STATE1")
    stop = text["$STOPMESS"]
    return ProgramState(
        state=state.strip().lstrip("#"),
        name=(text["$PRO_NAME1[]"] or "").strip().strip('"'),
        submit_state=(text["$PRO_STATE0"] or "").strip().lstrip("#") or None,
        stop_message=None if stop is None else stop.strip().upper() == "TRUE",
        message=None
        if text["$EMU_MESSAGE[]"] is None
        else text["$EMU_MESSAGE[]"].strip().strip('"'),
    )


def program_upload(
    client: Any,
    src: bytes,
    src_name: str,
    dat: bytes | None = None,
    *,
    folder: str = PROGRAM_FOLDER,
    overwrite: bool = True,
    timeout: float | None = None,
) -> Op[str]:
    """Upload a KRL module (``.src`` and optionally its ``.dat``) into ``folder``; returns the
    KRC path of the ``.src`` (select it with :func:`program_select`). The ``.dat`` goes first,
    so the module is complete whenever its ``.src`` exists."""
    base = _module_name(src_name)
    folder = folder.rstrip("\\/")
    target = f"{folder}\\{base}.src"
    if dat is not None:
        yield from file_write(
            client, f"{folder}\\{base}.dat", dat, overwrite=overwrite, timeout=timeout
        )
    yield from file_write(client, target, src, overwrite=overwrite, timeout=timeout)
    return target


def _module_name(name: str) -> str:
    stem = PureWindowsPath(PurePosixPath(name).name).stem
    if not stem or not all(c.isalnum() or c == "_" for c in stem) or stem[0].isdigit():
        raise ValueError(
            f"{name!r}: a KRL module name is letters, digits and _ and starts with a letter"
        )
    if len(stem) > 24:
        raise RequestTooLargeError(f"module name {stem!r} is longer than KRL's 24 characters")
    return stem
