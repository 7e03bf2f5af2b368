"""C3 Bridge reply payloads (other than the file ones) and the footer, both directions.

A reply is ``tag | length | type | payload | error code u16 | success BOOL`` (spec §3.1, §3.2).
:class:`Outcome` is that footer plus the raw payload, built from a decoded
:class:`~pyopenshowvar.protocol.Reply` (whose ``value`` is the raw payload for types >= 4) or
encoded by the emulator with :func:`encode_c3_reply`.

Payloads (spec v1 rev 5):

====  ===============  ==========================================================================
#4/5  Value            u16 n + UTF-16 value (also #27/#28: a path)
#6/7  Multiple         u8 count, per variable: u8 error code, u16 n + UTF-16 value
#10   Echo             u8 command (also #11 motion type, #12 key type)
#13   ProxyInfoReply   u8 major, u8 minor, u8 type, u16 year, month, weekday, day, hour, minute,
                       second, millisecond (UTC), u16 n + UTF-16 computer name
#14   FeatureMap       32 bytes, message 255..248 first, bit 7 of each byte the higher type
#17   BenchmarkReply   bool write, u8 count, u32 iterations, u32 start ms, u32 stop ms, u32 ms
====  ===============  ==========================================================================
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from typing import Self

from ..protocol import Reply, encode_reply
from .constants import ErrorCode, VersionType
from .wire import Reader, Writer

__all__ = [
    "BenchmarkReply",
    "Echo",
    "FeatureMap",
    "Multiple",
    "Outcome",
    "ProxyInfoReply",
    "Value",
    "encode_c3_reply",
    "error_name",
]


def error_name(code: int) -> str:
    """``9`` → ``"ErrorProtocol (malformed message content)"``; unknown codes stay numbers."""
    try:
        known = ErrorCode(code)
    except ValueError:
        return f"error {code}"
    camel = "".join(part.capitalize() for part in known.name.split("_"))
    return f"Error{camel} ({known.describe})"


@dataclass(frozen=True, slots=True)
class Outcome:
    """A reply's type, raw payload and footer."""

    msg_id: int
    type: int
    payload: bytes
    code: int
    #: The success flag; the spec: any non-zero byte is TRUE.
    ok: bool

    @classmethod
    def of(cls, reply: Reply) -> Self:
        code = int.from_bytes(reply.code, "big") if len(reply.code) == 2 else 0
        mode = -1 if reply.mode is None else reply.mode
        return cls(reply.msg_id, mode, reply.value, code, reply.status != 0)

    def reader(self) -> Reader:
        return Reader(self.payload)


def encode_c3_reply(msg_id: int, msg_type: int, payload: bytes, code: int, ok: bool) -> bytes:
    """A whole reply frame (types 0..3 take the payload as KVP's value block instead)."""
    return encode_reply(Reply(msg_id, msg_type, payload, 1 if ok else 0, code.to_bytes(2, "big")))


@dataclass(frozen=True, slots=True)
class Value:
    """One UTF-16 value (#4, #5) or path (#27, #28)."""

    value: str

    def payload(self) -> bytes:
        return Writer().wstr(self.value, "value").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        return cls(r.wstr("value"))


@dataclass(frozen=True, slots=True)
class Multiple:
    """#6/#7: (error code, value) per variable, in request order."""

    items: tuple[tuple[int, str], ...]

    def payload(self) -> bytes:
        w = Writer().u8(len(self.items))
        for code, value in self.items:
            w.u8(code).wstr(value, "value")
        return w.payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        count = r.u8("count")
        return cls(tuple((r.u8("error code"), r.wstr("value")) for _ in range(count)))


@dataclass(frozen=True, slots=True)
class Echo:
    """#10/#11/#12: the command, motion type or key type of the request, echoed."""

    value: int

    def payload(self) -> bytes:
        return bytes((self.value & 0xFF,))

    @classmethod
    def parse(cls, r: Reader) -> Self:
        return cls(r.u8("echo"))


@dataclass(frozen=True, slots=True)
class ProxyInfoReply:
    """#13: the server's version and clock (UTC) and the controller's computer name."""

    major: int
    minor: int
    version_type: int
    time: dt.datetime
    computer_name: str

    @property
    def version(self) -> str:
        """``"1.4 (OPEN SOURCE)"``, as ``@PROXY_VERSION`` reads."""
        try:
            edition = VersionType(self.version_type).name.replace("_", " ")
        except ValueError:
            edition = f"TYPE {self.version_type}"
        return f"{self.major}.{self.minor} ({edition})"

    def payload(self) -> bytes:
        t = self.time.astimezone(dt.UTC) if self.time.tzinfo else self.time
        w = Writer().u8(self.major).u8(self.minor).u8(self.version_type)
        # SYSTEMTIME: Sunday is day 0 (Python's isoweekday has Sunday = 7)
        for field in (t.year, t.month, t.isoweekday() % 7, t.day, t.hour, t.minute, t.second):
            w.u16(field)
        w.u16(t.microsecond // 1000)
        return w.wstr(self.computer_name, "computer name").payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        major, minor, kind = r.u8("major"), r.u8("minor"), r.u8("version type")
        year, month, _weekday, day, hour, minute, second, ms = (r.u16() for _ in range(8))
        try:
            when = dt.datetime(year, month, day, hour, minute, second, ms * 1000, tzinfo=dt.UTC)
        except ValueError:  # a server clock that is not a date: keep the reply usable
            when = dt.datetime(1601, 1, 1, tzinfo=dt.UTC)
        return cls(major, minor, kind, when, r.wstr("computer name"))


@dataclass(frozen=True, slots=True)
class FeatureMap:
    """#14: the set of message types the server handles (a 256-bit map, type 255 first)."""

    types: frozenset[int]

    def payload(self) -> bytes:
        out = bytearray(32)
        for t in self.types:
            if 0 <= t <= 255:
                out[31 - t // 8] |= 1 << (t % 8)
        return bytes(out)

    @classmethod
    def parse(cls, r: Reader) -> Self:
        data = r.raw(32, "feature bits")
        return cls(frozenset(t for t in range(256) if data[31 - t // 8] >> (t % 8) & 1))

    @classmethod
    def from_string(cls, text: str) -> Self:
        """``@PROXY_FEATURES``: one ``0``/``1`` per type, the **last** character type 0."""
        bits = text.strip()
        if not bits or set(bits) - {"0", "1"} or len(bits) > 256:
            raise ValueError(f"not a feature string: {text!r}")
        return cls(frozenset(i for i, c in enumerate(reversed(bits)) if c == "1"))

    def to_string(self) -> str:
        """The ``@PROXY_FEATURES`` text: from the highest type handled down to 0, at least 8."""
        top = max(self.types, default=0)
        return "".join("1" if t in self.types else "0" for t in range(max(top, 7), -1, -1))


@dataclass(frozen=True, slots=True)
class BenchmarkReply:
    """#17: what the server timed (milliseconds of its tick counter)."""

    write: bool
    count: int
    iterations: int
    start_ms: int
    stop_ms: int
    elapsed_ms: int

    def payload(self) -> bytes:
        w = Writer().boolean(self.write).u8(self.count).u32(self.iterations)
        return w.u32(self.start_ms).u32(self.stop_ms).u32(self.elapsed_ms).payload()

    @classmethod
    def parse(cls, r: Reader) -> Self:
        return cls(r.boolean(), r.u8(), r.u32(), r.u32(), r.u32(), r.u32())
