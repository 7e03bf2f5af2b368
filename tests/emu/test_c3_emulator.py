"""``--proxy c3bridge`` on the wire: the spec's sample exchanges, disconnects, refused paths,
bounds. Raw frames over real TCP (RawClient), so the bytes are exactly what a C3 client sees."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import pytest
from hexwire import H, W

from kukavarproxy_emu import Emulator
from kukavarproxy_emu.c3 import HANDLED
from kukavarproxy_emu.c3.vfs import Limits, VirtualFS
from kukavarproxy_emu.testing import EmulatorFactory, RawClient
from pyopenshowvar.c3.constants import ErrorCode
from pyopenshowvar.c3.files import (
    FileDelete,
    FileNameList,
    FileReadBegin,
    FileWriteBegin,
    FileWriteData,
    FileWriteEnd,
)
from pyopenshowvar.c3.messages import Motion, ProgramControl, ReadMultiple, ReadVariable
from pyopenshowvar.c3.replies import FeatureMap, Multiple, Outcome
from pyopenshowvar.protocol import decode_reply, encode_read


@pytest.fixture
async def c3(emulator_factory: EmulatorFactory) -> Emulator:
    return await emulator_factory(proxy="c3bridge", plant="ideal")


async def outcome(raw: RawClient, frame: bytes) -> Outcome:
    return Outcome.of(decode_reply(await raw.request(frame)))


async def test_spec_sample_exchanges(c3: Emulator) -> None:
    async with await RawClient.connect(c3.host, c3.port) as raw:
        # §3.5.7 sample request, answered as in the sample (with this emulator's port)
        reply = await raw.request(H("0400 0024 06 02 0004" + W("PING") + "000B" + W("@PROXY_PORT")))
        port = str(c3.port)
        body = "06 02 01 0004" + W("PONG") + f"01 {len(port):04x}" + W(port) + "0001 01"
        assert reply == H(f"0400 {len(H(body)):04x}") + H(body)
        # §3.6.1 sample: reset of the submit interpreter
        assert await raw.request(H("028C 0004 0A 01 0000")) == H("028C 0005 0A 01 0001 01")
        # §3.10.1 confirm all; §3.8.2 features: the 32-byte map of what is handled
        assert await raw.request(H("0007 0001 3F")) == H("0007 0004 3F 0001 01")
        features = await outcome(raw, H("0000 0001 0E"))
        assert FeatureMap.parse(features.reader()).types == HANDLED
        # §3.5.1: the KVP read, and C3's failure tail for an unknown name (empty, 00 00 00)
        assert decode_reply(await raw.request(encode_read(1, "@PROXY_TYPE"))).text == (
            "C3 BRIDGE INTERFACE"
        )
        assert await raw.request(encode_read(2, "NOPE")) == H("0002 0006 00 0000 0000 00")


async def test_unhandled_types_close_the_connection_after_what_is_owed(c3: Emulator) -> None:
    for msg_type in (2, 3, 8, 15, 99, 255):
        async with await RawClient.connect(c3.host, c3.port) as raw:
            # a good request in the same write is answered first (the server reads in order)
            await raw.send(encode_read(5, "$OV_PRO") + H(f"0009 0003 {msg_type:02x} 0000"))
            assert decode_reply(await raw.read_frame()).text == "100"
            assert await raw.is_closed_by_peer(), msg_type


async def test_malformed_payload_answers_error_protocol(c3: Emulator) -> None:
    async with await RawClient.connect(c3.host, c3.port) as raw:
        out = await outcome(raw, H("0001 0004 04 0009 41"))  # #4: 9 chars announced, 1 byte
        assert (out.code, out.ok, out.payload) == (ErrorCode.PROTOCOL, False, H("0000"))
        out = await outcome(raw, H("0002 0003 06 05 00"))  # #6: 5 names announced, none sent
        assert (out.code, out.payload) == (ErrorCode.PROTOCOL, H("00"))
        out = await outcome(raw, H("0003 0001 0A"))  # #10 without a command
        assert (out.code, out.payload) == (ErrorCode.PROTOCOL, H("00"))
        out = await outcome(raw, ProgramControl(7, 1).frame(4))  # a command it lacks
        assert out.code == ErrorCode.NOT_IMPLEMENTED


@pytest.mark.parametrize(
    "path",
    [
        "KRC:\\R1\\..\\..\\etc\\passwd",
        "KRC:/R1/Program/../../x.src",
        "C:\\Windows\\Temp\\C3_FILE2.TXT",  # the path the c3sharp sample writes to
        "/etc/passwd",
        "\\\\server\\share\\x.src",
        "KRC:\\R1\\.\\x.src",
        "KRC:\\R1\\a<b.src",
        "KRC:\\" + "A\\" * 200 + "x.src",
    ],
)
async def test_paths_outside_krc_are_refused(c3: Emulator, path: str, tmp_path: Path) -> None:
    before = set(c3.c3.vfs.files) if c3.c3 else set()
    host_file = tmp_path / "pwned.src"  # a host path the emulator must never write
    async with await RawClient.connect(c3.host, c3.port) as raw:
        assert (await outcome(raw, FileWriteBegin(3).frame(1))).ok
        assert (await outcome(raw, FileWriteData(0, b"abc").frame(2))).ok
        out = await outcome(raw, FileWriteEnd(path, 64).frame(3))
        assert (out.code, out.ok) == (ErrorCode.ARGUMENT, False)
        for message in (FileReadBegin(path), FileDelete(path, True), FileNameList(path)):
            assert (await outcome(raw, message.frame(4))).code == ErrorCode.ARGUMENT
        out = await outcome(raw, FileWriteEnd(str(host_file), 64).frame(5))
        assert out.code == ErrorCode.ARGUMENT
    assert c3.c3 is not None and set(c3.c3.vfs.files) == before
    assert not await asyncio.to_thread(host_file.exists)


async def test_upload_and_storage_bounds(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(proxy="c3bridge", robot=False)
    assert emu.c3 is not None
    emu.c3.vfs.limits = Limits(file_size=1000, files=len(emu.c3.vfs.files) + 2)
    async with await RawClient.connect(emu.host, emu.port) as raw:
        out = await outcome(raw, FileWriteBegin(1001).frame(1))  # one byte over: nothing kept
        assert (out.code, out.payload) == (ErrorCode.MEMORY, H("01 00000000"))
        out = await outcome(raw, FileWriteBegin(1000).frame(1))  # the limit itself: taken
        assert (out.code, out.payload) == (ErrorCode.SUCCESS, H("01 000003E8"))
        for i in range(3):
            await outcome(raw, FileWriteBegin(10).frame(2))
            out = await outcome(raw, FileWriteEnd(f"KRC:\\R1\\Program\\F{i}.SRC", 64).frame(3))
            assert out.code == (ErrorCode.SUCCESS if i < 2 else ErrorCode.MEMORY), i
        # a data chunk beyond the announced size is cut, not stored past the buffer
        await outcome(raw, FileWriteBegin(4).frame(4))
        out = await outcome(raw, FileWriteData(2, b"xyz123").frame(5))
        assert out.payload == H("02 00000002 00000002")


def test_vfs_total_and_dir_rules() -> None:
    vfs = VirtualFS(Limits(total_bytes=100), seed=False)
    vfs.mkdir("KRC:\\R1")
    vfs.write("krc:/r1/a.src", b"x" * 60, overwrite=False)
    with pytest.raises(Exception, match="storage"):
        vfs.write("KRC:\\R1\\B.SRC", b"x" * 50, overwrite=False)
    with pytest.raises(Exception, match="exists"):
        vfs.write("KRC:\\R1\\A.SRC", b"", overwrite=False)  # names compare case-insensitively
    with pytest.raises(Exception, match="does not exist"):
        vfs.write("KRC:\\NOPE\\X.SRC", b"", overwrite=True)
    vfs.write("KRC:\\R1\\A.SRC", b"y", overwrite=True)
    assert vfs.total == 1 and vfs.read("KRC:\\r1\\a.SRC").path == "KRC:\\r1\\a.src"


async def test_read_multiple_is_one_interpolation_cycle(emulator_factory: EmulatorFactory) -> None:
    """While the robot moves, one #6 reply holds values of one cycle: the same variable read
    twice is identical, and $POS_ACT is the forward kinematics of $AXIS_ACT."""
    from pyopenshowvar.kinematics import KR6R900SIXX, forward
    from pyopenshowvar.krl import parse_value

    emu = await emulator_factory(plant="ideal", proxy="c3bridge", speed=1)
    names = ("$AXIS_ACT", "$POS_ACT", "$OV_PRO", "$AXIS_ACT")
    async with await RawClient.connect(emu.host, emu.port) as raw:
        # move the robot with a manual motion (#11) and sample while it runs
        out = await outcome(raw, Motion(1, "{A1 40, A2 -60, A5 30}").frame(2))
        assert out.ok
        moving = 0
        last = ""
        for i in range(30):
            out = await outcome(raw, ReadMultiple(names).frame(10 + i))
            (c1, axis), (c2, pos), _, (c4, axis2) = Multiple.parse(out.reader()).items
            assert c1 == c2 == c4 == 1 and axis == axis2
            q = parse_value(axis)
            p = parse_value(pos)
            fk = forward(KR6R900SIXX, [q[f"A{k}"] for k in range(1, 7)])  # type: ignore[index]
            assert (
                [round(float(p[k]), 2) for k in "XYZ"]
                == pytest.approx(  # type: ignore[index]
                    [float(v) for v in fk[:3]], abs=0.02
                )
            )
            moving += axis != last
            last = axis
            await asyncio.sleep(0.015)
        assert moving > 5, "the robot did not move while sampling"


#: How much earlier than its service time a reply may leave (s): the latency queue's compute
#: lead plus the timer's overshoot compensation, each at most 0.5 ms.
EARLY = 0.001


async def test_read_multiple_costs_one_service_time_per_variable(
    emulator_factory: EmulatorFactory,
) -> None:
    emu = await emulator_factory(proxy="c3bridge", robot=False, latency="fixed:0.01")
    async with await RawClient.connect(emu.host, emu.port) as raw:
        t0 = time.perf_counter()
        await raw.request(ReadMultiple(("$OV_PRO",) * 6).frame(1))
        # six CrossComm reads, as the server does (the emulator aims a reply early by its own
        # computing time and timer overshoot, under a millisecond: docs/emulator.md)
        assert time.perf_counter() - t0 >= 0.06 - EARLY
        t0 = time.perf_counter()
        await raw.request(ReadVariable("$OV_PRO").frame(2))
        assert 0.01 - EARLY <= time.perf_counter() - t0


async def test_long_answers_and_wide_values(c3: Emulator) -> None:
    async with await RawClient.connect(c3.host, c3.port) as raw:
        out = await outcome(raw, ReadMultiple(("$OUT[]",) * 3).frame(1))  # 3 x 24 KiB UTF-16
        assert (out.code, out.payload) == (ErrorCode.LONG_ANSWER, H("00"))
        out = await outcome(raw, ReadVariable("$OUT[]").frame(2))  # one fits
        assert out.ok and len(out.payload) > 20000


async def test_work_per_message_is_bounded(emulator_factory: EmulatorFactory) -> None:
    """A benchmark asking for 4·10⁹ iterations does at most BENCHMARK_OPS store operations
    (the reply says how many), a module over MAX_MODULE is not parsed, and all upload buffers
    together stay under the budget."""
    from kukavarproxy_emu.c3.control import MAX_MODULE
    from kukavarproxy_emu.c3.server import BENCHMARK_OPS
    from pyopenshowvar.c3.messages import Benchmark, ProgramSelect
    from pyopenshowvar.c3.replies import BenchmarkReply

    emu = await emulator_factory(proxy="c3bridge", plant="ideal")
    assert emu.c3 is not None
    emu.c3.files.limit = 100  # all connections' upload buffers together
    async with (
        await RawClient.connect(emu.host, emu.port) as raw,
        await RawClient.connect(emu.host, emu.port) as other,
    ):
        t0 = time.perf_counter()
        out = await outcome(raw, Benchmark(("$OV_PRO", "$MODE_OP"), 0xFFFFFFFE).frame(1))
        reply = BenchmarkReply.parse(out.reader())
        assert out.ok and reply.iterations * reply.count <= BENCHMARK_OPS
        assert time.perf_counter() - t0 < 5.0
        assert (await outcome(raw, FileWriteBegin(80).frame(2))).ok
        out = await outcome(other, FileWriteBegin(30).frame(3))  # 80 + 30 > 100
        assert out.code == ErrorCode.MEMORY
        assert (await outcome(other, FileWriteBegin(20).frame(3))).ok  # 80 + 20: the budget
        big = b"DEF BIG()\n" + b"; padding\n" * (MAX_MODULE // 10) + b"END\n"
        emu.c3.vfs.write("KRC:\\R1\\Program\\BIG.SRC", big, overwrite=True)
        out = await outcome(raw, ProgramSelect("/R1/BIG").frame(4))
        assert out.code == ErrorCode.MEMORY


async def test_an_array_no_message_can_carry_is_refused_unformatted(
    emulator_factory: EmulatorFactory,
) -> None:
    """Issue 16's bound holds for C3 reads too: a whole array of more than WHOLE_ARRAY_LIMIT
    elements is never formatted. #6 answers ErrorLongAnswer and the KVP read a failure; #4,
    whose answer the server cannot build, closes the connection (its ErrorBuildMessage)."""
    from kukavarproxy_emu.store import WHOLE_ARRAY_LIMIT

    emu = await emulator_factory(proxy="c3bridge", robot=False)
    emu.store.declare("BIG", "INT", (2 * WHOLE_ARRAY_LIMIT,), "0")
    async with await RawClient.connect(emu.host, emu.port) as raw:
        out = await outcome(raw, ReadMultiple(("$OV_PRO", "BIG[]")).frame(1))
        assert (out.code, out.ok, out.payload) == (ErrorCode.LONG_ANSWER, False, H("00"))
        assert await raw.request(encode_read(2, "BIG[]")) == H("0002 0006 00 0000 0000 00")
        await raw.send(ReadVariable("BIG[]").frame(3))
        assert await raw.is_closed_by_peer()
    assert emu.store._vars["BIG"].elem_text is None  # not one element was formatted
    async with await RawClient.connect(emu.host, emu.port) as raw:  # the emulator serves on
        assert (await outcome(raw, ReadVariable("BIG[1]").frame(4))).ok
