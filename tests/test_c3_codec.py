"""The C3 Bridge codec against the spec's hex samples, plus round-trip properties.

Golden vectors are the sample messages of "C3 Bridge Interface Protocol", version 1 revision 5
(documents/C3 Bridge Interface Protocol 1.5/index.htm in ulsu-tech/c3bridge-server); the
section is named at each vector. Messages without a hex sample in the spec (#10 subtype II,
#12, #17, #20..#30, #63) are checked field by field against the spec's layout tables.
"""

from __future__ import annotations

import datetime as dt

import pytest
from hexwire import H, W, payload_of
from hypothesis import given
from hypothesis import strategies as st

from pyopenshowvar.c3.constants import (
    Command,
    FileIo,
    ItemType,
    KcpKey,
    MotionType,
    ProgramCommand,
)
from pyopenshowvar.c3.files import (
    FileCopy,
    FileCreate,
    FileDelete,
    FileGetFullName,
    FileGetProperties,
    FileMove,
    FileNameList,
    FileReadBegin,
    FileReadData,
    FileReadEnd,
    FileSetAttribute,
    FileWriteBegin,
    FileWriteData,
    FileWriteEnd,
    IoChunk,
    IoSize,
    IoWritten,
    NameList,
    Properties,
)
from pyopenshowvar.c3.messages import (
    Benchmark,
    ConfirmAll,
    KcpAction,
    Motion,
    ProgramControl,
    ProgramSelect,
    ProxyFeatures,
    ProxyInfo,
    ReadMultiple,
    ReadVariable,
    WriteMultiple,
    WriteVariable,
    key_type,
    motion_type,
)
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
from pyopenshowvar.c3.server import ServerInfo, identify, parse_version
from pyopenshowvar.c3.wire import PayloadError, Reader, Writer, utf16_units
from pyopenshowvar.protocol import decode_reply, encode_read, encode_write

# --------------------------------------------------------------------------- spec samples


def test_sample_3_5_1_read_ascii() -> None:  # §3.5.1: KVP's mode 0, tag 256
    assert encode_read(256, "$ACCU_STATE") == H("0100 000E 00 000B") + b"$ACCU_STATE"
    reply = decode_reply(H("0100 0010 00 000A") + b"#CHARGE_OK" + H("0001 01"))
    assert (reply.msg_id, reply.mode, reply.text, reply.ok) == (256, 0, "#CHARGE_OK", True)


def test_sample_3_5_2_write_ascii() -> None:  # §3.5.2
    assert encode_write(256, "$OV_PRO", "35") == H("0100 000E 01 0007") + b"$OV_PRO" + H(
        "0002 3335"
    )
    reply = decode_reply(H("0100 0008 01 0002 3335 0001 01"))
    assert reply.text == "35" and reply.ok


def test_sample_3_5_5_read_variable() -> None:  # §3.5.5: UTF-16, length in characters
    frame = ReadVariable("$ACT_BASE").frame(512)
    assert frame == H("0200 0015 04 0009" + W("$ACT_BASE"))
    out = Outcome.of(decode_reply(H("0200 0008 04 0001 3100 0001 01")))
    assert (out.msg_id, out.type, out.code, out.ok) == (512, 4, 1, True)
    assert Value.parse(out.reader()) == Value("1")
    assert ReadVariable.parse(Reader(payload_of(frame))) == ReadVariable("$ACT_BASE")


def test_sample_3_5_6_write_variable() -> None:  # §3.5.6
    frame = WriteVariable("$OV_PRO", "5").frame(256)
    assert frame == H("0100 0015 05 0007" + W("$OV_PRO") + "0001 3500")
    reply = H("0100 0008 05 0001 3500 0001 01")
    assert Value.parse(Outcome.of(decode_reply(reply)).reader()).value == "5"
    assert encode_c3_reply(256, 5, Value("5").payload(), 1, True) == reply


def test_sample_3_5_7_read_multiple() -> None:  # §3.5.7: per-variable code is one byte
    frame = ReadMultiple(("PING", "@PROXY_PORT")).frame(1024)
    assert frame == H("0400 0024 06 02 0004" + W("PING") + "000B" + W("@PROXY_PORT"))
    reply = H("0400 001B 06 02 01 0004" + W("PONG") + "01 0004" + W("7000") + "0001 01")
    out = Outcome.of(decode_reply(reply))
    assert Multiple.parse(out.reader()) == Multiple(((1, "PONG"), (1, "7000")))
    assert (
        encode_c3_reply(1024, 6, Multiple(((1, "PONG"), (1, "7000"))).payload(), 1, True) == reply
    )


def test_sample_3_5_8_write_multiple() -> None:  # §3.5.8
    frame = WriteMultiple((("$OV_PRO", "37"), ("$OV_JOG", "100"))).frame(1024)
    expected = "0400 0030 07 02 0007" + W("$OV_PRO") + "0002" + W("37")
    expected += "0007" + W("$OV_JOG") + "0003" + W("100")
    assert frame == H(expected)
    reply = H("0400 0015 07 02 01 0002" + W("37") + "01 0003" + W("100") + "0001 01")
    assert Multiple.parse(Outcome.of(decode_reply(reply)).reader()).items == ((1, "37"), (1, "100"))


def test_sample_3_6_1_program_control() -> None:  # §3.6.1: reset of the submit interpreter
    frame = ProgramControl(ProgramCommand.RESET, 0).frame(652)
    assert frame == H("028C 0004 0A 01 0000")
    out = Outcome.of(decode_reply(H("028C 0005 0A 01 0001 01")))
    assert Echo.parse(out.reader()) == Echo(1) and out.ok
    assert encode_c3_reply(652, 10, Echo(1).payload(), 1, True) == H("028C 0005 0A 01 0001 01")


def test_layout_3_6_2_program_select() -> None:  # §3.6.2 (no sample): u8, i16, name, params, bool
    payload = ProgramSelect("/R1/CELL", "", False).payload()
    assert payload == H("05 0000 0008" + W("/R1/CELL") + "0000 00")
    run = ProgramSelect("/R1/CELL", "1,2", True, ProgramCommand.RUN)
    assert ProgramSelect.parse(Reader(run.payload())) == run


def test_sample_3_7_1_motion() -> None:  # §3.7.1
    position = "{POS: X 0, Y 0, Z 0, A 0, B 0, C 0}"
    frame = Motion(MotionType.PTP, position).frame(128)
    assert frame == H("0080 004A 0B 01 0023" + W(position))
    assert encode_c3_reply(128, 11, Echo(1).payload(), 1, True) == H("0080 0005 0B 01 0001 01")


def test_layout_3_7_2_kcp_key() -> None:  # §3.7.2: u8 key, i32, i32, bool, bool
    payload = KcpAction(3, 6, 2, True, False).payload()
    assert payload == H("03 00000006 00000002 01 00")
    assert KcpAction.parse(Reader(H("01 00000001 00000000 02 01"))).direction  # non-zero: TRUE


def test_sample_3_8_1_proxy_info() -> None:  # §3.8.1
    assert ProxyInfo().frame(0) == H("0000 0001 0D")
    reply = H(
        "0000 002F 0D 01 00 00 07E4 0008 0002 0004 0008 0038 0006 0379 000B"
        + W("VDMHOSTTEST")
        + "0001 01"
    )
    info = ProxyInfoReply.parse(Outcome.of(decode_reply(reply)).reader())
    assert info.version == "1.0 (OPEN SOURCE)" and info.computer_name == "VDMHOSTTEST"
    assert info.time == dt.datetime(2020, 8, 4, 8, 56, 6, 889000, tzinfo=dt.UTC)
    # 2020-08-04 was a Tuesday: SYSTEMTIME's wDayOfWeek 2 (Sunday = 0), as in the sample
    assert encode_c3_reply(0, 13, info.payload(), 1, True) == reply


def test_sample_3_8_2_proxy_features() -> None:  # §3.8.2: 32 bytes, type 255 first
    assert ProxyFeatures().frame(0) == H("0000 0001 0E")
    reply = H("0000 0024 0E" + "00" * 24 + "80 0000000000 7C F3" + "0001 01")
    features = FeatureMap.parse(Outcome.of(decode_reply(reply)).reader())
    assert features.types == {0, 1, 4, 5, 6, 7, 10, 11, 12, 13, 14, 63}
    assert encode_c3_reply(0, 14, features.payload(), 1, True) == reply


def test_sample_2_4_features_string() -> None:  # §2.4: the last character is message #0
    assert FeatureMap.from_string("0111110011110011").types == {
        0,
        1,
        4,
        5,
        6,
        7,
        10,
        11,
        12,
        13,
        14,
    }
    full = FeatureMap(frozenset({0, 1, 4, 63})).to_string()
    assert len(full) == 64 and full[0] == "1" and full[-1] == "1" and full[-3] == "0"
    assert FeatureMap.from_string(full).types == {0, 1, 4, 63}
    with pytest.raises(ValueError):
        FeatureMap.from_string("01x1")


def test_layout_3_8_5_benchmark() -> None:  # §3.8.5
    payload = Benchmark(("$OV_PRO",), 10, ("50",)).payload()
    assert payload == H("01 01 0000000A 0007" + W("$OV_PRO") + "0002" + W("50"))
    reply = BenchmarkReply(False, 1, 10, 100, 130, 30)
    assert reply.payload() == H("00 01 0000000A 00000064 00000082 0000001E")


def test_sample_3_10_1_confirm_all() -> None:  # §3.10.1: no payload either way
    assert ConfirmAll().frame(7) == H("0007 0001 3F")
    out = Outcome.of(decode_reply(H("0007 0004 3F 0001 01")))
    assert (out.type, out.payload, out.ok) == (63, b"", True)


def test_failure_footer() -> None:  # §3.2/§3.3: code + flag; any non-zero flag is TRUE
    out = Outcome.of(decode_reply(H("0001 0004 17 0009 00")))
    assert (out.type, out.code, out.ok) == (23, 9, False)
    assert Outcome.of(decode_reply(H("0001 0004 17 0001 FF"))).ok
    assert error_name(9).startswith("ErrorProtocol") and error_name(42) == "error 42"


# --------------------------------------------------------------------------- file layouts


def test_file_layouts() -> None:  # §3.9.2 .. §3.9.18, field by field
    assert FileSetAttribute("A", 1, 1).payload() == H("00000001 00000001 0001" + W("A"))
    assert FileNameList("KRC:\\", 0, 1).payload() == H("00000000 00000001 0005" + W("KRC:\\"))
    assert FileCreate("X", 32, 6, True, "T").payload() == H(
        "0020 06 01 0001" + W("X") + "0001" + W("T")
    )
    assert FileDelete("X", True).payload() == H("01 0001" + W("X"))
    assert FileCopy("A", "B", 64).payload() == H("00000040 0001" + W("A") + "0001" + W("B"))
    assert FileMove("A", "B").frame(0)[4] == Command.FILE_MOVE
    assert FileGetProperties("A").payload() == H("000000FF 0001" + W("A"))
    assert FileGetFullName("/R1/T.SRC").frame(0)[4] == 27
    assert FileWriteBegin(70000).payload() == H("01 00011170")
    assert FileWriteData(4, b"ab").payload() == H("02 00000004 00000002 6162")
    assert FileWriteEnd("N", 64).payload() == H("04 00000040 0001" + W("N"))
    # §3.9.15 prints the name length as UINT32; the server reads UINT16 (client_file.cpp)
    assert FileReadBegin("N").payload() == H("01 00000000 0001" + W("N"))
    assert FileReadData(8).payload() == H("02 00000008 FFFFFFFF")
    assert FileReadEnd().payload() == bytes((FileIo.END,))
    assert IoSize(1, 5).payload() == H("01 00000005")
    assert IoWritten.parse(Reader(H("02 00000004 00000002"))) == IoWritten(4, 2)
    assert IoChunk(0, b"xy").payload() == H("02 00000000 00000002 7879")
    listing = NameList(("KRC:\\R1",), ("i",))
    assert listing.payload() == H("0001 0007" + W("KRC:\\R1") + "0001 0001" + W("i"))
    props = Properties("T.SRC", int(ItemType.MODULE), (1 << 33) + 5, 32, modified=(7 << 32) + 9)
    raw = props.payload()
    assert raw[:12] == H("00000020 00000005 00000002")  # type, size low, size high
    assert Properties.parse(Reader(raw)) == props


# --------------------------------------------------------------------------- properties

texts = st.text(max_size=40)
names = st.lists(st.text(min_size=1, max_size=20), max_size=12)


@given(texts)
def test_wstr_counts_utf16_units(text: str) -> None:
    raw = Writer().wstr(text).payload()
    assert int.from_bytes(raw[:2], "big") == utf16_units(text) == (len(raw) - 2) // 2
    assert Reader(raw).wstr() == text


@given(names, st.lists(st.tuples(st.text(max_size=10), st.text(max_size=10)), max_size=8))
def test_variable_messages_round_trip(ns: list[str], pairs: list[tuple[str, str]]) -> None:
    for msg in (ReadMultiple(tuple(ns)), WriteMultiple(tuple(pairs))):
        parsed = type(msg).parse(Reader(payload_of(msg.frame(9))))
        assert parsed == msg


@given(
    st.lists(st.tuples(st.integers(0, 255), texts), max_size=20), st.integers(0, 10), st.booleans()
)
def test_multiple_reply_round_trip(items: list[tuple[int, str]], code: int, ok: bool) -> None:
    frame = encode_c3_reply(3, 6, Multiple(tuple(items)).payload(), code, ok)
    out = Outcome.of(decode_reply(frame))
    assert (out.code, out.ok, Multiple.parse(out.reader()).items) == (code, ok, tuple(items))


@given(st.frozensets(st.integers(0, 255)))
def test_feature_map_round_trip(types: frozenset[int]) -> None:
    assert FeatureMap.parse(Reader(FeatureMap(types).payload())).types == types
    if types:
        assert FeatureMap.from_string(FeatureMap(types).to_string()).types == types


@given(st.binary(max_size=64))
def test_truncated_payloads_raise_payload_error(data: bytes) -> None:
    for kind in (ReadVariable, WriteMultiple, ProgramSelect, KcpAction, Benchmark, FileCreate):
        try:
            kind.parse(Reader(data))
        except PayloadError:
            pass


def test_limits() -> None:
    with pytest.raises(PayloadError, match="at most 255"):
        ReadMultiple(tuple("x" * 256)).payload()
    with pytest.raises(PayloadError, match="payload"):
        ReadVariable("A" * 40000).frame(0)
    with pytest.raises(PayloadError):
        Writer().u8(256)


def test_motion_and_key_names() -> None:
    assert motion_type(" lin_rel ") is MotionType.LIN_REL and motion_type(1) is MotionType.PTP
    assert key_type("jog") is KcpKey.JOG and key_type(2) is KcpKey.STOP
    # both refuse the same way: a ValueError naming the choices (the CLI turns it into exit 2)
    with pytest.raises(ValueError, match=r"unknown key 'PRESS' \(START, STOP, JOG, MOUSE_6D\)"):
        key_type("PRESS")
    with pytest.raises(ValueError, match=r"unknown motion type 9 \(PTP, LIN, PTP_REL, LIN_REL\)"):
        motion_type(9)


def test_identify() -> None:
    assert identify(None, None, None) == ServerInfo("kvp")
    assert identify("", "", "").describe() == "KUKAVARPROXY"
    info = identify("C3 BRIDGE INTERFACE", "1.4 (OPEN SOURCE)", "1" + "0" * 55 + "11110011")
    assert info.version == (1, 4) and info.edition == "OPEN SOURCE" and 63 in info.features
    assert info.supports(Command.READ_MULTIPLE) and not info.supports(Command.FILE_READ_CONTENT)
    old = identify("C3 BRIDGE INTERFACE", "1.1 (FREEWARE)", "11110011")
    assert not old.supports(Command.READ_MULTIPLE)  # spec §3.5.7: not below 1.2
    assert parse_version("junk") == (None, "")
