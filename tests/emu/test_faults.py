"""Fault injection, seen from a raw client: drop, delay, split, close mid-frame, corrupt, wrong id."""

from __future__ import annotations

import asyncio
import time

import pytest

from kukavarproxy_emu import Emulator, Fault
from kukavarproxy_emu.faults import WRONG_ID_MASK

# the fixtures (the root conftest may also load them as a plugin)
from kukavarproxy_emu.testing import *  # noqa: F403
from kukavarproxy_emu.testing import EmulatorFactory, RawClient
from pyopenshowvar.errors import ProtocolError
from pyopenshowvar.protocol import decode_reply, encode_read

H = bytes.fromhex
OV_PRO_1 = H("0001 0009 00 0003 313030 000101")


def read(i: int) -> bytes:
    return encode_read(i, "$OV_PRO")


async def connect(emu: Emulator) -> RawClient:
    return await RawClient.connect(emu.host, emu.port)


@pytest.mark.parametrize(
    ("spec", "fault"),
    [
        ("drop:3", Fault("drop", nth=3)),
        ("drop@3", Fault("drop", nth=3)),
        ("delay:0.5@2", Fault("delay", nth=2, seconds=0.5)),
        ("split:2@1,pause=0.01", Fault("split", nth=1, size=2, pause=0.01)),
        ("close@4,conn=2", Fault("close", nth=4, connection=2)),
        ("close-mid-frame:1", Fault("close", nth=1)),
        ("corrupt-length", Fault("corrupt-length")),
        ("wrong-id,count=0", Fault("wrong-id", count=None)),
        ("drop,count=3", Fault("drop", count=3)),
    ],
)
def test_parse(spec: str, fault: Fault) -> None:
    assert Fault.parse(spec) == fault


@pytest.mark.parametrize(
    "spec", ["explode", "delay", "delay:x", "drop:0", "drop:1@2", "split:0", "drop,foo=1", "drop,x"]
)
def test_parse_errors(spec: str) -> None:
    with pytest.raises(ValueError, match="bad fault spec"):
        Fault.parse(spec)


async def test_drop_nth(emulator: Emulator) -> None:
    emulator.faults.add(Fault("drop", nth=2))
    async with await connect(emulator) as c:
        assert await c.request(read(1)) == OV_PRO_1
        await c.send(read(2))
        with pytest.raises(TimeoutError):
            await c.read_frame(timeout=0.2)
        assert (await c.request(read(3)))[:2] == H("0003")
        assert (await c.request(read(4)))[:2] == H("0004")  # fired once only
    assert emulator.faults.fired == 1 and not emulator.faults


async def test_drop_count_and_connection_filter(emulator: Emulator) -> None:
    emulator.faults.add(Fault("drop", connection=2, count=2))
    first, second = await connect(emulator), await connect(emulator)
    assert await first.request(read(1)) == OV_PRO_1  # connection 1 is not affected
    await second.send(read(1) + read(2) + read(3))
    assert (await second.read_frame())[:2] == H("0003")
    await first.close()
    await second.close()


async def test_delay(emulator: Emulator) -> None:
    emulator.faults.add(Fault("delay", nth=1, seconds=0.3))
    async with await connect(emulator) as c:
        start = time.perf_counter()
        await c.send(read(1) + read(2))
        assert await c.read_frame() == OV_PRO_1
        assert time.perf_counter() - start >= 0.28
        assert (await c.read_frame())[:2] == H("0002")  # order is kept


async def test_split_into_tiny_segments(emulator: Emulator) -> None:
    emulator.faults.add(Fault("split", nth=1, size=1, pause=0.01))
    async with await connect(emulator) as c:
        await c.send(read(1))
        chunks: list[bytes] = []
        while sum(map(len, chunks)) < len(OV_PRO_1):
            chunks.append(await asyncio.wait_for(c.reader.read(64), 2.0))
    assert b"".join(chunks) == OV_PRO_1
    assert len(chunks) >= 5


async def test_close_mid_frame(emulator: Emulator) -> None:
    emulator.faults.add(Fault("close", nth=2))
    async with await connect(emulator) as c:
        assert await c.request(read(1)) == OV_PRO_1
        await c.send(read(2))
        rest = await c.read_until_eof()
    full = H("0002") + OV_PRO_1[2:]
    assert 0 < len(rest) < len(full) and rest == full[: len(rest)]


async def test_corrupt_length(emulator: Emulator) -> None:
    emulator.faults.add(Fault("corrupt-length", nth=1))
    async with await connect(emulator) as c:
        await c.send(read(1))
        data = await asyncio.wait_for(c.reader.readexactly(len(OV_PRO_1)), 2.0)
    assert data == H("0001 0008") + OV_PRO_1[4:]
    with pytest.raises(ProtocolError):
        decode_reply(data[: 4 + 8])


async def test_wrong_id(emulator: Emulator) -> None:
    emulator.faults.add(Fault("wrong-id", nth=1))
    async with await connect(emulator) as c:
        reply = await c.request(read(1))
    assert int.from_bytes(reply[:2], "big") == 1 ^ WRONG_ID_MASK
    assert reply[2:] == OV_PRO_1[2:]


async def test_faults_from_config(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(faults=(Fault.parse("wrong-id,count=0"),))
    async with await connect(emu) as c:
        for i in range(3):
            assert (await c.request(read(i)))[:2] == (i ^ WRONG_ID_MASK).to_bytes(2, "big")


async def test_fault_removed_restores_fast_path(emulator: Emulator) -> None:
    fault = emulator.faults.add(Fault("drop", count=None))
    async with await connect(emulator) as c:
        await c.send(read(1))
        with pytest.raises(TimeoutError):
            await c.read_frame(timeout=0.1)
        emulator.faults.remove(fault)
        assert not emulator.slow
        assert (await c.request(read(2)))[:2] == H("0002")
