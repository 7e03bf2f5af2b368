"""C3 Bridge file operations (#20..#30 on files), written once for both clients.

See :mod:`pyopenshowvar.c3.ops` for the contract. ``file_list``, ``file_properties``, the name
conversions, ``file_delete``/``create``/``copy``/``move``/``set_attribute``, and whole files:
``file_write`` and ``file_read`` travel in chunks of at most ``client._c3_chunk`` bytes through
the server's upload (#29) and download (#30) buffers. A failed file operation's error says
what the controller's error code usually means.
"""

from __future__ import annotations

from typing import Any

from ..core import Op
from ..errors import KvpError, ProtocolError
from .constants import CopyFlag, ErrorCode
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
from .messages import Message
from .ops import (
    _parse,
    check,
    encode,
    exchange,
    send,
)
from .replies import Outcome, Value

__all__ = [
    "MAX_DOWNLOAD",
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
]

#: Largest file ``file_read`` accepts by default (a KRL module is a few KiB to a few MiB).
MAX_DOWNLOAD = 16 * 1024 * 1024
#: Where ``program_upload`` puts modules unless told otherwise.


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
