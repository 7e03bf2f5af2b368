"""C3 Bridge request messages: one frozen dataclass per request, encoded and parsed here.

Each class knows its message type (``TYPE``), builds its payload (:meth:`Message.payload`) and a
whole frame (:meth:`Message.frame`), and parses a payload (``parse``) the way the server reads
it (``source/handlers/*.cpp``: fields in order, trailing bytes ignored). The client encodes
them, the emulator parses them with ``parse`` (:mod:`kukavarproxy_emu.c3`): one layout for both.

Layouts (spec v1 rev 5 §3.5–§3.10; request = header, type, payload):

====  ================  ==================================================================
#4    ReadVariable      u16 n + UTF-16 name
#5    WriteVariable     name, value (each u16 n + UTF-16)
#6    ReadMultiple      u8 count, names
#7    WriteMultiple     u8 count, (name, value) pairs
#10   ProgramControl    u8 command (1 reset 2 start 3 stop 4 cancel), i16 interpreter
#10   ProgramSelect     u8 command (5 select 6 run), i16 (unused), name, parameters, bool force
#11   Motion            u8 type (1 PTP 2 LIN 3 PTP_REL 4 LIN_REL), position string
#12   KcpAction         u8 key, i32 interpreter or axis, i32 key code, bool direction,
                        bool released
#13   ProxyInfo         (no payload)
#14   ProxyFeatures     (no payload)
#17   Benchmark         bool write, u8 count, u32 iterations, names (and values if write)
#63   ConfirmAll        (no payload)
====  ================  ==================================================================

File messages (#20..#30) are in :mod:`pyopenshowvar.c3.files`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import ClassVar, Self, TypeVar

from ..protocol import Request, encode_request
from .constants import Command, Interpreter, KcpKey, MotionType, ProgramCommand
from .wire import PayloadError, Reader, Writer

__all__ = [
    "Benchmark",
    "ConfirmAll",
    "KcpAction",
    "Message",
    "Motion",
    "ProgramControl",
    "ProgramSelect",
    "ProxyFeatures",
    "ProxyInfo",
    "ReadMultiple",
    "ReadVariable",
    "WriteMultiple",
    "WriteVariable",
]

_E = TypeVar("_E", bound=IntEnum)

#: A count field of #6/#7/#17 is one byte.
MAX_COUNT = 255


class Message:
    """Base of every C3 request: ``TYPE`` plus a payload."""

    TYPE: ClassVar[Command]

    def payload(self) -> bytes:
        return b""

    def frame(self, msg_id: int) -> bytes:
        """The whole request frame with tag ``msg_id``."""
        return encode_request(Request(msg_id, int(self.TYPE), "", self.payload()))

    @classmethod
    def parse(cls, r: Reader) -> Self:
        return cls()


def _count(n: int, what: str) -> int:
    if n > MAX_COUNT:
        raise PayloadError(
            f"{n} {what} in one message; its count field holds at most {MAX_COUNT} (split the list)"
        )
    return n


@dataclass(frozen=True, slots=True)
class ReadVariable(Message):
    """#4: read one variable, name and value in UTF-16."""

    TYPE: ClassVar[Command] = Command.READ_VARIABLE
    name: str

    def payload(self) -> bytes:
        return Writer().wstr(self.name, "variable name").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        return cls(r.wstr("variable name"))


@dataclass(frozen=True, slots=True)
class WriteVariable(Message):
    """#5: write one variable (UTF-16); the reply echoes the value."""

    TYPE: ClassVar[Command] = Command.WRITE_VARIABLE
    name: str
    value: str

    def payload(self) -> bytes:
        return Writer().wstr(self.name, "variable name").wstr(self.value, "value").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        return cls(r.wstr("variable name"), r.wstr("value"))


@dataclass(frozen=True, slots=True)
class ReadMultiple(Message):
    """#6: read up to 255 variables in one message."""

    TYPE: ClassVar[Command] = Command.READ_MULTIPLE
    names: tuple[str, ...]

    def payload(self) -> bytes:
        w = Writer().u8(_count(len(self.names), "variables"))
        for name in self.names:
            w.wstr(name, "variable name")
        return w.payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        count = r.u8("count")
        return cls(tuple(r.wstr("variable name") for _ in range(count)))


@dataclass(frozen=True, slots=True)
class WriteMultiple(Message):
    """#7: write up to 255 variables in one message; the reply reads each one back."""

    TYPE: ClassVar[Command] = Command.WRITE_MULTIPLE
    items: tuple[tuple[str, str], ...]

    def payload(self) -> bytes:
        w = Writer().u8(_count(len(self.items), "variables"))
        for name, value in self.items:
            w.wstr(name, "variable name").wstr(value, "value")
        return w.payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        count = r.u8("count")
        return cls(tuple((r.wstr("variable name"), r.wstr("value")) for _ in range(count)))


@dataclass(frozen=True, slots=True)
class ProgramControl(Message):
    """#10 subtype I: reset, start, stop or cancel the program of one interpreter."""

    TYPE: ClassVar[Command] = Command.PROGRAM_CONTROL
    command: int
    interpreter: int = Interpreter.ROBOT

    def payload(self) -> bytes:
        return Writer().u8(self.command).i16(self.interpreter).payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        return cls(r.u8("command"), r.i16("interpreter"))


@dataclass(frozen=True, slots=True)
class ProgramSelect(Message):
    """#10 subtype II: select (5) or run (6) a program, e.g. ``/R1/CELL`` or a KRC path."""

    TYPE: ClassVar[Command] = Command.PROGRAM_CONTROL
    name: str
    parameters: str = ""
    force: bool = False
    command: int = ProgramCommand.SELECT
    #: Not used by the server (spec: "NOT USED"), sent as 0.
    interpreter: int = 0

    def payload(self) -> bytes:
        return (
            Writer()
            .u8(self.command)
            .i16(self.interpreter)
            .wstr(self.name, "program name")
            .wstr(self.parameters, "parameters")
            .boolean(self.force)
            .payload()
        )

    @classmethod
    def parse(cls, r: Reader) -> Self:
        command = r.u8("command")
        interpreter = r.i16("interpreter")
        return cls(r.wstr("name"), r.wstr("parameters"), r.boolean("force"), command, interpreter)


@dataclass(frozen=True, slots=True)
class Motion(Message):
    """#11: a PTP, LIN, PTP_REL or LIN_REL motion to a KRL position literal."""

    TYPE: ClassVar[Command] = Command.MOTION
    motion: int
    position: str

    def payload(self) -> bytes:
        return Writer().u8(self.motion).wstr(self.position, "position").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        return cls(r.u8("motion type"), r.wstr("position"))


@dataclass(frozen=True, slots=True)
class KcpAction(Message):
    """#12: press or release a smartPAD key (start, stop, jog, 6D mouse)."""

    TYPE: ClassVar[Command] = Command.KCP_ACTION
    key: int
    #: Interpreter (start/stop keys) or axis number (jog keys).
    target: int = Interpreter.ROBOT
    key_code: int = 0
    direction: bool = False
    released: bool = False

    def payload(self) -> bytes:
        return (
            Writer()
            .u8(self.key)
            .i32(self.target)
            .i32(self.key_code)
            .boolean(self.direction)
            .boolean(self.released)
            .payload()
        )

    @classmethod
    def parse(cls, r: Reader) -> Self:
        return cls(r.u8("key"), r.i32("interpreter"), r.i32("key code"), r.boolean(), r.boolean())


@dataclass(frozen=True, slots=True)
class ProxyInfo(Message):
    """#13: version, time and computer name of the server."""

    TYPE: ClassVar[Command] = Command.PROXY_INFO


@dataclass(frozen=True, slots=True)
class ProxyFeatures(Message):
    """#14: the 256-bit map of message types the server handles."""

    TYPE: ClassVar[Command] = Command.PROXY_FEATURES


@dataclass(frozen=True, slots=True)
class ConfirmAll(Message):
    """#63: acknowledge every message on the controller (the smartPAD's "Confirm all")."""

    TYPE: ClassVar[Command] = Command.CROSS_CONFIRM_ALL


@dataclass(frozen=True, slots=True)
class Benchmark(Message):
    """#17: the server reads (or writes) the variables ``iterations`` times and times it."""

    TYPE: ClassVar[Command] = Command.PROXY_BENCHMARK
    names: tuple[str, ...]
    iterations: int
    #: Values to write, one per name; None benchmarks reads.
    values: tuple[str, ...] | None = None

    def payload(self) -> bytes:
        if self.values is not None and len(self.values) != len(self.names):
            raise PayloadError("a write benchmark needs one value per variable")
        w = Writer().boolean(self.values is not None)
        w.u8(_count(len(self.names), "variables")).u32(self.iterations)
        for i, name in enumerate(self.names):
            w.wstr(name, "variable name")
            if self.values is not None:
                w.wstr(self.values[i], "value")
        return w.payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        write = r.boolean("write")
        count = r.u8("count")
        iterations = r.u32("iterations")
        names: list[str] = []
        values: list[str] = []
        for _ in range(count):
            names.append(r.wstr("variable name"))
            if write:
                values.append(r.wstr("value"))
        return cls(tuple(names), iterations, tuple(values) if write else None)


def motion_type(value: int | str | MotionType) -> MotionType:
    """``"ptp"``, ``"LIN_REL"``, 3, ... → :class:`MotionType` (ValueError for anything else)."""
    return _member(MotionType, value, "motion type")


def key_type(value: int | str | KcpKey) -> KcpKey:
    """``"start"``, ``"JOG"``, 2, ... → :class:`KcpKey` (ValueError for anything else)."""
    return _member(KcpKey, value, "key")


def _member(kind: type[_E], value: int | str, what: str) -> _E:
    try:
        return kind[value.strip().upper()] if isinstance(value, str) else kind(value)
    except (KeyError, ValueError):
        choices = ", ".join(kind.__members__)
        raise ValueError(f"unknown {what} {value!r} ({choices})") from None


def names_tuple(names: Sequence[str]) -> tuple[str, ...]:
    if isinstance(names, str):  # a lone name is a common slip: ("$OV_PRO") is not a tuple
        raise TypeError("pass a list of names, not one string")
    return tuple(names)
