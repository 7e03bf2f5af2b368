"""C3 Bridge program and file operations (#10, #20..#30), written once for both clients.

See :mod:`pyopenshowvar.c3.ops` for the contract. Programs: ``program_select`` a module by
KRC path (``KRC:\\R1\\Program\\CELL.SRC``) or module path (``/R1/CELL``), ``program_start`` /
``stop`` / ``reset`` / ``cancel`` one interpreter, ``program_run`` = select and start,
``program_state`` reads ``$PRO_STATE1`` & co. in one snapshot. Files travel in chunks of at
most ``client._c3_chunk`` bytes through the server's upload (#29) and download (#30) buffers.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import PurePosixPath, PureWindowsPath
from typing import Any

from ..core import Op
from ..errors import KvpError, ProtocolError
from .constants import Command, CopyFlag, ErrorCode, Interpreter, ProgramCommand
from .errors import C3CommandError, RequestTooLargeError
from .files import (
    FileCopy,
    FileCreate,
    FileDelete,
    FileGetFullName,
    FileGetKrcName,
    FileGetProperties,
    FileMove,
    FileNameList,
    FileReadBegin,
    FileReadData,
    FileReadEnd,
    FileSetAttribute,
    FileWriteBegin,
    FileWriteData,
    FileWriteEnd,
    IoChunk,
    IoSize,
    IoWritten,
    NameList,
    Properties,
)
from .messages import Message, ProgramControl, ProgramSelect
from .ops import (
    _need_motion,
    _parse,
    check,
    encode,
    exchange,
    read_multiple,
    send,
    server_info,
)
from .replies import Outcome, Value

__all__ = [
    "MAX_DOWNLOAD",
    "ProgramState",
    "file_copy",
    "file_create",
    "file_delete",
    "file_full_name",
    "file_krc_name",
    "file_list",
    "file_move",
    "file_properties",
    "file_read",
    "file_set_attribute",
    "file_write",
    "program_cancel",
    "program_reset",
    "program_run",
    "program_select",
    "program_start",
    "program_state",
    "program_stop",
    "program_upload",
]

#: Largest file ``file_read`` accepts by default (a KRL module is a few KiB to a few MiB).
MAX_DOWNLOAD = 16 * 1024 * 1024
#: Where ``program_upload`` puts modules unless told otherwise.
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


# --------------------------------------------------------------------------- files


def _file_op(
    client: Any, message: Message, method: str, subject: str, timeout: float | None
) -> Op[Outcome]:
    """One file message of operation ``method`` on ``subject``, checked (with a hint)."""
    what = f"{method} of {subject}"
    out = yield from send(client, message, method, what, timeout)
    return _checked(client, out, what)


def _checked(client: Any, out: Outcome, what: str) -> Outcome:
    return check(client, out, what, _FILE_HINTS.get(out.code, ""))


#: What a file error code usually means on a controller.
_FILE_HINTS: dict[int, str] = {
    ErrorCode.ARGUMENT: "not a valid path on the controller (KRC:\\...)",
    ErrorCode.ACCESS: "read-only, or part of the selected program",
    ErrorCode.MEMORY: "too large for the controller's storage",
}


def file_list(
    client: Any,
    path: str = "KRC:\\",
    *,
    recursive: bool = False,
    item_type: int = 0,
    flags: int = 0,
    timeout: float | None = None,
) -> Op[NameList]:
    """Names (and info strings) of the items in a directory (#21)."""
    message = FileNameList(path, item_type, flags | (1 if recursive else 0))
    out = yield from _file_op(client, message, "file_list", path, timeout)
    listing: NameList = _parse(client, out, NameList, "#21")
    return listing


def file_properties(client: Any, name: str, *, timeout: float | None = None) -> Op[Properties]:
    """Type, size, attributes, times and edit mode of one item (#26)."""
    out = yield from _file_op(client, FileGetProperties(name), "file_properties", name, timeout)
    props: Properties = _parse(client, out, Properties, "#26")
    return props


def file_full_name(client: Any, path: str, *, timeout: float | None = None) -> Op[str]:
    """``/R1/TEST.SRC`` → ``KRC:\\R1\\PROGRAM\\TEST.SRC`` (#27)."""
    out = yield from _file_op(client, FileGetFullName(path), "file_full_name", path, timeout)
    value: str = _parse(client, out, Value, "#27").value
    return value


def file_krc_name(client: Any, path: str, *, timeout: float | None = None) -> Op[str]:
    """``KRC:\\R1\\PROGRAM\\TEST.SRC`` → ``/R1/TEST.SRC`` (#28)."""
    out = yield from _file_op(client, FileGetKrcName(path), "file_krc_name", path, timeout)
    value: str = _parse(client, out, Value, "#28").value
    return value


def file_delete(
    client: Any, name: str, *, always: bool = False, timeout: float | None = None
) -> Op[None]:
    """Delete a file (#23); ``always`` deletes a read-only one too."""
    yield from _file_op(client, FileDelete(name, always), "file_delete", name, timeout)


def file_create(
    client: Any,
    name: str,
    *,
    item_type: int = 0,
    module_part: int = 0,
    always: bool = False,
    template: str = "",
    timeout: float | None = None,
) -> Op[None]:
    """Create an empty file, module or directory (#22)."""
    message = FileCreate(name, item_type, module_part, always, template)
    yield from _file_op(client, message, "file_create", name, timeout)


def file_copy(
    client: Any, source: str, destination: str, *, flags: int = 0, timeout: float | None = None
) -> Op[None]:
    """Copy a file (#24); ``flags`` are :class:`CopyFlag` (e.g. ``OVERWRITE``)."""
    message = FileCopy(source, destination, flags)
    yield from _file_op(client, message, "file_copy", source, timeout)


def file_move(
    client: Any, source: str, destination: str, *, flags: int = 0, timeout: float | None = None
) -> Op[None]:
    """Move or rename a file (#25)."""
    message = FileMove(source, destination, flags)
    yield from _file_op(client, message, "file_move", source, timeout)


def file_set_attribute(
    client: Any, name: str, attributes: int, mask: int, *, timeout: float | None = None
) -> Op[None]:
    """Set the attributes under ``mask`` to ``attributes`` (#20), e.g. READ_ONLY."""
    message = FileSetAttribute(name, attributes, mask)
    yield from _file_op(client, message, "file_set_attribute", name, timeout)


def file_write(
    client: Any,
    name: str,
    data: bytes,
    *,
    overwrite: bool = True,
    timeout: float | None = None,
) -> Op[int]:
    """Upload ``data`` as file ``name`` (#29: begin, data chunks, end); returns its size."""
    data = bytes(data)
    if len(data) > 0xFFFFFFFF:
        raise RequestTooLargeError(f"{len(data)} bytes do not fit the protocol's 32-bit size")
    end = FileWriteEnd(name, int(CopyFlag.OVERWRITE) if overwrite else 0)
    encode(end)  # the name is refused before the upload starts
    what = f"upload of {name}"
    out = yield from send(client, FileWriteBegin(len(data)), "file_write", what, timeout)
    size: IoSize = _parse(client, _checked(client, out, what), IoSize, "#29 begin")
    if size.size != len(data):
        raise C3CommandError(
            what, out.code, endpoint=client.endpoint,
            detail=f"the server made a buffer of {size.size} bytes for {len(data)}",
        )  # fmt: skip
    chunk = max(1, int(client._c3_chunk))
    offset = 0
    while offset < len(data):
        piece = data[offset : offset + chunk]
        out = yield from exchange(client, FileWriteData(offset, piece), what, timeout)
        taken: IoWritten = _parse(client, check(client, out, what), IoWritten, "#29 data")
        if taken.offset != offset or taken.written != len(piece):
            raise C3CommandError(
                what, out.code, endpoint=client.endpoint,
                detail=f"{taken.written} of {len(piece)} bytes taken at offset {offset}",
            )  # fmt: skip
        offset += len(piece)
    out = yield from exchange(client, end, what, timeout)
    _checked(client, out, what)
    return len(data)


def file_read(
    client: Any, name: str, *, max_size: int = MAX_DOWNLOAD, timeout: float | None = None
) -> Op[bytes]:
    """Download file ``name`` (#30: begin, data chunks, end); at most ``max_size`` bytes."""
    what = f"download of {name}"
    out = yield from send(client, FileReadBegin(name), "file_read", what, timeout)
    size: IoSize = _parse(client, _checked(client, out, what), IoSize, "#30 begin")
    try:
        data = yield from _download(client, name, size.size, max_size, what, timeout)
    except GeneratorExit:  # the caller was cancelled: nothing more may be sent from here
        raise
    except BaseException:
        yield from _end_download(client, what, timeout)
        raise
    yield from _end_download(client, what, timeout)
    return data


def _download(
    client: Any, name: str, total: int, max_size: int, what: str, timeout: float | None
) -> Op[bytes]:
    if total > max_size:
        raise RequestTooLargeError(
            f"{name} on {client.endpoint} is {total} bytes, over max_size={max_size}"
        )
    parts: list[bytes] = []
    offset = 0
    while offset < total:
        out = yield from exchange(client, FileReadData(offset), what, timeout)
        chunk: IoChunk = _parse(client, check(client, out, what), IoChunk, "#30 data")
        if chunk.offset != offset or not chunk.data:
            raise ProtocolError(f"{client.endpoint}: {what} stalled at offset {offset}")
        parts.append(chunk.data[: total - offset])
        offset += len(parts[-1])
    return b"".join(parts)


def _end_download(client: Any, what: str, timeout: float | None) -> Op[None]:
    """Free the server's download buffer (a lost connection frees it anyway)."""
    try:
        yield from exchange(client, FileReadEnd(), what, timeout)
    except KvpError:
        pass


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
