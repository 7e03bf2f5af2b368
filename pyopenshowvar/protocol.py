"""Sans-IO codec for the KUKAVARPROXY wire protocol, shared by the client and the emulator.

No sockets and no asyncio here: bytes in, frames out. The layout is the one the public
KUKAVARPROXY 9.0 source builds and parses (ImtsSrl/KUKAVARPROXY: ``frmMain.frm``,
``basMain.bas``; all integers unsigned 16-bit big-endian)::

    request  id:u16 | L:u16 | mode:u8 | N:u16 | name[N] | (write: M:u16 | value[M])
    reply    id:u16 | L:u16 | mode:u8 | V:u16 | value[V] | 00 01 | status:u8      (L = V + 6)

``L`` counts every byte after the 4-byte header, so a read request has L = 3 + N and a write
L = 5 + N + M. Success is decided from the last byte only (KVP answers ``00 01 00`` on failure,
C3 Bridge ``00 00 00``). An unknown mode byte makes KVP answer a bare 4-byte ``id 00 00``;
:class:`Reply` represents that with ``mode=None``.

Types 4 and up are C3 Bridge messages (:mod:`pyopenshowvar.c3`): the same header and the same
3-byte footer (error code u16 + success flag), but a payload whose layout depends on the type.
For them :attr:`Reply.value` / :attr:`Request.value` hold the raw payload (no length prefix),
which :mod:`pyopenshowvar.c3` encodes and decodes.

Text is latin-1 (KVP converts through the Windows ANSI code page; names and KRL literals are
ASCII in practice). Both length bytes are honoured, so names and values of 256..65535 bytes
work — several peers mask the high byte.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import dataclass
from enum import IntEnum

from .errors import ProtocolError

__all__ = [
    "ENCODING",
    "FIRST_EXTENDED",
    "HEADER_SIZE",
    "MAX_FRAME",
    "MAX_ID",
    "FrameDecoder",
    "FramingError",
    "Mode",
    "Reply",
    "ReplyDecoder",
    "Request",
    "RequestDecoder",
    "decode_reply",
    "decode_request",
    "encode_read",
    "encode_read_array",
    "encode_reply",
    "encode_request",
    "encode_write",
    "encode_write_array",
]

ENCODING = "latin-1"
HEADER_SIZE = 4
MAX_ID = 0xFFFF
MAX_CONTENT = 0xFFFF
#: The largest frame the 16-bit length field can describe; a decoder never buffers more.
MAX_FRAME = HEADER_SIZE + MAX_CONTENT

_HEADER = struct.Struct(">HH")
_U16 = struct.Struct(">H")
#: id, L, mode, first block length: the fixed head of every read request and reply (fast paths)
_HEAD = struct.Struct(">HHBH")
#: KVP's status block: a 2-byte length (= 1) followed by the status byte.
STATUS_BLOCK = b"\x00\x01"
#: The first C3 Bridge message type: replies of this type and above carry a raw payload.
FIRST_EXTENDED = 4


class Mode(IntEnum):
    """The function byte of a request (echoed in the reply)."""

    READ = 0
    WRITE = 1
    #: "read array for the PLC": the value text split on spaces, each token packed as a u16 word.
    READ_ARRAY = 2
    #: "write array": u16 words written to NAME[1..k]; status reflects the last element only.
    WRITE_ARRAY = 3


def _text(value: str | bytes, what: str) -> bytes:
    if isinstance(value, bytes | bytearray | memoryview):
        return bytes(value)
    try:
        return value.encode(ENCODING)
    except UnicodeEncodeError as exc:
        raise ProtocolError(f"{what} {value!r} is not representable in latin-1") from exc


def _check_id(msg_id: int) -> None:
    if not 0 <= msg_id <= MAX_ID:
        raise ProtocolError(f"message id {msg_id} outside 0..65535")


@dataclass(frozen=True, slots=True)
class Request:
    """One request. ``value`` is the write payload (None for reads); raw bytes for mode 3."""

    msg_id: int
    mode: int
    name: str
    value: bytes | None = None

    @property
    def text(self) -> str:
        """The write value as text ('' for reads)."""
        return (self.value or b"").decode(ENCODING)

    def encode(self) -> bytes:
        return encode_request(self)


@dataclass(frozen=True, slots=True)
class Reply:
    """One reply. ``mode`` is None for the 4-byte answer KVP gives to an unknown mode."""

    msg_id: int
    mode: int | None
    value: bytes = b""
    status: int = 1
    #: The two bytes before the status: ``00 01`` for KVP, an error code for C3 Bridge.
    code: bytes = STATUS_BLOCK

    @property
    def ok(self) -> bool:
        """True when the last byte says success (the only test that works on every server)."""
        return self.mode is not None and self.status == 1

    @property
    def text(self) -> str:
        return self.value.decode(ENCODING)

    @property
    def is_empty_success(self) -> bool:
        """An empty value with success status: KVP's answer for an unknown/unreadable variable."""
        return self.ok and not self.value

    def words(self) -> list[int]:
        """The value as big-endian u16 words (mode 2 replies, mode 3 payloads)."""
        if len(self.value) % 2:
            raise ProtocolError(f"array reply of odd length {len(self.value)}")
        return [w for (w,) in _U16.iter_unpack(self.value)]

    def encode(self) -> bytes:
        return encode_reply(self)


# --------------------------------------------------------------------------- encoding


def _frame(msg_id: int, body: bytes) -> bytes:
    _check_id(msg_id)
    if len(body) > MAX_CONTENT:
        raise ProtocolError(f"frame content of {len(body)} bytes exceeds 65535")
    return _HEADER.pack(msg_id, len(body)) + body


def _block(data: bytes, what: str) -> bytes:
    if len(data) > MAX_CONTENT:
        raise ProtocolError(f"{what} of {len(data)} bytes exceeds 65535")
    return _U16.pack(len(data)) + data


def encode_read(msg_id: int, name: str | bytes) -> bytes:
    """A mode-0 read request, e.g. ``encode_read(1, "$OV_PRO")`` → ``00 01 00 0A 00 00 07 $OV_PRO``."""
    if type(name) is str and 0 <= msg_id <= MAX_ID:
        # fast path (the client's hot loop); anything unusual takes the checked path below
        try:
            raw = name.encode(ENCODING)
        except UnicodeEncodeError:
            pass
        else:
            n = len(raw)
            if n <= MAX_CONTENT - 3:
                return _HEAD.pack(msg_id, n + 3, 0, n) + raw
    return _frame(msg_id, bytes((Mode.READ,)) + _block(_text(name, "name"), "name"))


def encode_write(msg_id: int, name: str | bytes, value: str | bytes) -> bytes:
    """A mode-1 write request carrying the KRL literal ``value``."""
    body = (
        bytes((Mode.WRITE,))
        + _block(_text(name, "name"), "name")
        + _block(_text(value, "value"), "value")
    )
    return _frame(msg_id, body)


def encode_read_array(msg_id: int, name: str | bytes) -> bytes:
    """A mode-2 request (the reply value is packed u16 words)."""
    return _frame(msg_id, bytes((Mode.READ_ARRAY,)) + _block(_text(name, "name"), "name"))


def encode_write_array(msg_id: int, name: str | bytes, words: Iterable[int]) -> bytes:
    """A mode-3 request writing ``words`` (each 0..65535) to NAME[1..k]."""
    try:
        payload = b"".join(_U16.pack(w) for w in words)
    except struct.error as exc:
        raise ProtocolError(f"array word out of range 0..65535: {exc}") from exc
    body = (
        bytes((Mode.WRITE_ARRAY,)) + _block(_text(name, "name"), "name") + _block(payload, "value")
    )
    return _frame(msg_id, body)


def encode_request(request: Request) -> bytes:
    """Encode a request; C3 Bridge types (4 and up) send ``value`` as their raw payload."""
    if request.mode >= FIRST_EXTENDED:
        if not request.mode <= 255:
            raise ProtocolError(f"message type {request.mode} is not one byte")
        return _frame(request.msg_id, bytes((request.mode,)) + (request.value or b""))
    body = bytes((request.mode,)) + _block(_text(request.name, "name"), "name")
    if request.value is not None:
        body += _block(request.value, "value")
    return _frame(request.msg_id, body)


def encode_reply(reply: Reply) -> bytes:
    """Encode a reply; ``mode=None`` gives the bare 4-byte unknown-mode answer."""
    mode, value, code, status = reply.mode, reply.value, reply.code, reply.status
    if (
        mode is not None
        and 0 <= mode < FIRST_EXTENDED
        and 0 <= reply.msg_id <= MAX_ID
        and len(value) <= MAX_CONTENT - 6
        and len(code) == 2
        and 0 <= status <= 255
    ):  # fast path (the emulator's hot loop); the checked path below raises the errors
        return (
            _HEAD.pack(reply.msg_id, len(value) + 6, mode, len(value))
            + value
            + code
            + bytes((status,))
        )
    if reply.mode is None:
        return _frame(reply.msg_id, b"")
    if len(reply.code) != 2 or not 0 <= reply.status <= 255 or not 0 <= reply.mode <= 255:
        raise ProtocolError("reply mode and status must be one byte each and code 2 bytes")
    # C3 Bridge types carry their payload as it is; KVP's modes wrap the value in a block
    payload = reply.value if reply.mode >= FIRST_EXTENDED else _block(reply.value, "value")
    body = bytes((reply.mode,)) + payload + reply.code + bytes((reply.status,))
    return _frame(reply.msg_id, body)


# --------------------------------------------------------------------------- decoding


def _split(frame: bytes | bytearray | memoryview) -> tuple[int, memoryview]:
    view = memoryview(frame)
    if len(view) < HEADER_SIZE:
        raise ProtocolError(f"frame of {len(view)} bytes is shorter than the 4-byte header")
    msg_id, length = _HEADER.unpack_from(view)
    if length != len(view) - HEADER_SIZE:
        raise ProtocolError(
            f"length field {length} does not match {len(view) - HEADER_SIZE} content bytes"
        )
    return msg_id, view[HEADER_SIZE:]


def _take_block(body: memoryview, pos: int, what: str) -> tuple[bytes, int]:
    if pos + 2 > len(body):
        raise ProtocolError(f"{what} length missing at offset {pos + HEADER_SIZE}")
    (n,) = _U16.unpack_from(body, pos)
    end = pos + 2 + n
    if end > len(body):
        raise ProtocolError(f"{what} length {n} runs past the end of the frame")
    return bytes(body[pos + 2 : end]), end


def decode_request(frame: bytes | bytearray | memoryview) -> Request:
    """Decode one whole request frame (header included).

    Modes 0..3 are checked block by block and the inner lengths must add up to L exactly.
    Other types decode to a Request with that type, an empty name and the raw payload as value:
    KVP answers them as unknown modes, C3 Bridge decodes them (:mod:`pyopenshowvar.c3`).
    """
    if type(frame) is bytes and len(frame) >= 7:
        # fast path for a well-formed read (the emulator's hot loop); all else is checked below
        msg_id, length, mode, n = _HEAD.unpack_from(frame)
        if mode == Mode.READ and length == len(frame) - HEADER_SIZE and n + 7 == len(frame):
            return Request(msg_id, 0, frame[7:].decode(ENCODING), None)
    msg_id, body = _split(frame)
    if not body:
        raise ProtocolError("request with length 0 (no mode byte)")
    mode = body[0]
    if mode > Mode.WRITE_ARRAY:
        return Request(msg_id, mode, "", bytes(body[1:]))
    raw_name, pos = _take_block(body, 1, "name")
    value: bytes | None = None
    if mode in (Mode.WRITE, Mode.WRITE_ARRAY):
        value, pos = _take_block(body, pos, "value")
    if pos != len(body):
        raise ProtocolError(f"{len(body) - pos} unexpected bytes after the request blocks")
    return Request(msg_id, mode, raw_name.decode(ENCODING), value)


def decode_reply(frame: bytes | bytearray | memoryview) -> Reply:
    """Decode one whole reply frame (header included).

    Modes 0..3 must be KVP's ``V | value | 00 01 | status`` exactly; C3 Bridge types (4 and up)
    give ``value`` = the raw payload between the type byte and the 3-byte footer.
    """
    size = len(frame)
    if type(frame) is bytes and size >= 10:
        # fast path for a well-formed reply (the client's hot loop); all else is checked below
        msg_id, length, mode, n = _HEAD.unpack_from(frame)
        if length == size - HEADER_SIZE and n + 10 == size and mode < FIRST_EXTENDED:
            return Reply(msg_id, mode, frame[7 : 7 + n], frame[-1], frame[-3:-1])
    msg_id, body = _split(frame)
    if not body:
        return Reply(msg_id, None, b"", 0, b"")
    if body[0] >= FIRST_EXTENDED:
        if len(body) < 4:
            raise ProtocolError(f"C3 reply content of {len(body)} bytes has no 3-byte footer")
        return Reply(msg_id, body[0], bytes(body[1:-3]), body[-1], bytes(body[-3:-1]))
    if len(body) < 6:
        raise ProtocolError(f"reply content of {len(body)} bytes is shorter than the minimum 6")
    value, pos = _take_block(body, 1, "value")
    if pos + 3 != len(body):
        raise ProtocolError(
            f"reply value length {len(value)} inconsistent with L = {len(body)} (expected V + 6)"
        )
    return Reply(msg_id, body[0], value, body[pos + 2], bytes(body[pos : pos + 2]))


class FramingError(ProtocolError):
    """A length field the decoder refuses; ``frames`` are the whole frames that came before it
    in the same chunk, so a server can still answer them before it closes the connection."""

    def __init__(self, message: str, frames: list[bytes]) -> None:
        super().__init__(message)
        self.frames = frames


class FrameDecoder:
    """Incremental framer: feed arbitrary chunks, get whole frames (header included) back.

    A frame split over many chunks is reassembled and several frames in one chunk are all
    returned, in order. The length field is 16-bit, so at most one partial frame of < 64 KiB is
    ever buffered; ``max_frame`` lowers that bound further, ``min_length`` rejects impossible
    length fields at once instead of waiting for bytes that would make no sense. Such a length
    raises :class:`FramingError`, which carries the whole frames of the chunk before it.
    """

    def __init__(self, *, min_length: int = 0, max_frame: int = MAX_FRAME) -> None:
        self.min_length = min_length
        self.max_frame = min(max_frame, MAX_FRAME)
        self._buf = bytearray()

    @property
    def buffered(self) -> int:
        """Bytes held that do not yet form a whole frame."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[bytes]:
        if not self._buf and type(data) is bytes:
            return self._feed_bytes(data)
        self._buf += data
        frames: list[bytes] = []
        buf = self._buf
        start = 0
        while len(buf) - start >= HEADER_SIZE:
            _, length = _HEADER.unpack_from(buf, start)
            if length < self.min_length or HEADER_SIZE + length > self.max_frame:
                self._buf = bytearray()
                raise self._error(length, frames)
            size = HEADER_SIZE + length
            if len(buf) - start < size:
                break
            frames.append(bytes(buf[start : start + size]))
            start += size
        if start:
            del buf[:start]
        return frames

    def _feed_bytes(self, data: bytes) -> list[bytes]:
        """:meth:`feed` with nothing buffered: frames are sliced from ``data`` without copying it
        into the buffer first (the common case: a read delivers whole frames)."""
        frames: list[bytes] = []
        total = len(data)
        start = 0
        while total - start >= HEADER_SIZE:
            _, length = _HEADER.unpack_from(data, start)
            if length < self.min_length or HEADER_SIZE + length > self.max_frame:
                raise self._error(length, frames)
            size = HEADER_SIZE + length
            if total - start < size:
                break
            frames.append(data if size == total else data[start : start + size])
            start += size
        if start < total:
            self._buf += data[start:]
        return frames

    def _error(self, length: int, frames: list[bytes]) -> FramingError:
        if length < self.min_length:
            message = f"length field {length} below the minimum {self.min_length}"
        else:
            message = f"frame of {HEADER_SIZE + length} bytes exceeds the limit of {self.max_frame}"
        return FramingError(message, frames)

    def eof(self) -> None:
        """Call at end of stream: raises if a frame was cut off mid-way."""
        if self._buf:
            n = len(self._buf)
            self._buf = bytearray()
            raise ProtocolError(f"connection closed in the middle of a frame ({n} bytes pending)")


class RequestDecoder(FrameDecoder):
    """Server side: chunks in, :class:`Request` objects out (mode byte required: L >= 1)."""

    def __init__(self, *, max_frame: int = MAX_FRAME) -> None:
        super().__init__(min_length=1, max_frame=max_frame)

    def feed_requests(self, data: bytes | bytearray | memoryview) -> list[Request]:
        return [decode_request(f) for f in self.feed(data)]


class ReplyDecoder(FrameDecoder):
    """Client side: chunks in, :class:`Reply` objects out (L is 0 or at least 6)."""

    def __init__(self, *, max_frame: int = MAX_FRAME) -> None:
        super().__init__(min_length=0, max_frame=max_frame)

    def feed_replies(self, data: bytes | bytearray | memoryview) -> list[Reply]:
        return [decode_reply(f) for f in self.feed(data)]
