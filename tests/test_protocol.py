"""Sans-IO codec: golden vectors from the protocol reference, properties, bad input."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyopenshowvar.errors import ProtocolError
from pyopenshowvar.protocol import (
    FrameDecoder,
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
    encode_write,
    encode_write_array,
)

H = bytes.fromhex

# --- golden vectors (kukavarproxy-protocol.md §1.2, §1.3, §2.2; kr6r900sixx.md §4.1) ---------

READ_OV_PRO = H("0001 000A 00 0007") + b"$OV_PRO"
WRITE_OV_PRO_50 = H("0002 000E 01 0007") + b"$OV_PRO" + H("0002") + b"50"
REPLY_100 = H("0001 0009 00 0003") + b"100" + H("000101")
REPLY_WRITE_OK = H("0002 0008 01 0002") + b"50" + H("000101")
REPLY_WRITE_FAIL_KVP = H("0002 0008 01 0002") + b"50" + H("000100")
REPLY_WRITE_FAIL_C3 = H("0002 0006 01 0000 000000")
REPLY_UNKNOWN_VAR = H("0003 0006 00 0000 000101")
REPLY_PONG = H("0004 000A 00 0004") + b"PONG" + H("000101")
REPLY_UNKNOWN_MODE = H("0005 0000")
CAPTURE_POS_X_REQ = H("0000 000D 00 000A") + b"$POS_ACT.x"
CAPTURE_POS_X_REPLY = H("0000 0010 00 000A") + b"284.994965" + H("000101")


def test_golden_read_request() -> None:
    assert encode_read(1, "$OV_PRO") == READ_OV_PRO
    assert encode_read(0, "$POS_ACT.x") == CAPTURE_POS_X_REQ
    assert decode_request(READ_OV_PRO) == Request(1, Mode.READ, "$OV_PRO")


def test_golden_write_request() -> None:
    assert encode_write(2, "$OV_PRO", "50") == WRITE_OV_PRO_50
    req = decode_request(WRITE_OV_PRO_50)
    assert (req.msg_id, req.mode, req.name, req.text) == (2, Mode.WRITE, "$OV_PRO", "50")


@pytest.mark.parametrize(
    ("frame", "msg_id", "text", "ok", "empty"),
    [
        (REPLY_100, 1, "100", True, False),
        (REPLY_WRITE_OK, 2, "50", True, False),
        (REPLY_WRITE_FAIL_KVP, 2, "50", False, False),
        (REPLY_WRITE_FAIL_C3, 2, "", False, False),
        (REPLY_UNKNOWN_VAR, 3, "", True, True),
        (REPLY_PONG, 4, "PONG", True, False),
        (CAPTURE_POS_X_REPLY, 0, "284.994965", True, False),
    ],
)
def test_golden_replies(frame: bytes, msg_id: int, text: str, ok: bool, empty: bool) -> None:
    reply = decode_reply(frame)
    assert reply.msg_id == msg_id
    assert reply.text == text
    assert reply.ok is ok
    assert reply.is_empty_success is empty
    assert encode_reply(reply) == frame  # byte-exact both ways


def test_reply_length_is_value_plus_six() -> None:
    frame = encode_reply(Reply(7, Mode.READ, b"x" * 154))
    assert int.from_bytes(frame[2:4], "big") == 154 + 6


def test_unknown_mode_reply_is_four_bytes() -> None:
    reply = decode_reply(REPLY_UNKNOWN_MODE)
    assert reply.mode is None and not reply.ok and reply.msg_id == 5
    assert encode_reply(Reply(5, None)) == REPLY_UNKNOWN_MODE


def test_unknown_mode_request_decodes_for_the_server() -> None:
    req = decode_request(H("0009 0003 07 ABCD"))
    assert req.mode == 7 and req.value == H("ABCD")


def test_array_modes() -> None:
    frame = encode_write_array(3, "ARR[]", [1, 2, 0xFFFF])
    req = decode_request(frame)
    assert req.mode == Mode.WRITE_ARRAY and req.name == "ARR[]"
    assert req.value == H("0001 0002 FFFF")
    assert decode_request(encode_read_array(4, "ARR[]")).mode == Mode.READ_ARRAY
    reply = decode_reply(encode_reply(Reply(4, Mode.READ_ARRAY, H("0001 FFFE"))))
    assert reply.words() == [1, 0xFFFE]
    with pytest.raises(ProtocolError):
        encode_write_array(3, "ARR[]", [70000])


# --- regression cases from peers' bugs ---------------------------------------------------------


@pytest.mark.parametrize("n", [255, 256, 257, 1024, 4000, 65532])
def test_long_names_use_both_length_bytes(n: int) -> None:
    name = "N" * n
    frame = encode_read(1, name)
    assert frame[5:7] == n.to_bytes(2, "big")
    assert decode_request(frame).name == name


@pytest.mark.parametrize("v", [256, 1025, 5000, 65529])
def test_long_values_over_1024_bytes(v: int) -> None:
    value = b"7" * v
    frame = encode_reply(Reply(65535, Mode.READ, value))
    dec = ReplyDecoder()
    # arriving in 1000-byte segments, as TCP would cut it
    out = []
    for i in range(0, len(frame), 1000):
        out += dec.feed_replies(frame[i : i + 1000])
    assert len(out) == 1 and out[0].value == value and out[0].msg_id == 65535


def test_too_long_raises() -> None:
    with pytest.raises(ProtocolError):
        encode_read(1, "N" * 65533)
    with pytest.raises(ProtocolError):
        encode_reply(Reply(1, 0, b"x" * 65530))


def test_ids_are_16_bit() -> None:
    assert encode_read(65535, "A")[:2] == b"\xff\xff"
    with pytest.raises(ProtocolError):
        encode_read(65536, "A")
    with pytest.raises(ProtocolError):
        encode_read(-1, "A")


def test_latin1_text() -> None:
    frame = encode_write(1, "MYSTRING[]", '"Größe"')
    assert decode_request(frame).text == '"Größe"'
    with pytest.raises(ProtocolError):
        encode_write(1, "X", "€")


@pytest.mark.parametrize(
    "frame",
    [
        H("0001 0005 00 0000 01"),  # reply shorter than 6
        H("0001 0007 00 0002 41 000101"),  # V + 6 != L (V too large for L)
        H("0001 0009 00 0001 41 000101 00"),  # trailing junk in the reply
        H("00 01"),  # shorter than a header
        H("0001 0004 00 0000 01"),  # L disagrees with the frame size
    ],
)
def test_malformed_replies(frame: bytes) -> None:
    with pytest.raises(ProtocolError):
        decode_reply(frame)


@pytest.mark.parametrize(
    "frame",
    [
        H("0001 0000"),  # no mode byte
        H("0001 0003 00 0005"),  # name longer than the frame
        H("0001 0005 00 0001 41 00"),  # junk after a read's name
        H("0001 0004 01 0001 41"),  # write without a value block
    ],
)
def test_malformed_requests(frame: bytes) -> None:
    with pytest.raises(ProtocolError):
        decode_request(frame)


def test_decoder_rejects_oversize_and_short_lengths() -> None:
    dec = FrameDecoder(max_frame=100)
    with pytest.raises(ProtocolError):
        dec.feed(H("0001 0100"))  # 256 content bytes > 100
    assert dec.buffered == 0
    with pytest.raises(ProtocolError):
        RequestDecoder().feed_requests(H("0001 0000"))


def test_eof_mid_frame_raises() -> None:
    dec = ReplyDecoder()
    assert dec.feed_replies(REPLY_100[:7]) == []
    with pytest.raises(ProtocolError):
        dec.eof()
    dec.eof()  # clean stream: no error


# --- properties ----------------------------------------------------------------------------------

names = st.text(st.characters(min_codepoint=32, max_codepoint=255), max_size=300)
values = st.text(st.characters(min_codepoint=0, max_codepoint=255), max_size=1500)
ids = st.integers(0, 0xFFFF)


@given(ids, names)
def test_read_round_trip(msg_id: int, name: str) -> None:
    req = decode_request(encode_read(msg_id, name))
    assert (req.msg_id, req.mode, req.name, req.value) == (msg_id, Mode.READ, name, None)


@given(ids, names, values)
def test_write_round_trip(msg_id: int, name: str, value: str) -> None:
    req = decode_request(encode_write(msg_id, name, value))
    assert (req.msg_id, req.name, req.text) == (msg_id, name, value)


@given(ids, st.sampled_from([0, 1, 2, 3]), st.binary(max_size=2000), st.integers(0, 255))
def test_reply_round_trip(msg_id: int, mode: int, value: bytes, status: int) -> None:
    reply = Reply(msg_id, mode, value, status)
    assert decode_reply(encode_reply(reply)) == reply


@given(
    st.lists(st.tuples(ids, st.binary(max_size=400)), min_size=1, max_size=12),
    st.lists(st.integers(1, 64), min_size=1, max_size=50),
)
def test_any_chunking_yields_the_same_frames(
    items: list[tuple[int, bytes]], cuts: list[int]
) -> None:
    replies = [Reply(i, Mode.READ, v) for i, v in items]
    stream = b"".join(encode_reply(r) for r in replies)
    dec = ReplyDecoder()
    got: list[Reply] = []
    pos, k = 0, 0
    while pos < len(stream):
        size = cuts[k % len(cuts)]
        got += dec.feed_replies(stream[pos : pos + size])
        pos += size
        k += 1
    assert got == replies
    assert dec.buffered == 0


@settings(max_examples=300)
@given(st.binary(max_size=3000), st.integers(1, 97))
def test_garbage_raises_protocol_error_or_waits_bounded(data: bytes, chunk: int) -> None:
    # Feeding random bytes either yields frames, raises ProtocolError, or buffers less than
    # one maximal frame; it can never hang or allocate more than the 16-bit length allows.
    for decoder in (RequestDecoder(), ReplyDecoder()):
        try:
            for i in range(0, len(data), chunk):
                if isinstance(decoder, RequestDecoder):
                    decoder.feed_requests(data[i : i + chunk])
                else:
                    decoder.feed_replies(data[i : i + chunk])
        except ProtocolError:
            continue
        assert decoder.buffered < 4 + 0x10000
