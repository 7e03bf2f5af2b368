"""The emulator's KVP 9.0 behaviour on the wire: golden replies over real TCP on 127.0.0.1."""

from __future__ import annotations

import asyncio
import socket
import time
from typing import ClassVar

import pytest

from kukavarproxy_emu import Emulator, EmulatorThread
from kukavarproxy_emu.store import VariableStore

# the fixtures (the root conftest may also load them as a plugin)
from kukavarproxy_emu.testing import *  # noqa: F403
from kukavarproxy_emu.testing import EmulatorFactory, RawClient
from pyopenshowvar.protocol import (
    Mode,
    Request,
    encode_read,
    encode_read_array,
    encode_request,
    encode_write,
    encode_write_array,
)

H = bytes.fromhex


async def connect(emu: Emulator) -> RawClient:
    return await RawClient.connect(emu.host, emu.port)


# --- golden replies (reference §2.2) -------------------------------------------------------


async def test_read_ov_pro_golden(emulator: Emulator) -> None:
    async with await connect(emulator) as c:
        assert await c.request(encode_read(1, "$OV_PRO")) == H("0001 0009 00 0003 313030 000101")


async def test_write_ov_pro_golden_and_read_back(emulator: Emulator) -> None:
    async with await connect(emulator) as c:
        reply = await c.request(encode_write(2, "$OV_PRO", "50"))
        assert reply == H("0002 0008 01 0002 3530 000101")
        assert (await c.request(encode_read(3, "$ov_pro")))[7:-3] == b"50"


async def test_refused_write_echoes_value_with_failure(emulator: Emulator) -> None:
    value = b"{A1 1.0}"
    async with await connect(emulator) as c:
        reply = await c.request(encode_write(7, "$AXIS_ACT", value))
    assert reply == H("0007") + (len(value) + 6).to_bytes(2, "big") + H("01") + (
        len(value).to_bytes(2, "big") + value + H("000100")
    )


async def test_unknown_read_is_empty_success(emulator: Emulator) -> None:
    async with await connect(emulator) as c:
        assert await c.request(encode_read(3, "NO_SUCH_VAR")) == H("0003 0006 00 0000 000101")


async def test_strict_mode_failure_tails(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(strict=True)
    async with await connect(emu) as c:
        assert await c.request(encode_read(3, "NO_SUCH_VAR")) == H("0003 0006 00 0000 000000")
        assert await c.request(encode_write(4, "$AXIS_ACT", "1")) == H("0004 0006 01 0000 000000")
        assert await c.request(encode_read(5, "$OV_PRO")) == H("0005 0009 00 0003 313030 000101")


async def test_ping_pong_exact_and_case_sensitive(emulator: Emulator) -> None:
    async with await connect(emulator) as c:
        assert await c.request(encode_read(4, "PING")) == H("0004 000A 00 0004 504F4E47 000101")
        assert await c.request(encode_read(5, "ping")) == H("0005 0006 00 0000 000101")


async def test_no_ping_quirk(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(quirks=frozenset({"no-ping"}))
    async with await connect(emu) as c:
        assert await c.request(encode_read(4, "PING")) == H("0004 0006 00 0000 000101")


@pytest.mark.parametrize("frame", [H("0005 0001 07"), H("0005 0006 04 0003 414243")])
async def test_unknown_mode_gets_four_byte_reply(emulator: Emulator, frame: bytes) -> None:
    async with await connect(emulator) as c:
        assert await c.request(frame) == H("0005 0000")
        # the connection stays usable
        assert (await c.request(encode_read(6, "PING")))[7:-3] == b"PONG"


async def test_proxy_type(emulator: Emulator) -> None:
    async with await connect(emulator) as c:
        await c.send(encode_read(9, "@PROXY_TYPE"))
        reply = await c.read_reply()
    assert reply.ok and reply.msg_id == 9 and "EMULATOR" in reply.text.upper()


# --- modes 2 and 3 (reference §4.1) ----------------------------------------------------------


class PlcStore(VariableStore):
    """A store with a few texts that only mode 2 finds interesting."""

    TEXTS: ClassVar[dict[str, str]] = {
        "PLC": "1 -2 300 65537",
        "PLC_REAL": "2.5 3.5",
        "PLC_BAD": "1 two",
    }

    def read(self, name: str) -> str:
        return self.TEXTS.get(name.upper()) or super().read(name)


async def test_read_array_mode2(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(store=PlcStore())
    async with await connect(emu) as c:
        assert await c.request(encode_read_array(1, "PLC")) == H(
            "0001 000E 02 0008 0001 FFFE 012C 0001 000101"
        )
        # VB CLng rounds half to even
        assert (await c.request(encode_read_array(2, "PLC_REAL")))[7:-3] == H("0002 0004")
        # fewer than two tokens: empty value, success; unknown: the same
        assert await c.request(encode_read_array(3, "$OV_PRO")) == H("0003 0006 02 0000 000101")
        assert await c.request(encode_read_array(4, "NOPE")) == H("0004 0006 02 0000 000101")
        # a non-numeric token: failure (KVP sends nothing at all here)
        assert await c.request(encode_read_array(5, "PLC_BAD")) == H("0005 0006 02 0000 000100")
        assert await c.request(encode_read_array(6, "$AXIS_ACT")) == H("0006 0006 02 0000 000100")


async def test_write_array_mode3(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(dat_text="DECL INT PLCW[3]\n")
    async with await connect(emu) as c:
        reply = await c.request(encode_write_array(1, "PLCW[]", [7, 8, 65535]))
        assert reply == H("0001 0006 03 0000 000101")
        for i, text in enumerate([b"7", b"8", b"65535"], start=1):
            assert (await c.request(encode_read(10 + i, f"PLCW[{i}]")))[7:-3] == text
        # without brackets too; only the last element's status counts
        assert (await c.request(encode_write_array(2, "PLCW", [1, 2])))[-1] == 1
        assert (await c.request(encode_write_array(3, "PLCW", [1, 2, 3, 4])))[-1] == 0
        assert (await c.request(encode_read(4, "PLCW[1]")))[7:-3] == b"1"
        # odd payload length: failure
        odd = encode_request(Request(5, Mode.WRITE_ARRAY, "PLCW", b"\x00\x01\x02"))
        assert await c.request(odd) == H("0005 0006 03 0000 000100")


# --- connections -------------------------------------------------------------------------


async def test_eleventh_client_is_closed_without_bytes(emulator: Emulator) -> None:
    clients = [await connect(emulator) for _ in range(10)]
    try:
        for i, c in enumerate(clients):  # make sure all ten are registered
            assert (await c.request(encode_read(i, "PING")))[7:-3] == b"PONG"
        extra = await connect(emulator)
        assert await extra.is_closed_by_peer(timeout=2.0)
        await extra.close()
        assert emulator.stats.rejected == 1 and emulator.stats.clients == 10
        await clients[0].close()
        await asyncio.sleep(0.05)
        again = await connect(emulator)  # a slot is free again
        assert (await again.request(encode_read(1, "PING")))[7:-3] == b"PONG"
        await again.close()
    finally:
        for c in clients:
            await c.close()


async def test_idle_client_dropped_active_client_kept(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(idle_timeout=0.3)
    idle, busy = await connect(emu), await connect(emu)
    start = time.monotonic()
    for _ in range(6):
        await asyncio.sleep(0.1)
        assert (await busy.request(encode_read(1, "PING")))[7:-3] == b"PONG"
    assert await idle.is_closed_by_peer(timeout=0.1)
    assert 0.3 <= time.monotonic() - start < 1.0
    assert emu.stats.idle_drops == 1
    await idle.close()
    await busy.close()


async def test_request_split_across_segments_is_reassembled(emulator: Emulator) -> None:
    frame = encode_write(11, "$OV_PRO", "42")
    async with await connect(emulator) as c:
        for i in range(len(frame)):
            await c.send(frame[i : i + 1])
            await asyncio.sleep(0.002)
        assert await c.read_frame() == H("000B 0008 01 0002 3432 000101")


async def test_many_requests_in_one_segment_answered_in_order(emulator: Emulator) -> None:
    frames = [encode_read(i, "$OV_PRO" if i % 2 else "PING") for i in range(1, 201)]
    async with await connect(emulator) as c:
        await c.send(b"".join(frames))
        replies = [await c.read_reply() for _ in frames]
    assert [r.msg_id for r in replies] == list(range(1, 201))
    assert {r.text for r in replies} == {"100", "PONG"}


async def test_legacy_ids_quirk(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(quirks=frozenset({"legacy-ids"}))
    async with await connect(emu) as c:
        await c.send(encode_read(5, "PING") + encode_read(6, "$OV_PRO") + encode_read(7, "X"))
        replies = [await c.read_reply() for _ in range(3)]
        assert [r.msg_id for r in replies] == [5, 5, 5]
        assert [r.text for r in replies] == ["PONG", "100", ""]
        # one request per read: ids are right
        assert (await c.request(encode_read(8, "PING")))[:2] == H("0008")


async def test_garbage_closes_only_that_connection(emulator: Emulator) -> None:
    good, bad = await connect(emulator), await connect(emulator)
    # a good request, then a request whose blocks do not add up to L
    await bad.send(encode_read(1, "PING") + H("0002 0004 00 0009 41"))
    assert (await bad.read_frame())[7:-3] == b"PONG"
    assert await bad.is_closed_by_peer()
    await bad.close()
    assert (await good.request(encode_read(2, "$OV_PRO")))[7:-3] == b"100"
    await good.close()
    assert emulator.stats.protocol_errors == 1


async def test_length_below_minimum_and_oversize_close(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(max_frame=64)
    for junk in (H("0001 0000"), H("0001 FFFF 00")):
        async with await connect(emu) as c:
            await c.send(junk)
            assert await c.is_closed_by_peer()
    assert emu.stats.protocol_errors == 2


async def test_stats_and_connection_info(emulator: Emulator) -> None:
    async with await connect(emulator) as c:
        await c.request(encode_read(1, "PING"))
        await c.send(encode_read(2, "PING")[:5])
        await asyncio.sleep(0.05)
        (info,) = emulator.connections()
        assert info.index == 1 and info.received == 1 and info.buffered == 5
    assert emulator.stats.requests == 1 and emulator.stats.connections == 1


async def test_udp_discovery(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(discovery=True, udp_port=0, udp_reply_port=0)
    assert emu.udp_port
    loop = asyncio.get_running_loop()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.setblocking(False)
        sock.sendto(b"WHEREAREYOU?", ("127.0.0.1", emu.udp_port))
        sock.sendto(b"HELLO?", ("127.0.0.1", emu.udp_port))  # ignored
        data = await asyncio.wait_for(loop.sock_recv(sock, 1024), 2.0)
    model = emu.store.read("$MODEL_NAME[]").strip('"')
    assert data == f"KUKA|{model}|{emu.store.read('$KR_SERIALNO')}".encode()


async def test_discovery_off_for_ephemeral_port(emulator: Emulator) -> None:
    assert emulator.udp_port is None


def test_emulator_thread(emulator_thread: EmulatorThread) -> None:
    with socket.create_connection((emulator_thread.host, emulator_thread.port), 2) as s:
        s.sendall(encode_read(1, "$OV_PRO"))
        assert s.recv(64) == H("0001 0009 00 0003 313030 000101")
    assert emulator_thread.call(lambda: emulator_thread.stats.requests) == 1
