"""C3 Bridge payload fields and reply payloads at their edges: the range of every integer
field, the length limits, what a truncated payload's error says, and the reply footer.

The golden spec vectors are in tests/test_c3_codec.py; here the boundaries a one-character bug
would move (``<`` for ``<=``, a wrong byte order, a dropped check) are pinned byte by byte.
"""

from __future__ import annotations

import datetime as dt

import pytest
from hexwire import H

from pyopenshowvar.c3.replies import (
    BenchmarkReply,
    Echo,
    FeatureMap,
    Multiple,
    Outcome,
    ProxyInfoReply,
    Value,
    encode_c3_reply,
    error_name,
)
from pyopenshowvar.c3.wire import MAX_PAYLOAD, PayloadError, Reader, Writer, utf16_units
from pyopenshowvar.protocol import Reply, decode_reply


# --- Writer ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("method", "lo", "hi", "name", "size"),
    [
        ("u16", 0, 0xFFFF, "UINT16", 2),
        ("i16", -0x8000, 0x7FFF, "INT16", 2),
        ("u32", 0, 0xFFFFFFFF, "UINT32", 4),
        ("i32", -0x80000000, 0x7FFFFFFF, "INT32", 4),
    ],
)
def test_integer_fields_take_their_whole_range_big_endian(
    method: str, lo: int, hi: int, name: str, size: int
) -> None:
    w = Writer()
    getattr(w, method)(lo)
    getattr(w, method)(hi)
    data = w.payload()
    assert len(data) == 2 * size
    signed = lo < 0
    assert int.from_bytes(data[:size], "big", signed=signed) == lo
    assert int.from_bytes(data[size:], "big", signed=signed) == hi
    r = Reader(data)
    assert (getattr(r, method)(), getattr(r, method)()) == (lo, hi)
    for bad in (lo - 1, hi + 1):
        with pytest.raises(PayloadError, match=f"^{bad} does not fit {name}$"):
            getattr(Writer(), method)(bad)


def test_u8_and_boolean() -> None:
    assert Writer().u8(0).u8(0xFF).boolean(True).boolean(False).payload() == H("00 FF 01 00")
    for bad in (-1, 0x100):
        with pytest.raises(PayloadError, match=f"^{bad} does not fit an unsigned byte$"):
            Writer().u8(bad)
    r = Reader(H("00 01 02 FF"))
    assert [r.boolean() for _ in range(4)] == [False, True, True, True]  # non-zero is TRUE


def test_wstr_counts_code_units_little_endian() -> None:
    w = Writer().wstr("A\U0001f600")  # U+1F600: a surrogate pair, two units
    assert w.payload() == H("0003 4100 3DD8 00DE")
    assert utf16_units("A\U0001f600") == 3 and utf16_units("") == 0
    assert type(utf16_units("AB")) is int
    assert Reader(w.payload()).wstr() == "A\U0001f600"


def test_wstr_length_limit_is_65535_units() -> None:
    ok = Writer().wstr("x" * 0xFFFF)
    assert ok._buf[:2] == H("FFFF")  # the length prefix (payload() would refuse the size)
    with pytest.raises(PayloadError, match=r"^name of 65536 UTF-16 units exceeds 65535$"):
        Writer().wstr("x" * 0x10000, "name")
    with pytest.raises(PayloadError, match=r"^string of 65536 UTF-16 units exceeds 65535$"):
        Writer().wstr("x" * 0x10000)


def test_lone_surrogates_pass_both_ways() -> None:
    # a Windows BSTR may hold half a surrogate pair; it is carried, not refused
    assert Writer().wstr("A\ud800").payload() == H("0002 4100 00D8")
    assert Reader(H("0002 4100 00D8")).wstr() == "A\ud800"


def test_payload_limit_is_one_message() -> None:
    assert MAX_PAYLOAD == 65535 - 1 - 3
    assert len(Writer().raw(b"\0" * MAX_PAYLOAD).payload()) == MAX_PAYLOAD
    message = (
        f"message payload of {MAX_PAYLOAD + 1} bytes exceeds the {MAX_PAYLOAD} one C3 Bridge"
        " message can carry"
    )
    with pytest.raises(PayloadError, match=f"^{message}$"):
        Writer().raw(b"\0" * (MAX_PAYLOAD + 1)).payload()


# --- Reader ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("method", "what"),
    [("u8", "UINT8"), ("boolean", "BOOL"), ("u16", "UINT16"), ("i16", "INT16"),
     ("u32", "UINT32"), ("i32", "INT32"), ("wstr", "length of WSTRING")],
)  # fmt: skip
def test_truncated_field_names_itself_and_the_bytes_it_needed(method: str, what: str) -> None:
    with pytest.raises(PayloadError, match=f"^payload ends at byte 0, {what} needs bytes 0\\.\\."):
        getattr(Reader(b""), method)()


def test_truncated_binary_field_is_named_binary() -> None:
    with pytest.raises(PayloadError, match=r"^payload ends at byte 1, BINARY needs bytes 0\.\.1$"):
        Reader(b"x").raw(2)


def test_reader_positions_remaining_and_end() -> None:
    r = Reader(H("01 0002 4100 4200 AA BB"))
    assert r.remaining == 9
    assert r.u8() == 1 and r.remaining == 8
    assert r.wstr("name") == "AB" and r.remaining == 2
    with pytest.raises(PayloadError, match=r"^2 unexpected bytes after the reply$"):
        r.end("the reply")
    with pytest.raises(PayloadError, match=r"^payload ends at byte 9, chunk needs bytes 7\.\.9$"):
        r.raw(3, "chunk")
    assert r.rest() == H("AA BB") and r.remaining == 0
    r.end("the reply")  # nothing left: fine
    assert r.rest() == b""
    truncated = Reader(H("0003 4100"))  # says 3 units, carries 1
    with pytest.raises(PayloadError, match=r"^payload ends at byte 4, value needs bytes 2\.\.7$"):
        truncated.wstr("value")


# --- reply footer and payloads ----------------------------------------------------------------------
def test_error_names() -> None:
    assert error_name(9) == "ErrorProtocol (malformed message content)"
    assert error_name(7) == "ErrorNotImplemented (not implemented)"
    assert error_name(1) == "ErrorSuccess (success)"
    assert error_name(11) == "error 11" and error_name(-1) == "error -1"


def test_outcome_reads_the_footer() -> None:
    out = Outcome.of(Reply(5, 23, b"\x01", 2, H("0102")))
    assert (out.msg_id, out.type, out.payload, out.code, out.ok) == (5, 23, b"\x01", 0x0102, True)
    assert not Outcome.of(Reply(5, 23, b"", 0, H("0009"))).ok
    assert Outcome.of(Reply(5, 23, b"", 1, b"\x09")).code == 0  # no two-byte code: 0
    bare = Outcome.of(Reply(5, None, b"", 0, b""))  # KVP's bare answer to an unknown mode
    assert (bare.type, bare.code, bare.ok) == (-1, 0, False)
    assert Outcome.of(Reply(5, 23, H("0007"), 1, H("0001"))).reader().u16() == 7


def test_encoded_reply_footer() -> None:
    assert encode_c3_reply(0x1234, 23, b"", 9, False) == H("1234 0004 17 0009 00")
    assert encode_c3_reply(1, 10, H("05"), 0x0201, True) == H("0001 0005 0A 05 0201 01")
    out = Outcome.of(decode_reply(encode_c3_reply(2, 4, Value("é").payload(), 1, True)))
    assert Value.parse(out.reader()) == Value("é") and out.ok and out.code == 1


def test_multiple_and_echo_payloads() -> None:
    m = Multiple(((1, "A"), (3, "")))
    assert m.payload() == H("02 01 0001 4100 03 0000")
    assert Multiple.parse(Reader(m.payload())) == m
    assert Multiple(()).payload() == H("00")
    assert Echo(0x1FF).payload() == H("FF") and Echo.parse(Reader(H("07"))) == Echo(7)


def test_proxy_info_time_version_and_bad_clock() -> None:
    cet = dt.timezone(dt.timedelta(hours=1))
    # Sunday 2024-03-03 10:20:30.456 CET is 09:20:30.456 UTC, weekday 0 (Sunday)
    info = ProxyInfoReply(1, 4, 0, dt.datetime(2024, 3, 3, 10, 20, 30, 456789, tzinfo=cet), "PC")
    payload = info.payload()
    assert payload == H("01 04 00 07E8 0003 0000 0003 0009 0014 001E 01C8 0002 5000 4300")
    back = ProxyInfoReply.parse(Reader(payload))
    assert back.time == dt.datetime(2024, 3, 3, 9, 20, 30, 456000, tzinfo=dt.UTC)
    naive = ProxyInfoReply(1, 4, 0, dt.datetime(2024, 3, 4, 10, 0, 0), "").payload()
    assert naive[3:9] == H("07E8 0003 0001")  # taken as UTC, Monday = 1
    assert ProxyInfoReply(1, 4, 1, info.time, "").version == "1.4 (PROPRIETARY)"
    assert ProxyInfoReply(2, 0, 3, info.time, "").version == "2.0 (INTERNAL BUILD)"
    assert ProxyInfoReply(1, 5, 9, info.time, "").version == "1.5 (TYPE 9)"
    month_13 = H("01 00 00 07E8 000D 0000 0001 0000 0000 0000 0000 0001 5800")
    odd = ProxyInfoReply.parse(Reader(month_13))
    assert odd.time == dt.datetime(1601, 1, 1, tzinfo=dt.UTC) and odd.computer_name == "X"


def test_feature_map_bits_and_strings() -> None:
    fm = FeatureMap(frozenset({0, 7, 8, 255, 256, -1}))  # out-of-range types are ignored
    data = fm.payload()
    assert data[0] == 0x80 and data[30] == 0x01 and data[31] == 0x81
    assert sum(bin(b).count("1") for b in data) == 4
    assert FeatureMap.parse(Reader(data)).types == {0, 7, 8, 255}
    # type 256 would wrap onto type 0's bit: it must not
    assert FeatureMap(frozenset({256})).payload() == bytes(32)
    assert FeatureMap(frozenset({-1, -8})).payload() == bytes(32)
    assert FeatureMap(frozenset()).to_string() == "00000000"  # at least 8 characters
    assert FeatureMap(frozenset({3})).to_string() == "00001000"
    assert FeatureMap(frozenset({8})).to_string() == "100000000"
    assert FeatureMap.from_string(" 101 ").types == {0, 2}
    assert FeatureMap.from_string("1" * 256).types == frozenset(range(256))
    for bad in ("", "   ", "012", "1" * 257):
        with pytest.raises(ValueError, match="not a feature string"):
            FeatureMap.from_string(bad)


def test_benchmark_reply_round_trip() -> None:
    reply = BenchmarkReply(True, 3, 0xFFFFFFFF, 1, 2, 3)
    assert reply.payload()[:6] == H("01 03 FFFFFFFF")
    assert BenchmarkReply.parse(Reader(reply.payload())) == reply


@pytest.mark.parametrize(
    ("parse", "data", "field"),
    [
        (Echo.parse, "", "echo"),
        (Value.parse, "", "length of value"),
        (Value.parse, "0002 41", "value"),
        (Multiple.parse, "", "count"),
        (Multiple.parse, "01", "error code"),
        (Multiple.parse, "01 00 0001", "value"),
        (ProxyInfoReply.parse, "", "major"),
        (ProxyInfoReply.parse, "01", "minor"),
        (ProxyInfoReply.parse, "01 04", "version type"),
        (ProxyInfoReply.parse, "01 04 00 07E8 0003 0000 0003 0009 0014 001E 01C8", "length of computer name"),
        (ProxyInfoReply.parse, "01 04 00 07E8 0003 0000 0003 0009 0014 001E 01C8 0001", "computer name"),
        (FeatureMap.parse, "00" * 31, "feature bits"),
        (BenchmarkReply.parse, "01 03 0000", "UINT32"),
    ],
)  # fmt: skip
def test_a_truncated_reply_names_the_missing_field(parse, data: str, field: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(PayloadError, match=f", {field} needs bytes "):
        parse(Reader(H(data)))


def test_too_long_texts_name_their_field() -> None:
    big = "x" * 0x10000
    with pytest.raises(PayloadError, match=r"^value of 65536 UTF-16 units"):
        Value(big).payload()
    with pytest.raises(PayloadError, match=r"^value of 65536 UTF-16 units"):
        Multiple(((1, big),)).payload()
    t = dt.datetime(2024, 1, 1, tzinfo=dt.UTC)
    with pytest.raises(PayloadError, match=r"^computer name of 65536 UTF-16 units"):
        ProxyInfoReply(1, 0, 0, t, big).payload()


def test_proxy_info_clock_does_not_depend_on_the_local_time_zone(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import time

    monkeypatch.setenv("TZ", "Asia/Tokyo")  # UTC+9, no daylight saving
    time.tzset()
    try:
        cet = dt.timezone(dt.timedelta(hours=1))
        aware = ProxyInfoReply(1, 4, 0, dt.datetime(2024, 3, 3, 10, 0, 0, tzinfo=cet), "")
        assert aware.payload()[3:17] == H("07E8 0003 0000 0003 0009 0000 0000")  # 09:00 UTC
        naive = ProxyInfoReply(1, 4, 0, dt.datetime(2024, 3, 3, 10, 0, 0), "")
        assert naive.payload()[3:17] == H("07E8 0003 0000 0003 000A 0000 0000")  # as given
    finally:
        monkeypatch.undo()  # the original TZ (or none) back, then re-read by the C library
        time.tzset()
