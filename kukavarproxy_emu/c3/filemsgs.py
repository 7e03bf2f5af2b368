"""Handlers of the C3 Bridge file messages #20..#30 on the emulator's virtual file system.

Each handler takes the request payload and returns ``(payload, code)`` the way
``source/handlers/client_file.cpp`` builds its answer: the payload fields are written even when
the operation failed (zeros, empty names), a payload that ends early answers ErrorProtocol, and
the upload (#29) and download (#30) buffers belong to one connection (:class:`IoBuffers`).
Paths go through :class:`~kukavarproxy_emu.c3.vfs.VirtualFS`, which refuses anything outside
``KRC:\\``; the selected program's module cannot be overwritten, moved or deleted (ErrorAccess),
as a KRC locks it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from pyopenshowvar.c3 import files as f
from pyopenshowvar.c3.constants import (
    CopyFlag,
    ErrorCode,
    FileIo,
    ItemAttribute,
    ItemType,
    ListFlag,
)
from pyopenshowvar.c3.replies import Value
from pyopenshowvar.c3.wire import PayloadError, Reader
from pyopenshowvar.c3.wire import utf16_units as units

from .vfs import VfsError, VirtualFS, filetime

if TYPE_CHECKING:
    from .control import RobotControl

__all__ = ["FileHandlers", "IoBuffers"]

Result = tuple[bytes, int]
#: The server caps one download chunk at 63 KiB (SafePayloadSize in client.h).
SAFE_PAYLOAD = 64512


class IoBuffers:
    """One connection's upload and download buffers (freed with the connection)."""

    def __init__(self) -> None:
        self.upload = bytearray()
        self.download = b""

    @property
    def held(self) -> int:
        return len(self.upload) + len(self.download)


class FileHandlers:
    """The file messages on one VFS; ``budget()`` is the upload bytes all connections hold."""

    def __init__(
        self, vfs: VirtualFS, control: RobotControl, budget: Callable[[], int], limit: int
    ) -> None:
        self.vfs = vfs
        self.control = control
        self.budget = budget
        #: All connections' upload buffers together hold at most this many bytes.
        self.limit = limit

    def handle(self, msg_type: int, payload: bytes, io: IoBuffers) -> Result:
        handler = _HANDLERS[msg_type]
        try:
            return handler(self, Reader(payload), io)
        except VfsError as exc:
            return _FAILED_PAYLOAD.get(msg_type, b""), int(exc.code)
        except PayloadError:  # the message ends before its fields do
            return _FAILED_PAYLOAD.get(msg_type, b""), ErrorCode.PROTOCOL

    def _locked(self, path: str) -> None:
        key = self.vfs.key(self.vfs.normalize(path))
        if self.control.is_selected(key):
            raise VfsError(ErrorCode.ACCESS, f"{path} is the selected program; cancel it first")

    # ------------------------------------------------------------------ #20..#28

    def set_attribute(self, r: Reader, io: IoBuffers) -> Result:
        msg = f.FileSetAttribute.parse(r)
        self.vfs.set_attributes(msg.name, msg.attributes, msg.mask)
        return b"", ErrorCode.SUCCESS

    def name_list(self, r: Reader, io: IoBuffers) -> Result:
        msg = f.FileNameList.parse(r)
        items = self.vfs.listing(msg.path, recursive=bool(msg.flags & ListFlag.RECURSIVE))
        names = tuple(path for path, _ in items)
        infos = tuple(_info(entry) for _, entry in items)
        # the server's check before it builds the answer: the strings' bytes and one u16 each
        # (its two count fields are not counted)
        size = sum(2 + 2 * units(s) for s in (*names, *infos))
        if size > SAFE_PAYLOAD:
            return f.NameList(()).payload(), ErrorCode.LONG_ANSWER
        return f.NameList(names, infos).payload(), ErrorCode.SUCCESS

    def create(self, r: Reader, io: IoBuffers) -> Result:
        msg = f.FileCreate.parse(r)
        if msg.item_type & ItemType.DIRECTORY:
            self.vfs.mkdir(msg.name)
        else:
            self._locked(msg.name)
            self.vfs.write(msg.name, b"", overwrite=msg.always)
        return b"", ErrorCode.SUCCESS

    def delete(self, r: Reader, io: IoBuffers) -> Result:
        msg = f.FileDelete.parse(r)
        self._locked(msg.name)
        self.vfs.delete(msg.name, force=msg.always)
        return b"", ErrorCode.SUCCESS

    def copy(self, r: Reader, io: IoBuffers, *, move: bool = False) -> Result:
        msg = f.FileCopy.parse(r)
        self._locked(msg.destination)
        if move:
            self._locked(msg.source)
        overwrite = bool(msg.flags & CopyFlag.OVERWRITE)
        self.vfs.copy(msg.source, msg.destination, overwrite=overwrite, move=move)
        return b"", ErrorCode.SUCCESS

    def move(self, r: Reader, io: IoBuffers) -> Result:
        return self.copy(r, io, move=True)

    def properties(self, r: Reader, io: IoBuffers) -> Result:
        msg = f.FileGetProperties.parse(r)
        if self.vfs.is_dir(msg.name):
            normal = self.vfs.dirs[self.vfs.key(self.vfs.normalize(msg.name))]
            props = f.Properties(normal, int(ItemType.DIRECTORY), 0, int(ItemAttribute.DIRECTORY))
            return props.payload(), ErrorCode.SUCCESS
        hit = self.vfs.read(msg.name)
        props = f.Properties(
            hit.path,
            hit.item_type,
            len(hit.data),
            hit.attributes,
            created=filetime(hit.created),
            accessed=filetime(hit.accessed),
            modified=filetime(hit.modified),
        )
        return props.payload(), ErrorCode.SUCCESS

    def full_name(self, r: Reader, io: IoBuffers) -> Result:
        path = f.FileGetFullName.parse(r).path
        return Value(self.vfs.full_name(path)).payload(), ErrorCode.SUCCESS

    def krc_name(self, r: Reader, io: IoBuffers) -> Result:
        path = f.FileGetKrcName.parse(r).path
        return Value(self.vfs.krc_name(path)).payload(), ErrorCode.SUCCESS

    # ------------------------------------------------------------------ #29 upload

    def write_content(self, r: Reader, io: IoBuffers) -> Result:
        op = r.u8("operation")  # none at all: ErrorProtocol with an empty payload (handle)
        if op == FileIo.BEGIN:
            try:
                total = r.u32("total size")
            except PayloadError:  # the answer still holds the operation and the buffer's size
                return f.IoSize(op, len(io.upload)).payload(), ErrorCode.PROTOCOL
            io.upload = bytearray()
            if total > self.vfs.limits.file_size or self.budget() + total > self.limit:
                return f.IoSize(op, 0).payload(), ErrorCode.MEMORY
            io.upload = bytearray(total)
            return f.IoSize(op, total).payload(), ErrorCode.SUCCESS
        if op == FileIo.GET_SIZE:
            return f.IoSize(op, len(io.upload)).payload(), ErrorCode.SUCCESS
        if op == FileIo.DATA:
            offset, size = r.u32("offset"), r.u32("size")  # cut: empty payload (handle)
            total = len(io.upload)
            if size and total and offset < total:
                size = min(size, total - offset)
                try:
                    io.upload[offset : offset + size] = r.raw(size, "chunk data")
                except PayloadError:  # fewer bytes than announced: nothing is stored
                    return f.IoWritten(offset, size).payload(), ErrorCode.ACCESS
            else:
                size = 0
            return f.IoWritten(offset, size).payload(), ErrorCode.SUCCESS
        if op == FileIo.END:
            try:
                flags, name = r.i32("flags"), r.wstr("file name")
                self._locked(name)
                force = bool(flags & CopyFlag.OVERWRITE_READ_ONLY)
                self.vfs.write(name, bytes(io.upload), overwrite=bool(flags & 64), force=force)
            except PayloadError:
                return bytes((op,)), ErrorCode.PROTOCOL
            except VfsError as exc:
                return bytes((op,)), int(exc.code)
            io.upload = bytearray()
            return bytes((op,)), ErrorCode.SUCCESS
        return bytes((op,)), ErrorCode.NOT_IMPLEMENTED

    # ------------------------------------------------------------------ #30 download

    def read_content(self, r: Reader, io: IoBuffers) -> Result:
        op = r.u8("operation")
        if op == FileIo.BEGIN:
            try:
                r.i32("flags")
                name = r.wstr("file name")
            except PayloadError:  # the operation and the buffer's size, as the server answers
                return f.IoSize(op, len(io.download)).payload(), ErrorCode.PROTOCOL
            io.download = b""
            try:
                io.download = self.vfs.read(name).data
            except VfsError as exc:
                return f.IoSize(op, 0).payload(), int(exc.code)
            return f.IoSize(op, len(io.download)).payload(), ErrorCode.SUCCESS
        if op == FileIo.GET_SIZE:
            return f.IoSize(op, len(io.download)).payload(), ErrorCode.SUCCESS
        if op == FileIo.END:
            io.download = b""
            return bytes((op,)), ErrorCode.SUCCESS
        if op == FileIo.DATA:
            offset, size = r.u32("offset"), r.u32("max size")
            total = len(io.download)
            if size and total and offset < total:
                size = min(size, total - offset, SAFE_PAYLOAD)
            else:
                size = 0
            chunk = io.download[offset : offset + size]
            return f.IoChunk(offset, chunk).payload(), ErrorCode.SUCCESS
        return bytes((op,)), ErrorCode.NOT_IMPLEMENTED


def _info(entry: object) -> str:
    """The emulator's per-item info: ``DIR`` or ``FILE;size;attributes;modified (FILETIME)``.

    CrossComm's own info format is not documented; tools should treat it as opaque text.
    """
    from .vfs import VFile

    if not isinstance(entry, VFile):
        return "DIR;0;16;0"
    return f"FILE;{len(entry.data)};{entry.attributes};{filetime(entry.modified)}"


_HANDLERS: dict[int, Callable[[FileHandlers, Reader, IoBuffers], Result]] = {
    20: FileHandlers.set_attribute,
    21: FileHandlers.name_list,
    22: FileHandlers.create,
    23: FileHandlers.delete,
    24: FileHandlers.copy,
    25: FileHandlers.move,
    26: FileHandlers.properties,
    27: FileHandlers.full_name,
    28: FileHandlers.krc_name,
    29: FileHandlers.write_content,
    30: FileHandlers.read_content,
}
#: What the server still writes into a failed answer's payload (empty list, zero properties).
_FAILED_PAYLOAD = {
    21: f.NameList(()).payload(),
    26: f.Properties("").payload(),
    27: Value("").payload(),
    28: Value("").payload(),
}
