"""Field encoding of C3 Bridge payloads: integers, booleans, UTF-16 strings, and their limits.

The spec's data types (§1.5) on the wire: every integer is big-endian ("network byte order",
like KUKAVARPROXY), but WSTRING characters are UTF-16 **little**-endian (§1.3), and a WSTRING's
length prefix counts UTF-16 code units, not bytes (so ``$OV_PRO`` is ``00 07`` + 14 bytes).
A BOOL is one byte: 0 is FALSE, anything else TRUE on receipt, 1 when sent.

:class:`Reader` raises :class:`PayloadError` for a payload that ends early, which the emulator
answers with ``ErrorProtocol`` as the server does (its ``MessageReader`` fails the same way).
"""

from __future__ import annotations

import struct

from ..errors import ProtocolError

__all__ = [
    "MAX_PAYLOAD",
    "PayloadError",
    "Reader",
    "Writer",
    "utf16_units",
]

#: The largest payload of one message: 65535 content bytes minus the type byte and the footer.
MAX_PAYLOAD = 0xFFFF - 1 - 3
_U16 = struct.Struct(">H")
_I16 = struct.Struct(">h")
_U32 = struct.Struct(">I")
_I32 = struct.Struct(">i")


class PayloadError(ProtocolError):
    """A C3 payload that does not hold the fields its type needs (or a field out of range)."""


def utf16_units(text: str) -> int:
    """How many UTF-16 code units ``text`` takes (characters beyond U+FFFF take two)."""
    return len(text.encode("utf-16-le", "surrogatepass")) // 2


class Writer:
    """Builds one payload field by field."""

    __slots__ = ("_buf",)

    def __init__(self) -> None:
        self._buf = bytearray()

    def u8(self, value: int) -> Writer:
        if not 0 <= value <= 0xFF:
            raise PayloadError(f"{value} does not fit an unsigned byte")
        self._buf.append(value)
        return self

    def boolean(self, value: bool) -> Writer:
        self._buf.append(1 if value else 0)
        return self

    def u16(self, value: int) -> Writer:
        return self._pack(_U16, value, "UINT16")

    def i16(self, value: int) -> Writer:
        return self._pack(_I16, value, "INT16")

    def u32(self, value: int) -> Writer:
        return self._pack(_U32, value, "UINT32")

    def i32(self, value: int) -> Writer:
        return self._pack(_I32, value, "INT32")

    def wstr(self, text: str, what: str = "string") -> Writer:
        """A u16 length in code units, then the text as UTF-16LE."""
        data = text.encode("utf-16-le", "surrogatepass")
        if len(data) // 2 > 0xFFFF:
            raise PayloadError(f"{what} of {len(data) // 2} UTF-16 units exceeds 65535")
        self._buf += _U16.pack(len(data) // 2)
        self._buf += data
        return self

    def raw(self, data: bytes) -> Writer:
        self._buf += data
        return self

    def payload(self) -> bytes:
        if len(self._buf) > MAX_PAYLOAD:
            raise PayloadError(
                f"message payload of {len(self._buf)} bytes exceeds the {MAX_PAYLOAD} one "
                "C3 Bridge message can carry"
            )
        return bytes(self._buf)

    def _pack(self, fmt: struct.Struct, value: int, what: str) -> Writer:
        try:
            self._buf += fmt.pack(value)
        except struct.error:
            raise PayloadError(f"{value} does not fit {what}") from None
        return self


class Reader:
    """Reads one payload field by field; running past its end raises :class:`PayloadError`."""

    __slots__ = ("_data", "_pos")

    def __init__(self, data: bytes) -> None:
        self._data = data
        self._pos = 0

    @property
    def remaining(self) -> int:
        return len(self._data) - self._pos

    def _take(self, n: int, what: str) -> bytes:
        end = self._pos + n
        if end > len(self._data):
            raise PayloadError(
                f"payload ends at byte {len(self._data)}, {what} needs bytes {self._pos}..{end - 1}"
            )
        chunk = self._data[self._pos : end]
        self._pos = end
        return chunk

    def u8(self, what: str = "UINT8") -> int:
        return self._take(1, what)[0]

    def boolean(self, what: str = "BOOL") -> bool:
        return self._take(1, what)[0] != 0

    def u16(self, what: str = "UINT16") -> int:
        return int(_U16.unpack(self._take(2, what))[0])

    def i16(self, what: str = "INT16") -> int:
        return int(_I16.unpack(self._take(2, what))[0])

    def u32(self, what: str = "UINT32") -> int:
        return int(_U32.unpack(self._take(4, what))[0])

    def i32(self, what: str = "INT32") -> int:
        return int(_I32.unpack(self._take(4, what))[0])

    def wstr(self, what: str = "WSTRING") -> str:
        units = self.u16(f"length of {what}")
        data = self._take(2 * units, what)
        # A lone surrogate is kept (surrogatepass), as a Windows BSTR keeps it.
        return data.decode("utf-16-le", "surrogatepass")

    def raw(self, n: int, what: str = "BINARY") -> bytes:
        return self._take(n, what)

    def rest(self) -> bytes:
        return self._take(self.remaining, "the rest")

    def end(self, what: str) -> None:
        """Check that nothing follows (clients are strict; the server ignores trailing bytes)."""
        if self.remaining:
            raise PayloadError(f"{self.remaining} unexpected bytes after {what}")
