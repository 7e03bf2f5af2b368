"""The KVP codec at its edges: every limit on both sides of the boundary, what each refusal
says, and the fast paths (whole ``bytes``) giving exactly what the checked paths give
(``bytearray``/``memoryview`` input takes the checked path).

Layouts: reference kukavarproxy-protocol §1–§2 (docstring of pyopenshowvar.protocol).
"""

from __future__ import annotations

import re

import pytest
from hexwire import H

from pyopenshowvar.errors import ProtocolError
from pyopenshowvar.protocol import (
    MAX_FRAME,
    FrameDecoder,
    FramingError,
    Mode,
    Reply,
    ReplyDecoder,
    Request,
    RequestDecoder,
    decode_reply,
    decode_request,
    encode_read,
    encode_read_array,
    encode_reply,
    encode_request,
    encode_write,
    encode_write_array,
)


def raises(message: str) -> pytest.RaisesContext[ProtocolError]:
    return pytest.raises(ProtocolError, match=f"^{re.escape(message)}$")


# --- encoding -------------------------------------------------------------------------------------
def test_message_ids_are_16_bit() -> None:
    assert encode_read(0, "A") == H("0000 0004 00 0001 41")
    assert encode_read(0xFFFF, "A") == H("FFFF 0004 00 0001 41")
    for bad in (-1, 0x10000):
        for encode in (
            lambda i: encode_read(i, "A"),
            lambda i: encode_write(i, "A", "1"),
            lambda i: encode_read_array(i, "A"),
            lambda i: encode_write_array(i, "A", [1]),
        ):
            with raises(f"message id {bad} outside 0..65535"):
                encode(bad)


def test_text_must_be_latin1_and_the_error_names_the_field() -> None:
    assert encode_read(1, "Ä") == H("0001 0004 00 0001 C4")
    assert encode_read(1, b"\xff") == H("0001 0004 00 0001 FF")  # bytes go as they are
    with raises("name '€' is not representable in latin-1"):
        encode_read(1, "€")
    with raises("name '€' is not representable in latin-1"):
        encode_read_array(1, "€")
    with raises("name '€' is not representable in latin-1"):
        encode_write_array(1, "€", [1])
    with raises("name '€' is not representable in latin-1"):
        encode_write(1, "€", "1")
    with raises("value '€' is not representable in latin-1"):
        encode_write(1, "A", "€")
    with raises("name '€' is not representable in latin-1"):
        encode_request(Request(1, Mode.READ, "€"))


def test_longest_read_fills_the_16_bit_length_exactly() -> None:
    name = "N" * (0xFFFF - 3)  # L = mode + N + name = 65535
    frame = encode_read(7, name)
    assert frame[:7] == H("0007 FFFF 00 FFFC") and len(frame) == MAX_FRAME
    assert encode_read(7, name.encode()) == frame  # the checked path agrees
    with raises("frame content of 65536 bytes exceeds 65535"):
        encode_read(7, name + "N")
    with raises("name of 65536 bytes exceeds 65535"):
        encode_read(7, "N" * 0x10000)
    with raises("name of 65536 bytes exceeds 65535"):
        encode_read_array(7, "N" * 0x10000)


def test_write_blocks_and_their_limits() -> None:
    assert encode_write(2, "A", "12") == H("0002 0008 01 0001 41 0002 3132")
    assert encode_write(2, b"A", b"") == H("0002 0006 01 0001 41 0000")
    with raises("value of 65536 bytes exceeds 65535"):
        encode_write(2, "A", "1" * 0x10000)
    with raises("name of 65536 bytes exceeds 65535"):
        encode_write(2, "A" * 0x10000, "1")
    with raises("frame content of 65536 bytes exceeds 65535"):
        encode_write(2, "A", "1" * (0xFFFF - 5))


def test_array_requests() -> None:
    assert encode_read_array(3, "A") == H("0003 0004 02 0001 41")
    assert encode_write_array(3, "A", [0, 0xFFFF]) == H("0003 000A 03 0001 41 0004 0000 FFFF")
    for bad in (-1, 0x10000):
        with pytest.raises(ProtocolError, match=r"^array word out of range 0\.\.65535: "):
            encode_write_array(3, "A", [bad])
    with raises("value of 65536 bytes exceeds 65535"):
        encode_write_array(3, "A", [1] * 0x8000)


def test_encode_request_for_kvp_modes_and_c3_types() -> None:
    read = Request(1, Mode.READ, "A")
    assert read.encode() == encode_request(read) == encode_read(1, "A")
    write = Request(1, Mode.WRITE, "A", b"5")
    assert encode_request(write) == encode_write(1, "A", "5")
    assert encode_request(Request(1, Mode.WRITE, "A", b"")) == encode_write(1, "A", "")
    with raises("value of 65536 bytes exceeds 65535"):
        encode_request(Request(1, Mode.WRITE, "A", b"1" * 0x10000))
    with raises("name of 65536 bytes exceeds 65535"):
        encode_request(Request(1, Mode.READ, "A" * 0x10000))
    # C3 Bridge types: the raw payload after the type byte, no blocks
    assert encode_request(Request(9, 4, "", H("0001 4100"))) == H("0009 0005 04 0001 4100")
    assert encode_request(Request(9, 63, "")) == H("0009 0001 3F")
    assert encode_request(Request(9, 255, "", b"")) == H("0009 0001 FF")
    with raises("message type 256 is not one byte"):
        encode_request(Request(9, 256, ""))
    with raises("message id 65536 outside 0..65535"):
        encode_request(Request(0x10000, 4, ""))
    with raises("frame content of 65536 bytes exceeds 65535"):
        encode_request(Request(9, 4, "", b"\0" * 0xFFFF))


def test_encode_reply_kvp_c3_and_bare() -> None:
    kvp = Reply(5, Mode.READ, b"42", 1)
    assert kvp.encode() == encode_reply(kvp) == H("0005 0008 00 0002 3432 0001 01")
    assert encode_reply(Reply(0, 0, b"", 0)) == H("0000 0006 00 0000 0001 00")
    assert encode_reply(Reply(0xFFFF, 3, b"", 255, H("0102"))) == H("FFFF 0006 03 0000 0102 FF")
    # C3 types: raw payload, then the footer (the spec's error code and flag)
    assert encode_reply(Reply(5, 4, H("0001 4100"), 1, H("0001"))) == H(
        "0005 0008 04 0001 4100 0001 01"
    )
    assert encode_reply(Reply(5, 255, b"", 0, H("0009"))) == H("0005 0004 FF 0009 00")
    assert encode_reply(Reply(5, None)) == H("0005 0000")  # KVP's answer to an unknown mode
    assert encode_reply(Reply(0xFFFF, None)) == H("FFFF 0000")
    msg = "reply mode and status must be one byte each and code 2 bytes"
    for bad in (
        Reply(5, 0, b"", 1, b"\x00"),
        Reply(5, 0, b"", 1, b"\x00\x01\x02"),
        Reply(5, 0, b"", 256),
        Reply(5, 0, b"", -1),
        Reply(5, 256, b""),
        Reply(5, -1, b""),
        Reply(5, 4, b"", 1, b"\x00"),
        Reply(5, 4, b"", 256),
    ):
        with raises(msg):
            encode_reply(bad)
    with raises("message id 65536 outside 0..65535"):
        encode_reply(Reply(0x10000, 0, b""))
    with raises("message id -1 outside 0..65535"):
        encode_reply(Reply(-1, None))
    longest = Reply(1, 0, b"v" * (0xFFFF - 6))
    assert len(encode_reply(longest)) == MAX_FRAME
    with raises("frame content of 65536 bytes exceeds 65535"):
        encode_reply(Reply(1, 0, b"v" * (0xFFFF - 5)))
    with raises("value of 65536 bytes exceeds 65535"):
        encode_reply(Reply(1, 0, b"v" * 0x10000))


def test_reply_properties() -> None:
    assert Reply(1, 0, b"", 1).is_empty_success
    assert not Reply(1, 0, b"x", 1).is_empty_success
    assert not Reply(1, 0, b"", 0).ok and not Reply(1, None, b"", 1).ok
    assert not Reply(1, 0, b"", 2).ok  # success is the last byte being exactly 1
    assert Reply(1, 2, H("0001 FFFF")).words() == [1, 0xFFFF]
    with raises("array reply of odd length 3"):
        Reply(1, 2, b"abc").words()
    assert Reply(1, 0, b"\xc4").text == "Ä"
    assert Request(1, 1, "A", b"\xc4").text == "Ä" and Request(1, 0, "A").text == ""


# --- decoding -------------------------------------------------------------------------------------
def _both(decode, frame: bytes):  # type: ignore[no-untyped-def]
    """Decode through the fast path (bytes) and the checked paths; all must agree."""
    fast = decode(frame)
    for other in (bytearray(frame), memoryview(frame)):
        checked = decode(other)
        assert checked == fast
        # plain bytes out, whatever came in (a memoryview value has no .decode)
        assert type(checked.value) in (bytes, type(None))
        assert isinstance(checked, Reply) or type(checked.name) is str
        if isinstance(checked, Reply):
            assert type(checked.code) is bytes and type(checked.status) is int
    assert type(fast.value) in (bytes, type(None))
    return fast


def test_decode_requests_of_every_mode() -> None:
    assert _both(decode_request, encode_read(3, "$OV_PRO")) == Request(3, 0, "$OV_PRO", None)
    assert _both(decode_request, encode_read(3, "")) == Request(3, 0, "", None)
    assert _both(decode_request, encode_write(4, "A", "1")) == Request(4, 1, "A", b"1")
    assert _both(decode_request, encode_read_array(5, "A")) == Request(5, 2, "A", None)
    assert _both(decode_request, encode_write_array(6, "A", [2])) == Request(6, 3, "A", b"\0\2")
    c3 = _both(decode_request, H("0007 0003 17 AABB"))
    assert c3 == Request(7, 0x17, "", H("AABB"))
    assert _both(decode_request, H("0007 0001 04")) == Request(7, 4, "", b"")


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        ("000100", "frame of 3 bytes is shorter than the 4-byte header"),
        ("0001 0005 00 0001 41", "length field 5 does not match 4 content bytes"),
        ("0001 0003 00 0001 41", "length field 3 does not match 4 content bytes"),
        ("0001 0000", "request with length 0 (no mode byte)"),
        ("0001 0002 00 00", "name length missing at offset 5"),
        ("0001 0004 00 0009 41", "name length 9 runs past the end of the frame"),
        ("0001 0004 01 0001 41", "value length missing at offset 8"),
        ("0001 0007 01 0001 41 0005 31", "value length 5 runs past the end of the frame"),
        ("0001 0006 00 0001 41 AA BB", "2 unexpected bytes after the request blocks"),
        ("0001 0008 01 0001 41 0000 AABB", "2 unexpected bytes after the request blocks"),
        # looks like a read at a glance (L matches the size) but the name runs past the end
        ("0001 0003 00 000E", "name length 14 runs past the end of the frame"),
    ],
)
def test_malformed_requests_say_what_is_wrong(frame: str, message: str) -> None:
    for data in (H(frame), bytearray(H(frame))):
        with raises(message):
            decode_request(data)


def test_decode_replies_kvp_c3_and_bare() -> None:
    assert _both(decode_reply, H("0005 0008 00 0002 3432 0001 01")) == Reply(5, 0, b"42", 1)
    empty = _both(decode_reply, H("0005 0006 01 0000 0001 00"))
    assert empty == Reply(5, 1, b"", 0, H("0001"))
    assert _both(decode_reply, H("0005 0000")) == Reply(5, None, b"", 0, b"")
    # C3 Bridge: raw payload between the type byte and the footer, whatever its size
    c3 = _both(decode_reply, H("0005 000A 04 0002 4100 4200 0001 01"))
    assert c3 == Reply(5, 4, H("0002 4100 4200"), 1, H("0001"))
    c3 = _both(decode_reply, H("0005 0006 04 0000 0009 00"))  # 10 bytes, like a KVP reply
    assert c3 == Reply(5, 4, H("0000"), 0, H("0009"))
    assert _both(decode_reply, H("0005 0004 3F 0001 01")) == Reply(5, 63, b"", 1, H("0001"))


@pytest.mark.parametrize(
    ("frame", "message"),
    [
        ("0005 00", "frame of 3 bytes is shorter than the 4-byte header"),
        ("0005 0007 00 0000 0001 01", "length field 7 does not match 6 content bytes"),
        ("0005 0003 04 0001", "C3 reply content of 3 bytes has no 3-byte footer"),
        ("0005 0005 00 0000 0001", "reply content of 5 bytes is shorter than the minimum 6"),
        ("0005 0008 00 0001 41 0001 01 FF", "reply value length 1 inconsistent with L = 8 (expected V + 6)"),
        ("0005 0008 00 0006 41 0001 01 FF", "value length 6 runs past the end of the frame"),
        ("0005 0006 00 0014 0001 01", "value length 20 runs past the end of the frame"),
        ("0005 0007 00 0000 0001 01 FF", "reply value length 0 inconsistent with L = 7 (expected V + 6)"),
    ],
)  # fmt: skip
def test_malformed_replies_say_what_is_wrong(frame: str, message: str) -> None:
    for data in (H(frame), bytearray(H(frame))):
        with raises(message):
            decode_reply(data)


# --- framing ---------------------------------------------------------------------------------------
def test_frame_decoder_bounds_and_their_errors() -> None:
    assert RequestDecoder().min_length == 1 and ReplyDecoder().min_length == 0
    assert FrameDecoder().min_length == 0 and FrameDecoder().feed(H("0002 0000")) == [
        H("0002 0000")
    ]
    assert FrameDecoder(max_frame=10**6).max_frame == MAX_FRAME
    assert RequestDecoder(max_frame=9).max_frame == 9 and ReplyDecoder(max_frame=9).max_frame == 9
    # a request of the minimum length (the mode byte alone) passes, whole or split
    assert RequestDecoder().feed(H("0001 0001 05")) == [H("0001 0001 05")]
    split = RequestDecoder()
    assert split.feed(H("00")) == [] and split.feed(H("01 0001 05")) == [H("0001 0001 05")]
    # four bytes make a whole L = 0 frame (a bare reply) on the buffered path too
    bare = ReplyDecoder()
    assert bare.feed(H("00")) == [] and bare.feed(H("02 0000")) == [H("0002 0000")]
    # frames handed out are bytes of their own, never views of the caller's buffer
    chunk = bytearray(H("0001 0001 05 0002 0001 06"))
    got = RequestDecoder().feed(chunk)
    assert got == [H("0001 0001 05"), H("0002 0001 06")] and all(type(f) is bytes for f in got)
    whole = bytearray(H("0001 0001 05"))
    (only,) = RequestDecoder().feed(whole)
    whole[0] = 0xFF
    assert only == H("0001 0001 05") and type(only) is bytes
    with pytest.raises(FramingError, match=r"^length field 0 below the minimum 1$") as err:
        RequestDecoder().feed(encode_read(1, "A") + H("0002 0000"))
    assert err.value.frames == [encode_read(1, "A")]  # the whole frames before the bad one
    assert ReplyDecoder().feed(H("0002 0000")) == [H("0002 0000")]
    # a length at the minimum but beyond the size limit is "too big", not "too small"
    with pytest.raises(FramingError, match=r"^frame of 5 bytes exceeds the limit of 4$"):
        RequestDecoder(max_frame=4).feed(H("0001 0001 00"))
    small = FrameDecoder(max_frame=12)
    assert small.feed(H("0001 0008") + b"x" * 8) == [H("0001 0008") + b"x" * 8]
    with pytest.raises(FramingError, match=r"^frame of 13 bytes exceeds the limit of 12$"):
        small.feed(H("0001 0009"))
    # the same checks when the length arrives in a second chunk (buffered path)
    split = RequestDecoder(max_frame=12)
    assert split.feed(H("00")) == [] and split.buffered == 1
    with pytest.raises(FramingError, match=r"^frame of 13 bytes exceeds the limit of 12$") as err:
        split.feed(bytearray(H("01 0009")))
    assert err.value.frames == [] and split.buffered == 0
    split = RequestDecoder()
    split.feed(H("00"))
    with pytest.raises(FramingError, match=r"^length field 0 below the minimum 1$"):
        split.feed(H("01 0000"))


def test_frames_split_anywhere_and_eof_mid_frame() -> None:
    stream = encode_read(1, "AB") + encode_write(2, "C", "3") + encode_read(3, "")
    for cut in range(len(stream) + 1):
        dec = RequestDecoder()
        got = dec.feed_requests(stream[:cut]) + dec.feed_requests(stream[cut:])
        assert [r.msg_id for r in got] == [1, 2, 3], cut
        assert dec.buffered == 0
        dec.eof()  # nothing pending: fine
    dec = ReplyDecoder()
    assert dec.feed_replies(H("0001 0006 00 00")) == [] and dec.buffered == 6
    with raises("connection closed in the middle of a frame (6 bytes pending)"):
        dec.eof()
    assert dec.buffered == 0
    dec.eof()  # the buffer was dropped with the error
    assert dec.feed_replies(H("0001 0000")) == [Reply(1, None, b"", 0, b"")]


def test_each_refusal_names_the_part_that_is_too_long() -> None:
    # a value that fits its own 16-bit block but not the frame around it: the frame is named,
    # with its real size (mode 1 + name block 3 + value block 2 + 65535)
    with raises("frame content of 65541 bytes exceeds 65535"):
        encode_write(2, "A", "1" * 0xFFFF)
    with raises("frame content of 65541 bytes exceeds 65535"):
        encode_reply(Reply(1, 0, b"v" * 0xFFFF))
    # the name block of an array write names the name, not the words
    with raises("name of 65536 bytes exceeds 65535"):
        encode_write_array(3, "A" * 0x10000, [1])


def test_c3_replies_take_every_status_byte() -> None:
    # C3 Bridge types take the checked path: its status bound is 0..255 inclusive, like KVP's
    assert encode_reply(Reply(5, 4, b"", 255, H("0009"))) == H("0005 0004 04 0009 FF")
    assert encode_reply(Reply(5, 4, b"", 0, H("0009"))) == H("0005 0004 04 0009 00")
