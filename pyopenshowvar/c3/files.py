"""C3 Bridge file messages #20..#30: requests, and the replies only file messages have.

Layouts (spec v1 rev 5 §3.9; ``name`` = u16 length in UTF-16 units + UTF-16LE text):

====  ==================  ========================================  ===========================
#     request             payload                                   reply payload
====  ==================  ========================================  ===========================
20    FileSetAttribute    i32 attributes, i32 mask, name            (none)
21    FileNameList        i32 item type, i32 flags, path            u16 n, n names, u16 m,
                                                                    m infos
22    FileCreate          u16 item type, u8 module part, bool       (none)
                          always, name, template
23    FileDelete          bool always, name                         (none)
24/25 FileCopy/FileMove   i32 flags, source, destination            (none)
26    FileGetProperties   i32 flags, name                           14 × i32, name
27/28 FileGetFullName/    path                                      path
      FileGetKrcName
29    FileWrite...        u8 op: 1 begin (u32 total) | 2 data       op + u32 size | op, u32
                          (u32 offset, u32 n, n bytes) | 3 size |   offset, u32 written | op
                          4 end (i32 flags, name)
30    FileRead...         u8 op: 1 begin (i32 flags, name) | 2      op + u32 size | op, u32
                          data (u32 offset, u32 max) | 3 size |     offset, u32 n, n bytes |
                          4 end                                     op
====  ==================  ========================================  ===========================

The spec gives #30 begin's name length as UINT32; the server reads a UINT16
(``getBStringWithSize`` in ``handlers/client_file.cpp``) and so do we — the source decides.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Self

from .constants import Command, FileIo
from .messages import Message
from .wire import PayloadError, Reader, Writer

__all__ = [
    "FileCopy",
    "FileCreate",
    "FileDelete",
    "FileGetFullName",
    "FileGetKrcName",
    "FileGetProperties",
    "FileMove",
    "FileNameList",
    "FileReadBegin",
    "FileReadData",
    "FileReadEnd",
    "FileReadSize",
    "FileSetAttribute",
    "FileWriteBegin",
    "FileWriteData",
    "FileWriteEnd",
    "FileWriteSize",
    "IoChunk",
    "IoSize",
    "IoWritten",
    "NameList",
    "Properties",
]

#: Bytes of one message's payload left for file data after #29 data's 9 bytes of fields.
CHUNK_OVERHEAD = 1 + 4 + 4


@dataclass(frozen=True, slots=True)
class FileSetAttribute(Message):
    TYPE: ClassVar[Command] = Command.FILE_SET_ATTRIBUTE
    name: str
    attributes: int
    mask: int

    def payload(self) -> bytes:
        return Writer().i32(self.attributes).i32(self.mask).wstr(self.name, "name").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        attributes, mask = r.i32("attributes"), r.i32("mask")
        return cls(r.wstr("name"), attributes, mask)


@dataclass(frozen=True, slots=True)
class FileNameList(Message):
    TYPE: ClassVar[Command] = Command.FILE_NAME_LIST
    path: str
    item_type: int = 0
    flags: int = 0

    def payload(self) -> bytes:
        return Writer().i32(self.item_type).i32(self.flags).wstr(self.path, "path").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        item_type, flags = r.i32("item type"), r.i32("flags")
        return cls(r.wstr("path"), item_type, flags)


@dataclass(frozen=True, slots=True)
class FileCreate(Message):
    TYPE: ClassVar[Command] = Command.FILE_CREATE
    name: str
    item_type: int = 0
    module_part: int = 0
    always: bool = False
    template: str = ""

    def payload(self) -> bytes:
        w = Writer().u16(self.item_type).u8(self.module_part).boolean(self.always)
        return w.wstr(self.name, "name").wstr(self.template, "template").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        item_type, part, always = r.u16("item type"), r.u8("module part"), r.boolean()
        return cls(r.wstr("name"), item_type, part, always, r.wstr("template"))


@dataclass(frozen=True, slots=True)
class FileDelete(Message):
    TYPE: ClassVar[Command] = Command.FILE_DELETE
    name: str
    always: bool = False

    def payload(self) -> bytes:
        return Writer().boolean(self.always).wstr(self.name, "name").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        always = r.boolean("always")
        return cls(r.wstr("name"), always)


@dataclass(frozen=True, slots=True)
class FileCopy(Message):
    TYPE: ClassVar[Command] = Command.FILE_COPY
    source: str
    destination: str
    flags: int = 0

    def payload(self) -> bytes:
        w = Writer().i32(self.flags).wstr(self.source, "source")
        return w.wstr(self.destination, "destination").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        flags = r.i32("flags")
        return cls(r.wstr("source"), r.wstr("destination"), flags)


@dataclass(frozen=True, slots=True)
class FileMove(FileCopy):
    TYPE: ClassVar[Command] = Command.FILE_MOVE


@dataclass(frozen=True, slots=True)
class FileGetProperties(Message):
    TYPE: ClassVar[Command] = Command.FILE_GET_PROPERTIES
    name: str
    flags: int = 255

    def payload(self) -> bytes:
        return Writer().i32(self.flags).wstr(self.name, "name").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        flags = r.i32("flags")
        return cls(r.wstr("name"), flags)


@dataclass(frozen=True, slots=True)
class FileGetFullName(Message):
    """#27: ``/R1/TEST.SRC`` → ``KRC:\\R1\\PROGRAM\\TEST.SRC`` (spec's example)."""

    TYPE: ClassVar[Command] = Command.FILE_GET_FULL_NAME
    path: str

    def payload(self) -> bytes:
        return Writer().wstr(self.path, "path").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        return cls(r.wstr("path"))


@dataclass(frozen=True, slots=True)
class FileGetKrcName(FileGetFullName):
    """#28: ``KRC:\\R1\\PROGRAM\\TEST.SRC`` → ``/R1/TEST.SRC``."""

    TYPE: ClassVar[Command] = Command.FILE_GET_KRC_NAME


# --------------------------------------------------------------------------- #29 / #30


@dataclass(frozen=True, slots=True)
class FileWriteBegin(Message):
    """#29 op 1: a new upload buffer of ``total`` bytes (any earlier one is dropped)."""

    TYPE: ClassVar[Command] = Command.FILE_WRITE_CONTENT
    total: int

    def payload(self) -> bytes:
        return Writer().u8(FileIo.BEGIN).u32(self.total).payload()


@dataclass(frozen=True, slots=True)
class FileWriteSize(Message):
    TYPE: ClassVar[Command] = Command.FILE_WRITE_CONTENT

    def payload(self) -> bytes:
        return bytes((FileIo.GET_SIZE,))


@dataclass(frozen=True, slots=True)
class FileWriteData(Message):
    """#29 op 2: ``data`` into the upload buffer at ``offset``."""

    TYPE: ClassVar[Command] = Command.FILE_WRITE_CONTENT
    offset: int
    data: bytes

    def payload(self) -> bytes:
        w = Writer().u8(FileIo.DATA).u32(self.offset).u32(len(self.data))
        return w.raw(self.data).payload()


@dataclass(frozen=True, slots=True)
class FileWriteEnd(Message):
    """#29 op 4: store the buffer as file ``name`` (``flags``: copy flags, e.g. OVERWRITE)."""

    TYPE: ClassVar[Command] = Command.FILE_WRITE_CONTENT
    name: str
    flags: int = 0

    def payload(self) -> bytes:
        return Writer().u8(FileIo.END).i32(self.flags).wstr(self.name, "file name").payload()


@dataclass(frozen=True, slots=True)
class FileReadBegin(Message):
    """#30 op 1: load file ``name`` into the download buffer; the reply gives its size."""

    TYPE: ClassVar[Command] = Command.FILE_READ_CONTENT
    name: str
    flags: int = 0

    def payload(self) -> bytes:
        return Writer().u8(FileIo.BEGIN).i32(self.flags).wstr(self.name, "file name").payload()


@dataclass(frozen=True, slots=True)
class FileReadSize(Message):
    TYPE: ClassVar[Command] = Command.FILE_READ_CONTENT

    def payload(self) -> bytes:
        return bytes((FileIo.GET_SIZE,))


@dataclass(frozen=True, slots=True)
class FileReadData(Message):
    """#30 op 2: up to ``max_size`` bytes from ``offset`` (0xFFFFFFFF: as many as fit)."""

    TYPE: ClassVar[Command] = Command.FILE_READ_CONTENT
    offset: int
    max_size: int = 0xFFFFFFFF

    def payload(self) -> bytes:
        return Writer().u8(FileIo.DATA).u32(self.offset).u32(self.max_size).payload()


@dataclass(frozen=True, slots=True)
class FileReadEnd(Message):
    TYPE: ClassVar[Command] = Command.FILE_READ_CONTENT

    def payload(self) -> bytes:
        return bytes((FileIo.END,))


# --------------------------------------------------------------------------- replies


@dataclass(frozen=True, slots=True)
class NameList:
    """#21's reply: item names and the server's per-item info strings."""

    names: tuple[str, ...]
    infos: tuple[str, ...] = ()

    def payload(self) -> bytes:
        w = Writer().u16(len(self.names))
        for name in self.names:
            w.wstr(name, "item name")
        w.u16(len(self.infos))
        for info in self.infos:
            w.wstr(info, "item info")
        return w.payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        names = tuple(r.wstr("item name") for _ in range(r.u16("count of items")))
        infos = tuple(r.wstr("item info") for _ in range(r.u16("count of infos")))
        return cls(names, infos)


_TIME_FIELDS = ("created", "accessed", "modified")


@dataclass(frozen=True, slots=True)
class Properties:
    """#26's reply. Times are Windows FILETIME ticks (100 ns since 1601-01-01 UTC)."""

    name: str
    item_type: int = 0
    size: int = 0
    attributes: int = 0
    created: int = 0
    created_bias: int = 0
    accessed: int = 0
    accessed_bias: int = 0
    modified: int = 0
    modified_bias: int = 0
    edit_mode: int = 0

    def payload(self) -> bytes:
        w = Writer().i32(self.item_type)
        _i64(w, self.size)
        w.i32(self.attributes)
        for field in _TIME_FIELDS:
            _i64(w, getattr(self, field))
            w.i32(getattr(self, f"{field}_bias"))
        return w.i32(self.edit_mode).wstr(self.name, "item name").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        item_type = r.i32()
        size = _read_i64(r)
        attributes = r.i32()
        times: dict[str, int] = {}
        for field in _TIME_FIELDS:
            times[field] = _read_i64(r)
            times[f"{field}_bias"] = r.i32()
        edit_mode = r.i32()
        return cls(r.wstr("item name"), item_type, size, attributes, edit_mode=edit_mode, **times)


def _i64(w: Writer, value: int) -> None:
    """A 64-bit value as the spec sends it: low INT32 first, then high INT32 (both signed)."""
    low, high = value & 0xFFFFFFFF, (value >> 32) & 0xFFFFFFFF
    w.i32(low - (1 << 32) if low & 0x80000000 else low)
    w.i32(high - (1 << 32) if high & 0x80000000 else high)


def _read_i64(r: Reader) -> int:
    low = r.i32() & 0xFFFFFFFF
    high = r.i32() & 0xFFFFFFFF
    return (high << 32) | low


@dataclass(frozen=True, slots=True)
class IoSize:
    """#29/#30 begin and get-size replies: the op and the buffer size."""

    op: int
    size: int

    def payload(self) -> bytes:
        return Writer().u8(self.op).u32(self.size).payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        return cls(r.u8("operation"), r.u32("buffer size"))


@dataclass(frozen=True, slots=True)
class IoWritten:
    """#29 data reply: where the chunk went and how many bytes were taken."""

    offset: int
    written: int

    def payload(self) -> bytes:
        return Writer().u8(FileIo.DATA).u32(self.offset).u32(self.written).payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        op = r.u8("operation")
        if op != FileIo.DATA:
            raise PayloadError(f"data reply carries operation {op}, not 2")
        return cls(r.u32("offset"), r.u32("size"))


@dataclass(frozen=True, slots=True)
class IoChunk:
    """#30 data reply: ``data`` read from ``offset``."""

    offset: int
    data: bytes

    def payload(self) -> bytes:
        w = Writer().u8(FileIo.DATA).u32(self.offset).u32(len(self.data))
        return w.raw(self.data).payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        op = r.u8("operation")
        if op != FileIo.DATA:
            raise PayloadError(f"data reply carries operation {op}, not 2")
        offset = r.u32("offset")
        return cls(offset, r.raw(r.u32("size"), "chunk data"))
