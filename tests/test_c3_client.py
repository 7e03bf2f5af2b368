"""The client's C3 Bridge methods against the emulator over real TCP: detection and refusals
before sending, upload → select → start → the robot moves → stop/resume/reset, files."""

from __future__ import annotations

import asyncio

import pytest

from kukavarproxy_emu import Emulator
from kukavarproxy_emu.testing import EmulatorFactory
from pyopenshowvar import Client, UnknownVariableError, WriteRefusedError
from pyopenshowvar.c3 import (
    C3CommandError,
    ErrorCode,
    MotionNotAllowedError,
    RequestTooLargeError,
    UnsupportedError,
)
from pyopenshowvar.c3.api import C3Methods, SyncC3Methods
from pyopenshowvar.c3.server import ServerInfo

SRC = b"""DEF PICK()
  PTP {A1 30, A2 -70, A3 80, A4 0, A5 20, A6 0}
  PTP {A1 -30}
  DONE = DONE + 1
END
"""
DAT = b"""DEFDAT PICK PUBLIC
  DECL GLOBAL INT DONE = 0
ENDDAT
"""
BROKEN = b"DEF BROKEN()\n  PTP {A1 10\nEND\n"


@pytest.fixture
async def c3(emulator_factory: EmulatorFactory) -> Emulator:
    return await emulator_factory(proxy="c3bridge", plant="ideal", speed=8)


async def axes(kvp: Client) -> list[float]:
    value = (await kvp.read_multiple(["$AXIS_ACT"], typed=True))["$AXIS_ACT"].unwrap()
    return [float(value[f"A{i}"]) for i in range(1, 7)]


async def wait_for(predicate, timeout: float = 5.0) -> None:  # type: ignore[no-untyped-def]
    deadline = asyncio.get_running_loop().time() + timeout
    while not await predicate():
        assert asyncio.get_running_loop().time() < deadline, "timed out"
        await asyncio.sleep(0.02)


async def test_a_kvp_server_gets_a_clear_error_before_anything_is_sent(
    emulator: Emulator,
) -> None:
    async with Client(emulator.host, emulator.port) as kvp:
        info = await kvp.server_info()
        assert info.kind == "kvp" and info.describe() == "KUKAVARPROXY"
        served = emulator.stats.requests
        calls = [
            kvp.read_multiple(["$OV_PRO"]),
            kvp.program_select("/R1/FOLLOW"),
            kvp.file_list(),
            kvp.proxy_info(),
            kvp.write_utf16("$OV_PRO", 5),
        ]
        for call in calls:
            with pytest.raises(UnsupportedError, match=r"KUKAVARPROXY.*nothing was sent"):
                await call
        assert emulator.stats.requests == served  # not one frame went out
        assert (await kvp.program_state()).state == "P_ACTIVE"  # plain reads work on KVP


async def test_old_or_partial_c3_servers_are_refused_by_message() -> None:
    old = ServerInfo("c3bridge", (1, 1), "FREEWARE", frozenset({0, 1, 4, 5, 6, 7, 10}))
    with pytest.raises(UnsupportedError, match=r"from C3 Bridge 1.2 on"):
        old.require(6, "read_multiple", "h:1")
    with pytest.raises(UnsupportedError, match=r"does not offer.*#29"):
        old.require(29, "file_write", "h:1")


async def test_detection_and_variables(c3: Emulator) -> None:
    async with Client(c3.host, c3.port) as kvp:
        info = await kvp.server_info()
        assert info.describe() == "C3 Bridge 1.4 (OPEN SOURCE)" and 30 in info.features
        assert (await kvp.proxy_info()).computer_name == "KRC4-EMULATOR"
        assert await kvp.proxy_features() == info.features
        results = await kvp.read_multiple(["$OV_PRO", "NOPE", "PING", "$MODE_OP"], typed=True)
        assert results["$OV_PRO"].unwrap() == 100 and str(results["$MODE_OP"].unwrap()) == "#AUT"
        assert isinstance(results["NOPE"].error, UnknownVariableError)
        assert results["PING"].text == "PONG"
        assert await kvp.write_utf16("$OV_PRO", 40) == "40"
        assert await kvp.read_utf16("$OV_PRO") == "40"
        with pytest.raises(UnknownVariableError):
            await kvp.read_utf16("NOPE")
        with pytest.raises(UnknownVariableError):  # #0 as #4 and #6: one outcome for one fact
            await kvp.read("NOPE")
        with pytest.raises(UnknownVariableError):
            await kvp.read_value("NOPE")
        assert isinstance((await kvp.read_many(["NOPE"]))["NOPE"].error, UnknownVariableError)
        assert (await kvp.read("$TORQUE_AXIS_ACT[]")).endswith(" ")  # C3 does not trim
        back = await kvp.write_multiple([("$OV_PRO", 55), ("$OV_JOG", "75")])
        assert (back["$OV_PRO"].text, back["$OV_JOG"].text) == ("55", "75")
        with pytest.raises(WriteRefusedError, match=r"1 of 2 writes refused.*AXIS_ACT") as err:
            await kvp.write_multiple([("$OV_PRO", 60), ("$AXIS_ACT", "{A1 0}")])
        assert err.value.results["$OV_PRO"].text == "60"  # type: ignore[attr-defined]
        assert await kvp.read("$OV_PRO") == "60"  # the others were applied
        with pytest.raises(C3CommandError, match="read fewer or shorter variables") as long:
            await kvp.read_multiple(["$OUT[]"] * 3)  # 3 x 24 KiB of UTF-16: not one message
        assert long.value.code == ErrorCode.LONG_ANSWER


async def test_requests_over_the_limits_are_refused_before_sending(c3: Emulator) -> None:
    async with Client(c3.host, c3.port) as kvp:
        await kvp.server_info()
        served = c3.stats.requests
        with pytest.raises(RequestTooLargeError, match="at most 255"):
            await kvp.read_multiple(["$OV_PRO"] * 256)
        with pytest.raises(RequestTooLargeError, match="payload"):
            await kvp.read_multiple(["X" * 300] * 120)
        with pytest.raises(MotionNotAllowedError, match="allow_motion=True"):
            await kvp.program_start()
        with pytest.raises(MotionNotAllowedError):
            await kvp.motion("{A1 10}", "PTP_REL")
        with pytest.raises(ValueError, match="module name"):
            await kvp.program_upload(SRC, "9bad-name.src")
        assert c3.stats.requests == served
        many = await kvp.read_multiple(["$OV_PRO"] * 255)  # the most one message holds
        assert len(many) == 1 and many["$OV_PRO"].text == "100"


async def test_a_request_that_cannot_be_sent_costs_not_even_the_identifying_reads(
    c3: Emulator,
) -> None:
    served = c3.stats.requests
    async with Client(c3.host, c3.port) as kvp:
        with pytest.raises(RequestTooLargeError, match="at most 255"):
            await kvp.write_multiple([("$OV_PRO", 1)] * 256)
        with pytest.raises(RequestTooLargeError, match="exceeds 65535"):
            await kvp.read_utf16("X" * 70_000)
        with pytest.raises(RequestTooLargeError):
            await kvp.file_write("KRC:\\R1\\" + "X" * 70_000, b"data")
        with pytest.raises(RequestTooLargeError):
            await kvp.benchmark(["$OV_PRO"] * 256, 10)
        assert kvp._c3_info is None  # the server was never asked what it is
    assert c3.stats.requests == served


async def test_upload_select_start_moves_stop_resume_reset(c3: Emulator) -> None:
    async with Client(c3.host, c3.port) as kvp:
        path = await kvp.program_upload(SRC, "pick.src", DAT)
        assert path == "KRC:\\R1\\Program\\pick.src"
        await kvp.program_select(path)
        state = await kvp.program_state()
        assert (state.state, state.name) == ("P_RESET", "PICK")
        start = await axes(kvp)
        await kvp.program_start(allow_motion=True)

        async def moved() -> bool:
            return (await axes(kvp))[0] > start[0] + 2.0

        await wait_for(moved)
        await kvp.program_stop()
        assert (await kvp.program_state()).state == "P_STOP"

        async def standing() -> bool:  # braking on the path, then standing still
            first = await axes(kvp)
            await asyncio.sleep(0.05)
            return await axes(kvp) == first

        await wait_for(standing)
        held = await axes(kvp)
        await asyncio.sleep(0.1)
        assert await axes(kvp) == held
        assert (await kvp.program_state()).state == "P_STOP"
        await kvp.program_start(allow_motion=True)  # resume: the same motion goes on

        async def ended() -> bool:
            return (await kvp.program_state()).state == "P_END"

        await wait_for(ended)
        assert (await axes(kvp))[0] == pytest.approx(-30.0, abs=1e-3)
        assert await kvp.read("DONE") == "1"
        with pytest.raises(C3CommandError, match="program start"):
            await kvp.program_start(allow_motion=True)  # ended: reset first, as on a KRC
        await kvp.program_reset()
        assert (await kvp.program_state()).state == "P_RESET"
        # the selected module is locked, as on a KRC; cancel frees it
        with pytest.raises(C3CommandError) as locked:
            await kvp.file_write(path, SRC)
        assert locked.value.code == ErrorCode.ACCESS
        await kvp.program_cancel()
        assert (await kvp.program_state()).state == "P_FREE"
        await kvp.file_write(path, SRC)


async def test_select_errors_are_explained(c3: Emulator) -> None:
    async with Client(c3.host, c3.port) as kvp:
        await kvp.file_write("KRC:\\R1\\Program\\BROKEN.SRC", BROKEN)
        with pytest.raises(C3CommandError, match="ErrorGeneral"):
            await kvp.program_select("/R1/BROKEN")
        state = await kvp.program_state()
        assert state.state == "P_FREE" and state.message and "BROKEN.SRC:2:13:" in state.message
        with pytest.raises(C3CommandError):
            await kvp.program_select("/R1/NOT_THERE")
        await kvp.program_run("/R1/FOLLOW", allow_motion=True)  # a shipped program: runs
        state = await kvp.program_state()
        assert state.running and state.message == ""  # the failed select's reason is gone


async def test_a_refusal_message_is_cleared_by_a_later_successful_start(c3: Emulator) -> None:
    async with Client(c3.host, c3.port) as kvp:
        path = await kvp.program_upload(b"DEF QUICK()\nEND\n", "quick.src")
        with pytest.raises(C3CommandError):
            await kvp.program_start(allow_motion=True)  # nothing selected yet
        assert "no program selected" in ((await kvp.program_state()).message or "")
        await kvp.program_select(path)
        assert (await kvp.program_state()).message == ""
        await kvp.program_start(allow_motion=True)
        await wait_for(lambda: _state_is(kvp, "P_END"))
        with pytest.raises(C3CommandError):
            await kvp.program_start(allow_motion=True)  # ended: reset first
        assert "reset it first" in ((await kvp.program_state()).message or "")
        await kvp.program_reset()
        await kvp.program_start(allow_motion=True)
        assert (await kvp.program_state()).message == ""


async def _state_is(kvp: Client, state: str) -> bool:
    return (await kvp.program_state()).state == state


async def test_manual_motion_and_files(c3: Emulator) -> None:
    async with Client(c3.host, c3.port) as kvp:
        before = await axes(kvp)
        await kvp.motion("{A6 10}", "PTP_REL", allow_motion=True)

        async def arrived() -> bool:
            return abs((await axes(kvp))[5] - (before[5] + 10.0)) < 1e-3

        await wait_for(arrived)
        z0 = float((await kvp.read_value("$POS_ACT"))["Z"])  # type: ignore[index]
        await kvp.motion("{Z -50}", "LIN_REL", allow_motion=True)  # planned in slices

        async def lowered() -> bool:
            return abs(float((await kvp.read_value("$POS_ACT"))["Z"]) - (z0 - 50)) < 1e-2  # type: ignore[index]

        await wait_for(lowered)
        data = bytes(range(256)) * 300  # 76.8 KB: three chunks each way
        await kvp.file_write("KRC:\\R1\\blob.bin", data)
        assert await kvp.file_read("krc:/r1/BLOB.bin") == data
        props = await kvp.file_properties("KRC:\\R1\\blob.bin")
        assert (props.size, props.name) == (len(data), "KRC:\\R1\\blob.bin")
        with pytest.raises(RequestTooLargeError, match="max_size"):
            await kvp.file_read("KRC:\\R1\\blob.bin", max_size=1000)
        await kvp.file_copy("KRC:\\R1\\blob.bin", "KRC:\\R1\\copy.bin")
        await kvp.file_move("KRC:\\R1\\copy.bin", "KRC:\\R1\\moved.bin")
        names = (await kvp.file_list("KRC:\\R1")).names
        assert "KRC:\\R1\\moved.bin" in names and "KRC:\\R1\\copy.bin" not in names
        await kvp.file_delete("KRC:\\R1\\moved.bin")
        with pytest.raises(C3CommandError) as refused:
            await kvp.file_read("C:\\Windows\\win.ini")
        assert refused.value.code == ErrorCode.ARGUMENT
        assert await kvp.file_full_name("/R1/FOLLOW") == "KRC:\\R1\\Program\\follow.src"
        assert await kvp.file_krc_name("KRC:\\R1\\Program\\follow.src") == "/R1/FOLLOW.SRC"


def test_the_async_and_the_blocking_mixin_offer_the_same_methods() -> None:
    def public(cls: type) -> set[str]:
        return {n for n in vars(cls) if not n.startswith("_")}

    assert public(C3Methods) == public(SyncC3Methods)
    assert {"read_multiple", "program_start", "file_write", "program_state"} <= public(C3Methods)


async def test_both_clients_keep_a_c3_payload_that_looks_like_a_kvp_reply() -> None:
    """``05 | 00 00 | 00 01 01`` is #5's echo of an empty value — and also exactly the shape
    of a KVP reply with an empty value. The fast paths of both clients must hand C3 types the
    raw payload (``00 00``), not KVP's value (``b""``)."""
    from pyopenshowvar.c3.messages import WriteVariable
    from pyopenshowvar.c3.replies import Outcome, Value
    from pyopenshowvar.protocol import RequestDecoder
    from pyopenshowvar.sync import Client as SyncClient

    async def serve(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        decoder = RequestDecoder()
        while data := await reader.read(4096):
            for frame in decoder.feed(data):
                writer.write(frame[:2] + bytes.fromhex("0006 05 0000 0001 01"))

    server = await asyncio.start_server(serve, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    frame = WriteVariable("MYSTRING[]", "").frame(0)
    async with server, Client("127.0.0.1", port, id_policy="strict", keepalive=None) as kvp:
        reply = await kvp._request("MYSTRING[]", frame, 1.0)
        assert Value.parse(Outcome.of(reply).reader()) == Value("")

    def blocking() -> bytes:
        with SyncClient("127.0.0.1", port, id_policy="strict", keepalive=None) as sync:
            return sync._request("MYSTRING[]", frame, 1.0).value

    async with await asyncio.start_server(serve, "127.0.0.1", port):
        assert await asyncio.to_thread(blocking) == b"\x00\x00"


def test_the_blocking_client_runs_the_same_c3_operations() -> None:
    from dataclasses import replace

    from kukavarproxy_emu import EmulatorThread
    from kukavarproxy_emu.testing import TEST_CONFIG
    from pyopenshowvar.sync import Client as SyncClient

    config = replace(TEST_CONFIG, proxy="c3bridge", plant="ideal", speed=8.0)
    with EmulatorThread(config) as emu, SyncClient(emu.host, emu.port) as kvp:
        assert kvp.server_info().describe() == "C3 Bridge 1.4 (OPEN SOURCE)"
        assert kvp.read_multiple(["$OV_PRO", "PING"])["PING"].text == "PONG"
        with pytest.raises(UnknownVariableError):
            kvp.read("NOPE")  # the fast path hands a failure over to the same check
        path = kvp.program_upload(SRC, "pick.src", DAT)
        kvp.program_select(path)
        with pytest.raises(MotionNotAllowedError):
            kvp.program_start()
        kvp.program_start(allow_motion=True)
        assert kvp.program_state().state in ("P_ACTIVE", "P_END")
        assert kvp.file_read(path) == SRC
