"""``kukavarproxy_emu.kvp9`` rule by rule at its boundaries: VB6's Integer and Long limits,
``CLng`` rounding and errors, ``splitMsg``'s ten blocks and Integer cursor, mode 2/3 element
counts, the read loop's tests on what is left. Each expected value follows a statement of
KUKAVARPROXY 9.0's source (ImtsSrl/KUKAVARPROXY ``src/basMain.bas``, ``src/frmMain.frm``);
the wire-table (``test_wire_table.py``) covers whole malformed reads over TCP."""

from __future__ import annotations

from collections.abc import Coroutine
from typing import Any

import pytest

from kukavarproxy_emu import kvp9
from kukavarproxy_emu.kvp9 import ReadOutcome, VbError, long_to_word, sock_server_read, split_msg
from pyopenshowvar.protocol import encode_read, encode_write

H = bytes.fromhex


class Wire:
    """CrossComm as a dict; replies and writes recorded."""

    def __init__(self, values: dict[bytes, bytes] | None = None) -> None:
        self.values = dict(values or {})
        self.out: list[bytes] = []
        self.writes: list[tuple[bytes, bytes]] = []

    async def show_var(self, name: bytes) -> bytes:
        return self.values.get(name, b"")

    async def set_var(self, name: bytes, value: bytes) -> bool:
        self.writes.append((name, value))
        return not name.startswith(b"RO")

    async def send(self, data: bytes) -> None:
        self.out.append(data)


def run(coro: Coroutine[Any, Any, ReadOutcome]) -> ReadOutcome:
    try:
        coro.send(None)
    except StopIteration as done:
        return done.value  # type: ignore[no-any-return]
    raise AssertionError("the walk suspended")


def walk(data: bytes, values: dict[bytes, bytes] | None = None) -> tuple[ReadOutcome, Wire]:
    wire = Wire(values)
    return run(sock_server_read(data, wire)), wire


# ------------------------------------------------------------------ VB primitives


@pytest.mark.parametrize(
    ("token", "word"),
    [
        (b"1.5", 2),  # half to even
        (b"2.5", 2),
        (b"-2.5", 0xFFFE),
        (b"0.5", 0),
        (b"-1", 0xFFFF),  # two's complement, low 16 bits
        (b"65536", 0),
        (b"65537", 1),
        (b"2147483647", 0xFFFF),  # the largest Long
        (b"-2147483648", 0),  # the smallest
        (b"1E3", 1000),
        (b"1D2", 100),  # VB reads D exponents too
        (b"1d2", 100),  # in either case
        (b"+7", 7),
        (b".5", 0),
        (b"3.", 3),
    ],
)
def test_clng_then_long_to_word(token: bytes, word: int) -> None:
    assert long_to_word(kvp9._clng(token)) == word.to_bytes(2, "big")


@pytest.mark.parametrize(
    ("token", "number"),
    [
        (b"2147483648", 6),  # one past a Long: overflow
        (b"-2147483649", 6),
        (b"2147483647.5", 6),  # rounds to 2**31
        (b"1E400", 6),  # infinity
        (b"TRUE", 13),  # type mismatch
        (b"", 13),  # Split of a double space gives an empty token
        (b"&H10", 13),
        (b"1,5", 13),
        (b"--1", 13),
    ],
)
def test_clng_errors(token: bytes, number: int) -> None:
    with pytest.raises(VbError) as err:
        kvp9._clng(token)
    assert err.value.number == number


def test_integer_word_and_right() -> None:
    assert kvp9._integer_word(H("7FFF"), 1) == 0x7FFF
    with pytest.raises(VbError, match="overflow"):
        kvp9._integer_word(H("8000"), 1)
    with pytest.raises(VbError):
        kvp9._integer_word(H("01"), 1)  # Asc("") of the missing low byte
    assert kvp9._right(b"abc", 0) == b"" and kvp9._right(b"abc", 2) == b"bc"
    assert kvp9._right(b"abc", 5) == b"abc"
    with pytest.raises(VbError):
        kvp9._right(b"abc", -1)
    assert kvp9._mid(b"abcdef", 6, 4) == b"f" and kvp9._mid(b"abc", 9, 2) == b""
    assert kvp9._word_to_long(H("0102")) == 0x0102
    assert kvp9._word_to_long(H("01")) == 0 and kvp9._word_to_long(H("010203")) == 0
    assert long_to_word(-1) == H("FFFF") and long_to_word(0x12345) == H("2345")


@pytest.mark.parametrize(
    ("call", "text"),
    [
        (
            lambda: kvp9._asc(b"", 1),
            "run-time error 5: invalid procedure call (Asc of an empty string)",
        ),
        (
            lambda: kvp9._right(b"a", -1),
            "run-time error 5: invalid procedure call (Right with a negative length)",
        ),
        (lambda: kvp9._integer_word(H("80 00"), 1), "run-time error 6: overflow"),
        (lambda: kvp9._clng(b"1E400"), "run-time error 6: overflow"),
        (lambda: kvp9._clng(b"-1E400"), "run-time error 6: overflow"),
        (lambda: kvp9._clng(b"2147483648"), "run-time error 6: overflow"),
        (lambda: kvp9._clng(b"1\t"), "run-time error 13: type mismatch (CLng of b'1\\t')"),
    ],
)
def test_vb_errors_say_their_number_and_meaning(call: Any, text: str) -> None:
    """Each run-time error carries VB's number and says what it is, as VB's own message does."""
    with pytest.raises(VbError) as err:
        call()
    assert str(err.value) == text
    assert err.value.number == int(text.split()[2].rstrip(":"))


def test_split_msg_blocks() -> None:
    assert split_msg(H("0002 4142 0001 43")) == [b"AB", b"C", *[b""] * 8]
    assert split_msg(H("0005 4142")) == [b"AB", *[b""] * 9]  # Mid past the end: what is there
    ten = H("0001 41") * 10
    assert split_msg(ten) == [b"A"] * 10
    assert split_msg(ten + H("0001 42")) is None  # sString(10): subscript out of range
    assert split_msg(H("8000 41")) is None  # Integer overflow in the length
    # a 1-byte rest: Do While nStartPos < Len(msg) stops before it (never Asc(""))
    assert split_msg(H("0001 41 00")) == [b"A", *[b""] * 9]
    assert split_msg(H("0001 41 0000")) == [b"A", *[b""] * 9]
    # the cursor nStartPos is an Integer: a block ending past 32767 overflows
    assert split_msg(H("7FFF") + bytes(40)) is None  # 1 + 2 + 32767 > 32767
    assert split_msg(H("7FFC") + bytes(40)) == [bytes(40), *[b""] * 9]  # exactly 32767
    assert split_msg(H("0010") + bytes(16)) == [bytes(16), *[b""] * 9]


# ------------------------------------------------------------------ modes


def test_mode_0_and_1_replies() -> None:
    _, wire = walk(encode_read(7, "V"), {b"V": b"12"})
    assert wire.out == [H("0007 0008 00 0002 3132 000101")]
    _, wire = walk(encode_write(8, "RO", "5"))  # refused: echoed with the failure tail
    assert wire.out == [H("0008 0007 01 0001 35 000100")]
    assert wire.writes == [(b"RO", b"5")]
    _, wire = walk(encode_read(9, "PING"), {b"PING": b"x"})  # PONG without CrossComm
    assert wire.out == [H("0009 000A 00 0004 504F4E47 000101")]
    out = run(sock_server_read(encode_read(9, "PING"), wire := Wire({b"PING": b"x"}), ping=False))
    assert out.completed and wire.out == [H("0009 0007 00 0001 78 000101")]


def _mode2(msg_id: int, name: bytes) -> bytes:
    return (
        msg_id.to_bytes(2, "big")
        + (3 + len(name)).to_bytes(2, "big")
        + b"\x02"
        + (len(name).to_bytes(2, "big") + name)
    )


def test_mode_2_words_and_counts() -> None:
    _, wire = walk(_mode2(1, b"A"), {b"A": b"1 -2 2.5"})
    assert wire.out == [H("0001 000C 02 0006 0001 FFFE 0002 000101")]
    _, wire = walk(_mode2(1, b"A"), {b"A": b"7 8"})  # two tokens: UBound 1, both words
    assert wire.out == [H("0001 000A 02 0004 0007 0008 000101")]
    _, wire = walk(_mode2(2, b"A"), {b"A": b"5"})  # one token: UBound 0, no words
    assert wire.out == [H("0002 0006 02 0000 000101")]
    _, wire = walk(_mode2(3, b"NONE"))  # Split("") is empty
    assert wire.out == [H("0003 0006 02 0000 000101")]
    out, wire = walk(_mode2(4, b"A") + encode_read(5, "B"), {b"A": b"1  2", b"B": b"7"})
    assert not out.completed and wire.out == []  # CLng("") ends the read: B gets nothing


def _mode3(msg_id: int, name: bytes, payload: bytes) -> bytes:
    body = b"\x03" + len(name).to_bytes(2, "big") + name + len(payload).to_bytes(2, "big")
    body += payload
    return msg_id.to_bytes(2, "big") + len(body).to_bytes(2, "big") + body


@pytest.mark.parametrize(
    ("payload", "writes"),
    [
        (H("0001 0002"), [(b"W[1]", b"1"), (b"W[2]", b"2")]),
        (H("0001 02"), [(b"W[1]", b"1"), (b"W[2]", b"0")]),  # 1.5 -> 2, a 1-byte word is 0
        (H("0001 0002 03"), [(b"W[1]", b"1"), (b"W[2]", b"2")]),  # 2.5 -> 2
        (
            H("0001 0002 0003 04"),
            [(b"W[1]", b"1"), (b"W[2]", b"2"), (b"W[3]", b"3"), (b"W[4]", b"0")],
        ),  # 3.5 -> 4
        (H("01"), []),  # 0.5 -> 0
        (H("FFFF"), [(b"W[1]", b"65535")]),  # wordToLong is unsigned
    ],
)
def test_mode_3_element_count_rounds_half_to_even(
    payload: bytes, writes: list[tuple[bytes, bytes]]
) -> None:
    for name in (b"W[]", b"W"):
        _, wire = walk(_mode3(1, name, payload))
        assert wire.writes == writes, name
        status = "01" if writes else "00"  # no element written: bWriteAllOk stays False
        assert wire.out == [H(f"0001 0006 03 0000 0001{status}")]


def test_mode_3_status_is_the_last_elements() -> None:
    _, wire = walk(_mode3(1, b"RO", H("0001 0002")))
    assert wire.out == [H("0001 0006 03 0000 000100")]


# ------------------------------------------------------------------ the read loop


def test_each_reply_takes_its_requests_id_unless_legacy() -> None:
    data = encode_read(0x0A0B, "V") + encode_read(0x0C0D, "V")
    _, wire = walk(data, {b"V": b"1"})
    assert [r[:2] for r in wire.out] == [H("0A0B"), H("0C0D")]
    wire = Wire({b"V": b"1"})
    run(sock_server_read(data, wire, legacy_ids=True))
    assert [r[:2] for r in wire.out] == [H("0A0B"), H("0A0B")]


def test_the_loop_runs_while_the_rest_holds_l_bytes() -> None:
    # L = 10, but only 9 bytes after the header: Len(buffer) >= L still holds (13 >= 10), the
    # request is read short ("$OV_PR"), then Right(buffer, 13 - 14) raises: the read ends
    out, wire = walk(H("0001 000A 00 0007") + b"$OV_PR", {b"$OV_PR": b"x"})
    assert wire.out == [H("0001 0007 00 0001 78 000101")]
    assert out == ReadOutcome(1, completed=False)
    # a rest of 3 bytes keeps the old L; with L <= 3 the loop goes on and Asc fails at byte 5
    out, wire = walk(H("0001 0003 00 0000") + H("000102"))
    assert not out.completed and len(wire.out) == 1
    # a rest of 3 bytes with the old L = 10 > 3: the loop ends, the read is complete
    out, wire = walk(encode_read(1, "V") + H("000102"), {b"V": b"1"})
    assert len(wire.out) == 1 and out == ReadOutcome(1, completed=True)
    # a rest of 4 bytes is a new header (L = 0); its mode byte is missing: Asc("") ends it
    # (after a request whose L = 10 > 4, which the new header must replace)
    out, wire = walk(encode_read(1, "$OV_PRO") + H("0002 0000"), {b"$OV_PRO": b"1"})
    assert len(wire.out) == 1 and out.messages == 2 and not out.completed
    # with a fifth byte the mode is there: L = 0 reads an empty name
    out, wire = walk(encode_read(1, "V") + H("0002 0000 00"), {b"V": b"1"})
    assert wire.out[1] == H("0002 0006 00 0000 000101")
    assert out.messages == 3 and not out.completed  # the 1-byte rest loops once more, fails


def test_unknown_modes_nest_the_previous_reply() -> None:
    first = encode_read(1, "V")
    unknown = H("0002 0003 09 0000")
    _, wire = walk(first + unknown, {b"V": b"1"})
    reply = H("0001 0007 00 0001 31 000101")
    assert wire.out == [reply, H("0002") + len(reply).to_bytes(2, "big") + reply]
    _, wire = walk(unknown)  # first in its read: sValueToWrite is still ""
    assert wire.out == [H("0002 0000")]
    out, wire = walk(H("0002 0001 09"))  # mode byte only: nothing to split, answered
    assert wire.out == [H("0002 0000")] and out.messages == 1
