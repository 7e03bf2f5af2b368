"""The codec's write and slow paths with block lengths of 256 and more (both length bytes).

The fast paths (a ``str`` read request, a well-formed ``bytes`` reply) were tested with long
blocks; the checked paths every other frame takes — writes, array modes, ``bytes`` names,
``bytearray``/``memoryview`` input, ``Request``/``Reply`` objects — were not, so a high length
byte dropped there went unseen. Each case checks the length bytes on the wire and the round
trip, whole and cut into TCP-sized pieces.
"""

from __future__ import annotations

import pytest

from pyopenshowvar.protocol import (
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

LENGTHS = [255, 256, 257, 511, 4095, 30000]


def _u16(frame: bytes, at: int) -> int:
    return int.from_bytes(frame[at : at + 2], "big")


def _in_pieces(frame: bytes, size: int = 1000) -> list[bytes]:
    return [frame[i : i + size] for i in range(0, len(frame), size)]


@pytest.mark.parametrize("n", LENGTHS)
@pytest.mark.parametrize("m", [0, *LENGTHS])
def test_write_request_with_long_name_and_value(n: int, m: int) -> None:
    name, value = "N" * n, "v" * m
    frame = encode_write(0x1234, name, value)
    assert _u16(frame, 2) == len(frame) - 4 == 5 + n + m
    assert _u16(frame, 5) == n and _u16(frame, 7 + n) == m
    assert decode_request(frame) == Request(0x1234, Mode.WRITE, name, value.encode())
    assert decode_request(bytearray(frame)).text == value  # the checked decoder path too
    dec = RequestDecoder()
    got = [r for piece in _in_pieces(frame) for r in dec.feed_requests(piece)]
    assert got == [Request(0x1234, Mode.WRITE, name, value.encode())]


@pytest.mark.parametrize("n", LENGTHS)
def test_slow_path_reads_and_array_modes_with_long_names(n: int) -> None:
    name = "A" * n
    for frame in (
        encode_read(7, name.encode()),  # bytes name: the checked encoder
        encode_read(7, name + "\u00e9"),  # latin-1 beyond ASCII
        encode_read_array(7, name),
        encode_request(Request(7, Mode.READ, name)),
    ):
        size = len(frame) - 7
        assert _u16(frame, 5) == size and _u16(frame, 2) == size + 3
        assert decode_request(memoryview(frame)).name.startswith(name)


@pytest.mark.parametrize("words", [128, 129, 1000, 16000])
def test_write_array_with_long_payload(words: int) -> None:
    data = [(i * 7919) & 0xFFFF for i in range(words)]
    frame = encode_write_array(3, "ARR[]", data)
    assert _u16(frame, 12) == 2 * words  # value block after id, L, mode, N, "ARR[]"
    req = decode_request(frame)
    assert req.mode == Mode.WRITE_ARRAY and Reply(3, 3, req.value or b"").words() == data


@pytest.mark.parametrize("v", LENGTHS)
def test_reply_slow_paths_with_long_values(v: int) -> None:
    value = bytes(range(256)) * (v // 256) + b"x" * (v % 256)
    for reply in (Reply(9, Mode.READ, value), Reply(9, Mode.WRITE, value, 0, b"\x00\x00")):
        frame = encode_reply(reply)
        assert _u16(frame, 2) == v + 6 and _u16(frame, 5) == v
        assert decode_reply(bytearray(frame)) == reply  # not the bytes fast path
        dec = ReplyDecoder()
        assert [r for p in _in_pieces(frame, 97) for r in dec.feed_replies(p)] == [reply]
