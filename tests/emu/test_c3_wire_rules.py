"""The C3 Bridge responder message by message, in raw frames: every handled type, its error
codes and the fields its answer keeps when it fails, as ulsu-tech/c3bridge-server's handlers
(``source/handlers/*.cpp``) build them. Expected bytes are written out by hand from that
source, so a changed rule fails here."""

from __future__ import annotations

import asyncio
import datetime as dt
import logging
import random
import struct
import time
from collections.abc import Iterator
from typing import Any

import pytest

from kukavarproxy_emu import Emulator
from kukavarproxy_emu.abuse import big_module
from kukavarproxy_emu.c3 import HANDLED, VERSION, C3Session
from kukavarproxy_emu.c3 import control as c3_control
from kukavarproxy_emu.c3 import server as c3_server
from kukavarproxy_emu.logsafe import RateLimitedLog
from kukavarproxy_emu.testing import EmulatorFactory, RawClient, wait_until
from pyopenshowvar.c3.constants import ErrorCode
from pyopenshowvar.c3.files import FileWriteBegin, FileWriteData
from pyopenshowvar.c3.messages import ProgramControl, ProgramSelect
from pyopenshowvar.c3.replies import Outcome, ProxyInfoReply
from pyopenshowvar.c3.wire import Reader
from pyopenshowvar.errors import ProtocolError
from pyopenshowvar.protocol import Request, decode_reply, encode_read

H = bytes.fromhex


def W(text: str) -> bytes:
    """A WSTRING field: u16 length in UTF-16 units, then UTF-16LE."""
    return struct.pack(">H", len(text)) + text.encode("utf-16-le")


def A(text: str) -> bytes:
    """An ASCII string field of #0/#1: u16 length, then the bytes."""
    return struct.pack(">H", len(text)) + text.encode("latin-1")


async def outcome(raw: RawClient, message: bytes) -> Outcome:
    return Outcome.of(decode_reply(await raw.request(message)))


def frame(tag: int, msg_type: int, payload: bytes = b"") -> bytes:
    return struct.pack(">HHB", tag, len(payload) + 1, msg_type) + payload


def answer(tag: int, msg_type: int, payload: bytes, code: int) -> bytes:
    """The whole answer frame: payload, error code, success flag (1 only for SUCCESS)."""
    footer = struct.pack(">HB", code, 1 if code == ErrorCode.SUCCESS else 0)
    return frame(tag, msg_type, payload + footer)


CONFIG = "DEFDAT $CONFIG\nDECL INT RULE_A=1\nDECL INT RULE_B=2\nDECL INT RULE_C=3\nENDDAT\n"


@pytest.fixture
async def c3(emulator_factory: EmulatorFactory) -> Emulator:
    return await emulator_factory(proxy="c3bridge", plant="ideal", dat_text=CONFIG)


@pytest.fixture
async def raw(c3: Emulator) -> RawClient:
    client = await RawClient.connect(c3.host, c3.port)
    yield client  # type: ignore[misc]
    await client.close()


# ------------------------------------------------------------------------ #0, #1 (ASCII)


async def test_ascii_read_rules(raw: RawClient) -> None:
    ok = H("0001 0009 00 0003") + b"100" + H("0001 01")
    assert await raw.request(frame(1, 0, A("$OV_PRO"))) == ok
    # trailing bytes are ignored (the server's MessageReader reads the fields it needs)
    assert await raw.request(frame(1, 0, A("$OV_PRO") + H("BEEF"))) == ok
    empty_failure = H("0002 0006 00 0000 0000 00")
    for payload in (A("NOPE"), b"", H("00"), H("0009") + b"$OV", H("FFFF")):
        assert await raw.request(frame(2, 0, payload)) == empty_failure, payload
    assert await raw.request(frame(3, 0, A("PING"))) == H("0003 000A 00 0004") + b"PONG" + H(
        "0001 01"
    )
    # untrimmed, as CrossComm shows it: a whole array ends in a space (KVP would trim it)
    torque = decode_reply(await raw.request(frame(4, 0, A("$TORQUE_AXIS_ACT[]"))))
    assert torque.ok and torque.text.endswith(" ") and not torque.text.startswith(" ")


async def test_ascii_write_rules(c3: Emulator, raw: RawClient) -> None:
    assert await raw.request(frame(1, 1, A("RULE_A") + A("42"))) == H(
        "0001 0008 01 0002 3432 0001 01"
    )
    assert c3.store.read("RULE_A") == "42"
    empty_failure = H("0002 0006 01 0000 0000 00")
    cases = (
        A("$AXIS_ACT") + A("{A1 1}"),  # read-only: refused, the value is not echoed
        A("RULE_B"),  # no value block
        A("RULE_B") + H("0005") + b"9",  # a value longer than the bytes sent
        b"",  # no payload
    )
    for payload in cases:
        assert await raw.request(frame(2, 1, payload)) == empty_failure, payload
    assert c3.store.read("RULE_B") == "2"  # nothing half-applied
    assert await raw.request(frame(3, 1, A("RULE_C") + A("7") + H("00"))) == H(
        "0003 0007 01 0001 37 0001 01"
    )


# ------------------------------------------------------------------------ #4..#7


async def test_read_and_write_variable_utf16(c3: Emulator, raw: RawClient) -> None:
    assert await raw.request(frame(1, 4, W("RULE_A"))) == answer(1, 4, W("1"), 1)
    assert await raw.request(frame(2, 4, W("NOPE"))) == answer(2, 4, W(""), ErrorCode.GENERAL)
    assert await raw.request(frame(3, 4, H("0003 41"))) == answer(3, 4, W(""), ErrorCode.PROTOCOL)
    assert await raw.request(frame(4, 4)) == answer(4, 4, W(""), ErrorCode.PROTOCOL)
    torque = await raw.request(frame(5, 4, W("$TORQUE_AXIS_ACT[]")))
    assert torque[-5:-3] == " ".encode("utf-16-le")  # the last character, untrimmed
    assert await raw.request(frame(6, 5, W("RULE_B") + W("5"))) == answer(6, 5, W("5"), 1)
    assert c3.store.read("RULE_B") == "5"
    refused = await raw.request(frame(7, 5, W("$AXIS_ACT") + W("{A1 1}")))
    assert refused == answer(7, 5, W(""), ErrorCode.GENERAL)
    assert await raw.request(frame(8, 5, W("RULE_B"))) == answer(8, 5, W(""), ErrorCode.PROTOCOL)
    assert c3.store.read("RULE_B") == "5"


async def test_read_multiple_codes_and_bounds(raw: RawClient) -> None:
    payload = H("03") + W("RULE_A") + W("NOPE") + W("PING") + H("AA")  # + a trailing byte
    expected = H("03") + H("01") + W("1") + H("00") + W("") + H("01") + W("PONG")
    assert await raw.request(frame(1, 6, payload)) == answer(1, 6, expected, ErrorCode.GENERAL)
    assert await raw.request(frame(2, 6, H("01") + W("RULE_A"))) == answer(
        2, 6, H("01 01") + W("1"), 1
    )
    assert await raw.request(frame(3, 6, H("00"))) == answer(3, 6, H("00"), 1)
    for cut in (b"", H("02") + W("RULE_A"), H("01 0005") + b"x"):
        assert await raw.request(frame(4, 6, cut)) == answer(4, 6, H("00"), ErrorCode.PROTOCOL)


async def test_write_multiple_writes_the_whole_items_before_a_cut_one(
    c3: Emulator, raw: RawClient
) -> None:
    items = W("RULE_A") + W("11") + W("$AXIS_ACT") + W("{A1 1}") + W("RULE_B") + W("12")
    expected = H("03 01") + W("11") + H("00") + W("{A1 1}") + H("01") + W("12")
    reply = await raw.request(frame(1, 7, H("03") + items))
    assert reply == answer(1, 7, expected, ErrorCode.GENERAL)  # the refused one echoes the value
    cut = H("03") + W("RULE_A") + W("21") + W("RULE_B") + W("22") + W("RULE_C")
    assert await raw.request(frame(2, 7, cut)) == answer(2, 7, H("00"), ErrorCode.PROTOCOL)
    # the two whole items were written, as C3 Bridge writes each item as it reads it
    assert (c3.store.read("RULE_A"), c3.store.read("RULE_B"), c3.store.read("RULE_C")) == (
        "21",
        "22",
        "3",
    )
    assert await raw.request(frame(3, 7, b"")) == answer(3, 7, H("00"), ErrorCode.PROTOCOL)


# ------------------------------------------------------------------------ #10..#17, #63


async def test_program_control_echoes_and_codes(raw: RawClient) -> None:
    assert await raw.request(frame(1, 10)) == answer(1, 10, H("00"), ErrorCode.PROTOCOL)
    assert await raw.request(frame(2, 10, H("02"))) == answer(2, 10, H("02"), ErrorCode.PROTOCOL)
    assert await raw.request(frame(3, 10, H("07 0001"))) == answer(
        3, 10, H("07"), ErrorCode.NOT_IMPLEMENTED
    )
    assert await raw.request(frame(4, 10, H("00 0001"))) == answer(
        4, 10, H("00"), ErrorCode.NOT_IMPLEMENTED
    )
    # reset with nothing selected is refused; an interpreter that does not exist too
    assert await raw.request(frame(5, 10, H("01 0001"))) == answer(5, 10, H("01"), 0)
    assert await raw.request(frame(6, 10, H("02 0005"))) == answer(
        6, 10, H("02"), ErrorCode.ARGUMENT
    )
    # select: name, parameters and force are required
    assert await raw.request(frame(7, 10, H("05 0000") + W("/R1/X"))) == answer(
        7, 10, H("05"), ErrorCode.PROTOCOL
    )
    missing = H("05 0000") + W("/R1/NOPE") + W("") + H("00")
    assert await raw.request(frame(8, 10, missing)) == answer(8, 10, H("05"), 0)


async def test_motion_answers_every_target_and_echoes_its_type(c3: Emulator) -> None:
    async with await RawClient.connect(c3.host, c3.port) as raw:
        huge = frame(1, 11, H("01") + W("{A1 " + "9" * 400 + "}"))
        assert await raw.request(huge) == answer(1, 11, H("01"), ErrorCode.GENERAL)
        for n, text in enumerate(("{A1 1e999}", "{A1 -9" + "9" * 400 + ".5}", "{X", "7"), 2):
            assert await raw.request(frame(n, 11, H("02") + W(text))) == answer(
                n, 11, H("02"), ErrorCode.GENERAL
            ), text
        assert await raw.request(frame(9, 11, H("09") + W("{A1 1}"))) == answer(
            9, 11, H("09"), ErrorCode.NOT_IMPLEMENTED
        )
        assert await raw.request(frame(10, 11, H("01"))) == answer(
            10, 11, H("01"), ErrorCode.PROTOCOL
        )
        assert await raw.request(frame(11, 11)) == answer(11, 11, H("00"), ErrorCode.PROTOCOL)
        assert c3.robot is not None and not c3.robot.kernel.moving  # nothing was planned


async def test_kcp_keys(raw: RawClient) -> None:
    def kcp(kind: int, released: int = 0) -> bytes:
        return bytes((kind,)) + H("00000001 00000000 00") + bytes((released,))

    assert await raw.request(frame(1, 12, kcp(3))) == answer(
        1, 12, H("03"), ErrorCode.NOT_IMPLEMENTED
    )
    assert await raw.request(frame(2, 12, kcp(9))) == answer(
        2, 12, H("09"), ErrorCode.NOT_IMPLEMENTED
    )
    assert await raw.request(frame(3, 12, kcp(1, 1))) == answer(3, 12, H("01"), 1)  # released
    assert await raw.request(frame(4, 12, H("02 0000"))) == answer(
        4, 12, H("02"), ErrorCode.PROTOCOL
    )
    assert await raw.request(frame(5, 12)) == answer(5, 12, H("00"), ErrorCode.PROTOCOL)


async def test_benchmark_answers_keep_what_was_parsed(raw: RawClient) -> None:
    def bench(write: int, count: int, iterations: int, code: int) -> bytes:
        return H(f"{write:02x} {count:02x} {iterations:08x} 00000000 00000000 00000000"), code

    cases = [
        (b"", *bench(0, 0, 0, ErrorCode.PROTOCOL)),
        (H("01"), *bench(1, 0, 0, ErrorCode.PROTOCOL)),
        (H("01 05"), *bench(1, 5, 0, ErrorCode.PROTOCOL)),  # the count it parsed
        (H("00 0C 00000003"), *bench(0, 10, 3, ErrorCode.PROTOCOL)),  # capped at 10, no names
        (H("01 01 00000002") + W("RULE_A"), *bench(1, 1, 2, ErrorCode.PROTOCOL)),  # no value
        (H("00 01 FFFFFFFF"), *bench(0, 1, 0xFFFFFFFE, ErrorCode.PROTOCOL)),  # capped first
    ]
    for n, (payload, expected, code) in enumerate(cases, 1):
        assert await raw.request(frame(n, 17, payload)) == answer(n, 17, expected, code), payload
    # 20 announced, 10 sent: the server reads only 10, so this one succeeds
    names = b"".join(W("RULE_A") for _ in range(10))
    out = decode_reply(await raw.request(frame(9, 17, H("00 14 00000002") + names)))
    assert out.ok and out.value[:6] == H("00 0A 00000002")


async def test_info_features_and_confirm(raw: RawClient) -> None:
    info = decode_reply(await raw.request(frame(1, 13, H("DEAD"))))  # payload ignored
    major, minor, kind = VERSION
    assert info.ok and info.value[:3] == bytes((major, minor, kind))
    features = decode_reply(await raw.request(frame(2, 14)))
    assert features.ok and len(features.value) == 32
    bits = int.from_bytes(features.value, "big")
    assert {t for t in range(256) if bits >> t & 1} == HANDLED
    assert await raw.request(frame(3, 63, H("00"))) == answer(3, 63, b"", 1)


# ------------------------------------------------------------------------ #20..#30


async def test_file_messages_cut_short(raw: RawClient) -> None:
    protocol = ErrorCode.PROTOCOL
    zeros26 = bytes(4 * 14) + W("")
    cases = {
        20: (H("00000001 00000001"), b""),
        21: (H("00000000"), H("0000 0000")),
        22: (H("0001 00 00") + W("KRC:\\R1\\X.SRC"), b""),  # no template name
        23: (H("01"), b""),
        24: (H("00000000") + W("KRC:\\R1\\A.SRC"), b""),
        25: (H("00000000"), b""),
        26: (H("00000000"), zeros26),
        27: (H("0002 4100"), W("")),
        28: (b"", W("")),
    }
    for n, (msg_type, (payload, out)) in enumerate(cases.items(), 1):
        assert await raw.request(frame(n, msg_type, payload)) == answer(
            n, msg_type, out, protocol
        ), msg_type


async def test_upload_fields_kept_on_failure(c3: Emulator, raw: RawClient) -> None:
    protocol = ErrorCode.PROTOCOL
    assert await raw.request(frame(1, 29)) == answer(1, 29, b"", protocol)
    assert await raw.request(FileWriteBegin(6).frame(2)) == answer(2, 29, H("01 00000006"), 1)
    # begin cut short: the operation and the size of the buffer as it is
    assert await raw.request(frame(3, 29, H("01 0000"))) == answer(3, 29, H("01 00000006"), 9)
    assert await raw.request(frame(4, 29, H("03"))) == answer(4, 29, H("03 00000006"), 1)
    assert await raw.request(frame(5, 29, H("02 00000000"))) == answer(5, 29, b"", protocol)
    # a chunk shorter than announced: ErrorAccess, offset and (clipped) size echoed, nothing kept
    short = frame(6, 29, H("02 00000002 00000009") + b"ab")
    assert await raw.request(short) == answer(6, 29, H("02 00000002 00000004"), ErrorCode.ACCESS)
    assert await raw.request(FileWriteData(0, b"abcdef").frame(7)) == answer(
        7, 29, H("02 00000000 00000006"), 1
    )
    beyond = frame(8, 29, H("02 00000009 00000004") + b"wxyz")  # past the end: 0 taken
    assert await raw.request(beyond) == answer(8, 29, H("02 00000009 00000000"), 1)
    assert await raw.request(frame(9, 29, H("04 00000040"))) == answer(9, 29, H("04"), protocol)
    assert await raw.request(frame(10, 29, H("05"))) == answer(
        10, 29, H("05"), ErrorCode.NOT_IMPLEMENTED
    )
    end = frame(11, 29, H("04 00000040") + W("KRC:\\R1\\Program\\RULES.SRC"))
    assert await raw.request(end) == answer(11, 29, H("04"), 1)
    assert c3.c3 is not None and c3.c3.vfs.read("KRC:\\R1\\Program\\RULES.SRC").data == b"abcdef"
    # the end of a file that is the selected program: ErrorAccess with the operation byte
    c3.c3.control.selected = "KRC:\\R1\\Program\\RULES.SRC"
    c3.c3.control.robot.program = object()  # type: ignore[union-attr,assignment]
    assert await raw.request(FileWriteBegin(1).frame(12)) == answer(12, 29, H("01 00000001"), 1)
    assert await raw.request(end) == answer(11, 29, H("04"), ErrorCode.ACCESS)


async def test_download_fields_kept_on_failure(raw: RawClient) -> None:
    protocol = ErrorCode.PROTOCOL
    begin = frame(1, 30, H("01 00000000") + W("KRC:\\R1\\Program\\FOLLOW.SRC"))
    size = decode_reply(await raw.request(begin)).value
    assert size[0] == 1 and int.from_bytes(size[1:], "big") > 0
    assert await raw.request(frame(2, 30, H("01 0000"))) == answer(2, 30, size, protocol)
    assert await raw.request(frame(3, 30, H("02 00000000"))) == answer(3, 30, b"", protocol)
    first = await raw.request(frame(4, 30, H("02 00000000 00000004")))
    assert first[5:14] == H("02 00000000 00000004") and first[-3:] == H("0001 01")
    assert await raw.request(frame(5, 30, H("02 00100000 00000004"))) == answer(
        5, 30, H("02 00100000 00000000"), 1
    )
    total = int.from_bytes(size[1:], "big")
    near_end = await raw.request(
        frame(10, 30, H("02") + (total - 2).to_bytes(4, "big") + H("0000000A"))
    )
    assert near_end[5:14] == H("02") + (total - 2).to_bytes(4, "big") + H("00000002")
    assert await raw.request(frame(6, 30, H("04"))) == answer(6, 30, H("04"), 1)
    assert await raw.request(frame(7, 30, H("03"))) == answer(7, 30, H("03 00000000"), 1)
    assert await raw.request(frame(8, 30, H("07"))) == answer(
        8, 30, H("07"), ErrorCode.NOT_IMPLEMENTED
    )
    assert await raw.request(frame(9, 30)) == answer(9, 30, b"", protocol)


# ------------------------------------------------------------------------ no message stops it


async def test_random_payloads_of_every_type_are_all_answered(
    c3: Emulator, caplog: pytest.LogCaptureFixture
) -> None:
    rng = random.Random(16)
    # program, motion and key messages change the robot's state: their rules are pinned above
    types = sorted(HANDLED - {10, 11, 12})
    async with await RawClient.connect(c3.host, c3.port) as raw:
        for n in range(1, 600):
            msg_type = rng.choice(types)
            size = rng.choice((0, 1, 2, 3, 5, 9, 17, 40))
            reply = await raw.request(frame(n, msg_type, rng.randbytes(size)))
            out = decode_reply(reply)
            assert (out.msg_id, out.mode) == (n, msg_type)
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]


# ------------------------------------------------------------------------ selects in slices


async def test_other_clients_are_served_while_a_big_module_is_selected(
    c3: Emulator, raw: RawClient
) -> None:
    assert c3.c3 is not None
    c3.c3.vfs.write("KRC:\\R1\\Program\\BIGMOD.SRC", big_module("BIGMOD", 60_000), overwrite=True)
    served = 0
    async with await RawClient.connect(c3.host, c3.port) as other:
        await raw.send(ProgramSelect("/R1/BIGMOD").frame(1))
        select = asyncio.create_task(raw.read_frame(timeout=30.0))
        while not select.done():
            assert decode_reply(await other.request(encode_read(7, "$OV_PRO"))).text == "100"
            served += 1
        assert (await select) == answer(1, 10, H("05"), 1)
    # ~0.2 s of parsing (more on a loaded machine) in slices of 2 ms: many reads in between,
    # where selecting in one go answered none
    assert served >= 10
    assert c3.store.read("$PRO_NAME1[]") == '"BIGMOD"'


async def test_a_start_sent_during_a_select_waits_for_it(c3: Emulator) -> None:
    assert c3.c3 is not None
    src = big_module("WAITS", 20_000)
    c3.c3.vfs.write("KRC:\\R1\\Program\\WAITS.SRC", src, overwrite=True)
    async with (
        await RawClient.connect(c3.host, c3.port) as first,
        await RawClient.connect(c3.host, c3.port) as second,
    ):
        await first.send(ProgramSelect("/R1/WAITS").frame(1))
        for _ in range(5000):  # the select has begun (its first slice runs next iteration)
            if c3.c3.control.selecting:
                break
            await asyncio.sleep(0.001)
        assert c3.c3.control.selecting
        # start (no motion: the module only counts) and a second select, both behind it
        await second.send(ProgramControl(2, 1).frame(2) + ProgramSelect("/R1/WAITS").frame(3))
        assert await first.read_frame(timeout=30) == answer(1, 10, H("05"), 1)
        assert await second.read_frame(timeout=30) == answer(2, 10, H("02"), 1)
        # the program runs now: the second select is refused, not half-done
        assert await second.read_frame(timeout=30) == answer(3, 10, H("05"), 0)


# ------------------------------------------------------------------------ session hooks


def test_decode_kind_and_weight() -> None:
    from kukavarproxy_emu.c3 import C3Server
    from kukavarproxy_emu.store import VariableStore
    from pyopenshowvar.errors import ProtocolError
    from pyopenshowvar.protocol import Request

    session = C3Server(VariableStore(), None).session()
    assert session.decode(H("0102 0003 00 AABB")) == Request(0x0102, 0, "", H("AABB"))
    assert session.decode(H("0102 0001 3F")) == Request(0x0102, 63, "", b"")
    with pytest.raises(ProtocolError, match="length 0"):
        session.decode(H("0102 0000"))

    def kind(msg_type: int, payload: bytes = b"") -> str | None:
        return session.kind(Request(1, msg_type, "", payload))

    # which messages cost a CrossComm service time, and which kind (latency profiles)
    assert [kind(0), kind(1), kind(4), kind(5), kind(6), kind(7)] == [
        "read", "write", "read", "write", "read", "write",
    ]  # fmt: skip
    assert [kind(10), kind(11), kind(12), kind(13), kind(14), kind(17), kind(63)] == [
        "write", "write", "write", None, None, "read", "write",
    ]  # fmt: skip
    assert [kind(29, H("04")), kind(29, H("02")), kind(29), kind(30, H("01")), kind(30, H("02"))] == [
        "write", None, None, "read", None,
    ]  # fmt: skip
    assert [kind(21), kind(22), kind(26)] == ["read", "write", "read"]
    assert kind(30) is None  # a file read cut before its operation loads nothing
    weight = session.weight
    assert weight(Request(1, 6, "", H("05"))) == 5 and weight(Request(1, 7, "", H("03"))) == 3
    assert weight(Request(1, 6, "", H("00"))) == 1 and weight(Request(1, 6, "", b"")) == 1
    assert weight(Request(1, 4, "", H("09"))) == 1


async def test_benchmark_times_with_the_servers_tick(c3: Emulator, raw: RawClient) -> None:
    from pyopenshowvar.c3.replies import BenchmarkReply

    assert c3.c3 is not None
    before = c3.c3.tick_ms()
    out = decode_reply(await raw.request(frame(1, 17, H("00 01 00000064") + W("RULE_A"))))
    reply = BenchmarkReply.parse(Outcome.of(out).reader())
    after = c3.c3.tick_ms()
    assert out.ok and (reply.write, reply.count, reply.iterations) == (False, 1, 100)
    # milliseconds since the server started, GetTickCount-like: between the two readings
    assert before <= reply.start_ms <= after and before < 10 * 60 * 1000
    assert reply.stop_ms - reply.start_ms == reply.elapsed_ms <= after - before + 1
    await asyncio.sleep(0.05)
    assert c3.c3.tick_ms() - after >= 45  # it counts milliseconds


async def test_benchmark_writes_its_values_within_10000_store_operations(
    c3: Emulator, raw: RawClient
) -> None:
    """#17 (docs/c3bridge.md): a write benchmark writes each name's own value; the work is at
    most 10 000 store operations, the reply says how many iterations were done, and its
    elapsed time is that of all of them."""
    from pyopenshowvar.c3.replies import BenchmarkReply

    async def bench(tag: int, payload: bytes) -> BenchmarkReply:
        out = decode_reply(await raw.request(frame(tag, 17, payload), timeout=20))
        assert out.ok, out
        return BenchmarkReply.parse(Outcome.of(out).reader())

    two = W("RULE_A") + W("41") + W("RULE_B") + W("42")
    reply = await bench(1, H("01 02 00000003") + two)
    assert (reply.write, reply.count, reply.iterations) == (True, 2, 3)
    assert (c3.store.read("RULE_A"), c3.store.read("RULE_B")) == ("41", "42")
    assert (await bench(2, H("00 00 0000FFFF"))).iterations == 10_000  # nothing to do
    assert (await bench(3, H("00 03 0000FFFF") + W("RULE_A") * 3)).iterations == 3_333
    # one name: 10 000 reads of the arm's axes, milliseconds of store time in all (the last
    # iteration alone is microseconds)
    reply = await bench(4, H("00 01 FFFFFFFF") + W("$AXIS_ACT"))
    assert (reply.count, reply.iterations) == (1, 10_000)
    assert reply.elapsed_ms >= 2 and reply.stop_ms - reply.start_ms == reply.elapsed_ms
    # cut short before its iterations: the count parsed so far, capped at 10
    cut = await raw.request(frame(5, 17, H("00 0C 0000")))
    assert cut == answer(5, 17, H("00 0A 00000000 00000000 00000000 00000000"), ErrorCode.PROTOCOL)


# ------------------------------------------------------------------------ file rules


def _files() -> tuple[object, object, object]:
    from kukavarproxy_emu.c3.control import RobotControl
    from kukavarproxy_emu.c3.filemsgs import FileHandlers, IoBuffers
    from kukavarproxy_emu.c3.vfs import VirtualFS

    vfs = VirtualFS()
    handlers = FileHandlers(vfs, RobotControl(None, vfs), lambda: 0, 1 << 30)
    return vfs, handlers, IoBuffers()


def test_name_list_answers_long_answer_past_the_servers_safe_size() -> None:
    from kukavarproxy_emu.c3.filemsgs import SAFE_PAYLOAD, _info
    from kukavarproxy_emu.c3.vfs import Limits
    from pyopenshowvar.c3.files import FileNameList

    vfs, handlers, io = _files()
    vfs.mkdir("KRC:\\BIG")  # type: ignore[attr-defined]
    vfs.write("KRC:\\BIG\\A.SRC", b"", overwrite=False)  # type: ignore[attr-defined]

    def listing() -> tuple[bytes, int]:
        payload = FileNameList("KRC:\\BIG").payload()
        return handlers.handle(21, payload, io)  # type: ignore[attr-defined,no-any-return]

    def cost(text: str) -> int:  # the server: SysStringByteLen + a u16 per string
        return 2 + 2 * len(text)

    out, code = listing()
    assert code == ErrorCode.SUCCESS
    used = cost("KRC:\\BIG\\A.SRC") + cost(_info(vfs.read("KRC:\\BIG\\A.SRC")))  # type: ignore[attr-defined]
    vfs.write("KRC:\\BIG\\B.SRC", b"", overwrite=False)  # type: ignore[attr-defined]
    info_b = cost(_info(vfs.read("KRC:\\BIG\\B.SRC")))  # type: ignore[attr-defined]
    vfs.delete("KRC:\\BIG\\B.SRC", force=True)  # type: ignore[attr-defined]
    # a second file whose name makes the listing exactly SafePayloadSize: still answered
    stem = (SAFE_PAYLOAD - used - info_b - 2) // 2 - len("KRC:\\BIG\\.SRC")
    name = "KRC:\\BIG\\" + "N" * stem + ".SRC"
    assert used + cost(name) + info_b == SAFE_PAYLOAD
    vfs.limits = Limits(path_length=10**6)  # type: ignore[attr-defined]
    vfs.write(name, b"", overwrite=False)  # type: ignore[attr-defined]
    out, code = listing()
    assert code == ErrorCode.SUCCESS and out[:2] == H("0002")
    vfs.delete(name, force=True)  # type: ignore[attr-defined]
    vfs.write(name.replace(".SRC", "X.SRC"), b"", overwrite=False)  # type: ignore[attr-defined]
    out, code = listing()  # one character (two bytes) more
    assert (code, out) == (ErrorCode.LONG_ANSWER, H("0000 0000"))


async def test_file_flags_are_honoured(c3: Emulator, raw: RawClient) -> None:
    from pyopenshowvar.c3.files import FileCopy, FileCreate, FileGetProperties, FileNameList

    assert c3.c3 is not None
    vfs = c3.c3.vfs
    d = "KRC:\\R1\\Program\\"
    # #22: a file unless the item type says directory
    assert (await outcome(raw, FileCreate(d + "NEW.SRC").frame(1))).ok
    assert not vfs.is_dir(d + "NEW.SRC") and d + "NEW.SRC" in {f.path for f in vfs.files.values()}
    assert (await outcome(raw, FileCreate(d + "SUB", item_type=1).frame(2))).ok
    assert vfs.is_dir(d + "SUB")
    props = await outcome(raw, FileGetProperties(d + "SUB").frame(3))
    # item type, size (low, high), attributes: a directory of no size
    assert props.ok and props.payload[:16] == H("00000001 00000000 00000000 00000010")
    # #21: only the directory's own items unless recursive
    top = await outcome(raw, FileNameList("KRC:\\R1").frame(4))
    deep = await outcome(raw, FileNameList("KRC:\\R1", flags=1).frame(5))
    assert top.ok and deep.ok and len(deep.payload) > len(top.payload)
    assert (d + "NEW.SRC").encode("utf-16-le") in deep.payload
    assert (d + "NEW.SRC").encode("utf-16-le") not in top.payload
    # #24: no overwrite without the flag
    vfs.write(d + "A.SRC", b"a", overwrite=True)
    vfs.write(d + "B.SRC", b"b", overwrite=True)
    refused = await outcome(raw, FileCopy(d + "A.SRC", d + "B.SRC", 0).frame(6))
    assert not refused.ok and vfs.read(d + "B.SRC").data == b"b"
    assert (await outcome(raw, FileCopy(d + "A.SRC", d + "B.SRC", 64).frame(7))).ok
    assert vfs.read(d + "B.SRC").data == b"a"


async def test_upload_onto_a_read_only_file_needs_the_force_flag(
    c3: Emulator, raw: RawClient
) -> None:
    assert c3.c3 is not None
    vfs = c3.c3.vfs
    path = "KRC:\\R1\\Program\\RO.SRC"
    vfs.write(path, b"old", overwrite=True)
    vfs.set_attributes(path, 1, 1)  # read-only
    end = frame(3, 29, H("04 00000040") + W(path))  # overwrite, not read-only ones
    assert (await outcome(raw, FileWriteBegin(3).frame(1))).ok
    assert (await outcome(raw, FileWriteData(0, b"new").frame(2))).ok
    assert await raw.request(end) == answer(3, 29, H("04"), ErrorCode.ACCESS)
    assert vfs.read(path).data == b"old"
    forced = frame(4, 29, H("04 00001040") + W(path))  # + CopyFlag.OVERWRITE_READ_ONLY
    assert await raw.request(forced) == answer(4, 29, H("04"), 1)
    assert vfs.read(path).data == b"new"


async def test_download_chunk_of_size_zero_is_empty(raw: RawClient) -> None:
    begin = frame(1, 30, H("01 00000000") + W("KRC:\\R1\\Program\\FOLLOW.SRC"))
    assert decode_reply(await raw.request(begin)).ok
    assert await raw.request(frame(2, 30, H("02 00000000 00000000"))) == answer(
        2, 30, H("02 00000000 00000000"), 1
    )


async def test_a_krl_variable_named_ping_wins_over_the_internal_one(
    emulator_factory: EmulatorFactory,
) -> None:
    emu = await emulator_factory(
        proxy="c3bridge", robot=False, dat_text="DEFDAT $CONFIG\nDECL INT PING=5\nENDDAT\n"
    )
    async with await RawClient.connect(emu.host, emu.port) as raw:
        assert await raw.request(frame(1, 0, A("PING"))) == H("0001 0007 00 0001 35 0001 01")
        assert await raw.request(frame(2, 4, W("PING"))) == answer(2, 4, W("5"), 1)


async def test_a_select_whose_client_left_still_completes_and_frees_the_next(
    c3: Emulator,
) -> None:
    """A client that sends a select and disconnects at once: the select goes through (as a
    COM call on C3 Bridge would), and the next select is not left waiting for it."""
    assert c3.c3 is not None
    c3.c3.vfs.write("KRC:\\R1\\Program\\GONE.SRC", big_module("GONE", 8_000), overwrite=True)
    for _ in range(3):
        gone = await RawClient.connect(c3.host, c3.port)
        await gone.send(ProgramSelect("/R1/GONE").frame(1))
        gone.writer.transport.abort()  # a reset right behind the select
    # every select the server read from them is running or queued before the next one comes
    # (a message read after the next one would be selected after it, as on C3 Bridge)
    await wait_until(lambda: c3.stats.clients == 0, what="the server saw the clients leave")
    async with await RawClient.connect(c3.host, c3.port) as raw:
        reply = await raw.request(ProgramSelect("/R1/FOLLOW").frame(2), timeout=20)
        assert reply == answer(2, 10, H("05"), 1)
    assert not c3.c3.control.selecting
    assert c3.store.read("$PRO_NAME1[]") == '"FOLLOW"'


async def test_a_character_outside_ansi_is_written_as_a_question_mark(
    c3: Emulator, raw: RawClient
) -> None:
    """KRC text is ANSI: #5 and #7 write what has no ANSI character as '?', as the server's
    conversion does, instead of failing the write."""
    c3.store.declare("RULE_T", "CHAR", (8,), '"a"')
    assert await raw.request(frame(1, 5, W("RULE_T[]") + W('"€x"'))) == answer(1, 5, W('"€x"'), 1)
    assert c3.store.read("RULE_T[]") == '"?x"'
    reply = await raw.request(frame(2, 7, H("01") + W("RULE_T[]") + W('"y€"')))
    assert reply.endswith(W('"y?"') + H("0001 01"))  # read back, and success
    assert c3.store.read("RULE_T[]") == '"y?"'


async def test_a_start_or_stop_key_acts_on_the_interpreter_it_names(raw: RawClient) -> None:
    def kcp(kind: int, target: int) -> bytes:
        return bytes((kind,)) + struct.pack(">iiBB", target, 0, 0, 0)

    # the robot interpreter: no program runs, so there is nothing to stop
    assert await raw.request(frame(1, 12, kcp(2, 1))) == answer(1, 12, H("02"), 0)
    assert await raw.request(frame(2, 12, kcp(2, 0))) == answer(2, 12, H("02"), 1)  # submit
    assert await raw.request(frame(3, 12, kcp(2, 7))) == answer(3, 12, H("02"), ErrorCode.ARGUMENT)


async def test_the_servers_own_variables(c3: Emulator, raw: RawClient) -> None:
    """Spec §3.5.1: the internal variables a C3 client may read (by their exact names)."""

    async def read(tag: int, name: str) -> tuple[str, int]:
        reply = decode_reply(await raw.request(frame(tag, 4, W(name))))
        return reply.value[2:].decode("utf-16-le"), int.from_bytes(reply.code, "big")

    assert await read(1, "@PROXY_HOSTNAME") == ("KRC4-EMULATOR", ErrorCode.SUCCESS)
    assert await read(2, "@PROXY_ADDRESS") == ("127.0.0.1", ErrorCode.SUCCESS)
    assert await read(3, "@PROXY_PORT") == (str(c3.port), ErrorCode.SUCCESS)
    assert await read(4, "@PROXY_ENABLED") == ("TRUE", ErrorCode.SUCCESS)
    assert await read(5, "@proxy_enabled") == ("", ErrorCode.GENERAL)  # names are exact
    text, code = await read(6, "@PROXY_TIME")
    stamp = dt.datetime.strptime(text, "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=dt.UTC)
    assert code == ErrorCode.SUCCESS
    assert abs((dt.datetime.now(dt.UTC) - stamp).total_seconds()) < 60  # UTC, not local time


@pytest.fixture
def local_time_not_utc(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """This process's local time zone at UTC+9 for one test (POSIX TZ, no tz database
    needed), so that a clock read in local time cannot pass for UTC."""
    monkeypatch.setenv("TZ", "XST-9")
    time.tzset()
    yield
    monkeypatch.undo()
    time.tzset()


@pytest.mark.usefixtures("local_time_not_utc")
async def test_the_servers_clock_is_utc_on_a_machine_in_another_zone(raw: RawClient) -> None:
    """#13's SYSTEMTIME and @PROXY_TIME are UTC (spec §3.5.1), whatever the local zone."""
    assert dt.datetime.now().utcoffset() is None and time.localtime().tm_gmtoff == 9 * 3600
    info = decode_reply(await raw.request(frame(1, 13)))
    parsed = ProxyInfoReply.parse(Reader(info.value))
    assert info.ok and parsed.computer_name == "KRC4-EMULATOR"
    assert abs((dt.datetime.now(dt.UTC) - parsed.time).total_seconds()) < 60
    weekday = int.from_bytes(info.value[7:9], "big")  # SYSTEMTIME: Sunday is 0
    assert weekday == parsed.time.isoweekday() % 7
    reply = decode_reply(await raw.request(frame(2, 4, W("@PROXY_TIME"))))
    stamp = dt.datetime.strptime(reply.value[2:].decode("utf-16-le"), "%Y-%m-%dT%H:%M:%SZ")
    assert abs((dt.datetime.now(dt.UTC) - stamp.replace(tzinfo=dt.UTC)).total_seconds()) < 60


async def test_an_emulator_error_is_error_general_and_logged(
    c3: Emulator, raw: RawClient, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """docs/c3bridge.md: an error of the emulator itself answers ErrorGeneral and is logged,
    at once (a key, a confirmation) or later (a motion, a benchmark), with the echoed command
    byte where the message has one; the connection stays. The bugs are planted here: a key,
    the confirmation, a motion and the server's tick that raise."""
    assert c3.c3 is not None

    def broken_motion(kind: int, position: str) -> object:
        async def rest() -> int:
            raise RuntimeError("planted motion bug")

        return rest

    def broken_tick() -> int:
        raise RuntimeError("planted tick bug")

    def broken(*args: object) -> int:
        raise RuntimeError("planted bug")

    # a limiter of its own: the module's allows 5 such lines per 10 s per process, and tests run
    # before this one in the same worker (or mutmut's run) may have used them up
    monkeypatch.setattr(c3_server, "_limited", RateLimitedLog(c3_server.log))
    monkeypatch.setattr(c3.c3.control, "motion", broken_motion)
    monkeypatch.setattr(c3.c3, "tick_ms", broken_tick)
    monkeypatch.setattr(c3.c3.control, "key", broken)
    monkeypatch.setattr(c3.c3.control, "confirm_all", broken)
    with caplog.at_level(logging.WARNING, logger="kukavarproxy_emu"):
        key = frame(4, 12, H("02") + struct.pack(">iiBB", 1, 0, 0, 0))
        assert await raw.request(key) == answer(4, 12, H("02"), ErrorCode.GENERAL)  # its byte
        assert await raw.request(frame(5, 63, H("00"))) == answer(5, 63, b"", ErrorCode.GENERAL)
        motion = frame(1, 11, H("02") + W("{A1 1.0}"))
        assert await raw.request(motion) == answer(1, 11, H("02"), ErrorCode.GENERAL)  # echoed
        bench = frame(2, 17, H("00 01 00000001") + W("RULE_A"))
        assert await raw.request(bench) == answer(2, 17, b"", ErrorCode.GENERAL)  # nothing
        # a motion that waits for a select still loading, and then fails: the select's load
        # is held until the motion waits behind it (a 5000-line module alone loaded faster
        # than the test could see it loading on a quiet machine)
        gate = asyncio.Event()
        real_sliced, real_after = c3_control.run_sliced, c3.c3.control.after_select

        async def held(*args: Any, **kwargs: Any) -> Any:
            await gate.wait()
            return await real_sliced(*args, **kwargs)

        async def behind_the_select(action: Any) -> int:
            gate.set()
            return await real_after(action)

        monkeypatch.setattr(c3_control, "run_sliced", held)
        monkeypatch.setattr(c3.c3.control, "after_select", behind_the_select)
        c3.c3.vfs.write("KRC:\\R1\\Program\\SLOW.SRC", big_module("SLOW", 5000), overwrite=True)
        async with await RawClient.connect(c3.host, c3.port) as other:
            await other.send(ProgramSelect("/R1/SLOW").frame(1))
            await wait_until(lambda: c3.c3 is not None and c3.c3.control.selecting, what="select")
            motion = frame(6, 11, H("02") + W("{A1 1.0}"))
            assert await raw.request(motion, timeout=30) == answer(
                6, 11, H("02"), ErrorCode.GENERAL
            )
            assert await other.read_frame(timeout=30) == answer(1, 10, H("05"), 1)
        assert await raw.request(frame(3, 4, W("RULE_A"))) == answer(3, 4, W("1"), 1)  # still open
    failed = [r for r in caplog.records if "failed; answering ErrorGeneral" in r.getMessage()]
    assert [r.getMessage()[:15] for r in failed] == [
        f"C3 message #{n} " for n in (12, 63, 11, 17, 11)
    ]
    assert all(r.exc_info is not None and "planted" in str(r.exc_info[1]) for r in failed)


async def test_a_cut_short_ascii_message_is_a_failure_not_an_emulator_error(
    raw: RawClient, caplog: pytest.LogCaptureFixture
) -> None:
    """#0/#1 cut short are answered with the failure tail by their own rule, not through the
    emulator-error path (which would log a traceback a client could provoke at will)."""
    with caplog.at_level(logging.WARNING, logger="kukavarproxy_emu"):
        for n, payload in enumerate((H("0009") + b"$OV", A("$OV_PRO") + H("0005") + b"1")):
            tag = 1 + n
            reply = await raw.request(frame(tag, n, payload))
            assert reply == frame(tag, n, H("0000 0000 00")), payload
    assert not [r for r in caplog.records if "ErrorGeneral" in r.getMessage()]


def test_why_a_message_closes_the_connection_is_said(c3: Emulator) -> None:
    """The three messages C3 Bridge disconnects on raise a ProtocolError that names the rule
    (the connection logs it as its reason for closing): no type byte, a type without a
    handler, an answer no message can carry (ErrorBuildMessage)."""
    assert c3.c3 is not None
    with pytest.raises(ProtocolError) as empty:
        C3Session.decode(H("0001 0000"))
    assert str(empty.value) == "message with length 0 (no type byte): C3 Bridge disconnects"
    session = c3.c3.session()
    with pytest.raises(ProtocolError) as unhandled:
        session.answer(Request(1, 2, "", b""), 1)
    assert str(unhandled.value) == "message type 2 has no handler: C3 Bridge disconnects"
    c3.store.declare("BIG", "INT", (40_000,), "0")  # an array no answer can carry
    with pytest.raises(ProtocolError) as too_long:
        session.answer(Request(1, 4, "", W("BIG[]")), 1)
    text = str(too_long.value)
    assert text.startswith("the answer to message #4 does not fit one message (")
    assert text.endswith("): C3 Bridge disconnects (ErrorBuildMessage)")
