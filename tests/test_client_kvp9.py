"""Our asyncio client against ``--wire kvp9``: the proxy that parses every 2048-byte read alone.

A request cut by a read boundary would be lost or mis-parsed there, so everything below would
show missing or wrong answers if the client let a burst cross one.
"""

from __future__ import annotations

import socket
from typing import Any

import numpy as np
import pytest

from kukavarproxy_emu import Emulator
from kukavarproxy_emu.kvp9_connection import Kvp9ConnectionInfo
from kukavarproxy_emu.testing import EmulatorFactory
from pyopenshowvar import Client, E6Axis, KvpTimeoutError
from pyopenshowvar.errors import ProtocolError


async def kvp9(factory: EmulatorFactory, **kw: Any) -> Emulator:
    return await factory(wire="kvp9", robot=False, **kw)


def server_info(emu: Emulator) -> Kvp9ConnectionInfo:
    (info,) = emu.connections()
    assert isinstance(info, Kvp9ConnectionInfo)
    return info


@pytest.mark.parametrize("id_policy", ["auto", "strict", "fifo"])
async def test_pipelined_bursts_over_2048_bytes(
    emulator_factory: EmulatorFactory, id_policy: Any
) -> None:
    """300 partial-aggregate writes (~11 KB) and 303 reads (~6 KB), each call pipelined."""
    emu = await kvp9(emulator_factory)
    names = [f"MYE6ARRAY[{i}]" for i in range(1, 301)]
    async with Client("127.0.0.1", emu.port, timeout=5.0, id_policy=id_policy) as kvp:
        await kvp.write_many([(n, f"{{A1 {i}.5, A6 -{i}.0}}") for i, n in enumerate(names, 1)])
        results = await kvp.read_many([*names, "NO_SUCH_VAR", "PING", "$OV_PRO"], typed=True)
        info = server_info(emu)
    for i, name in enumerate(names, 1):
        value = results[name].unwrap()
        assert isinstance(value, E6Axis) and (value.a1, value.a6) == (i + 0.5, -i)
    assert not results["NO_SUCH_VAR"].ok and results["PING"].text == "PONG"
    assert results["$OV_PRO"].value == 100
    # + the two reads of the message-id probe sent when an "auto" connection opens
    assert emu.stats.requests == 603 + (2 if id_policy == "auto" else 0)
    assert info.largest_read <= 2048


async def test_partial_aggregates_torques_and_array_modes(
    emulator_factory: EmulatorFactory,
) -> None:
    emu = await kvp9(
        emulator_factory, dat_text="DECL INT WA[4]\nWA[1]=0\nWA[2]=0\nWA[3]=0\nWA[4]=0\n"
    )
    async with Client("127.0.0.1", emu.port) as kvp:
        await kvp.write("MYAXIS", "{A1 10.0, A2 -80.0}")  # untyped, partial
        axis = await kvp.read_value("MYAXIS")
        assert isinstance(axis, E6Axis) and (axis.a1, axis.a2, axis.a3) == (10.0, -80.0, 90.0)
        tau = await kvp.read_joint_torques()
        np.testing.assert_allclose(tau[:3], [0.0, -24.78, -25.5])
        # KVP's ExtractVariableValue trims the KRC's trailing space
        assert await kvp.read("$TORQUE_AXIS_ACT[]") == (
            "0.0 -24.7800 -25.5000 -0.800000 -0.600000 0.0 0.0 0.0 0.0 0.0 0.0 0.0"
        )
        words = await kvp.read_array_words("$TORQUE_AXIS_ACT[]")
        assert words == [0, 0xFFE7, 0xFFE6, 0xFFFF, 0xFFFF] + [0] * 7
        await kvp.write_array_words("WA[]", [1, 2, 3])
        assert await kvp.read("WA[]") == "1 2 3 0"
        assert await kvp.ping() > 0


async def test_legacy_ids_matched_in_order(emulator_factory: EmulatorFactory) -> None:
    emu = await kvp9(emulator_factory, quirks=frozenset({"legacy-ids"}))
    async with Client("127.0.0.1", emu.port, timeout=5.0) as kvp:
        await kvp.write_many([(f"MYE6ARRAY[{i}]", f"{{A1 {i}.0}}") for i in range(1, 201)])
        results = await kvp.read_many([f"MYE6ARRAY[{i}]" for i in range(1, 201)], typed=True)
        assert [r.unwrap().a1 for r in results.values()] == [float(i) for i in range(1, 201)]
        assert kvp.connection is not None and kvp.connection.mislabeled_replies > 0


async def test_unanswered_mode2_times_out_and_connection_recovers(
    emulator_factory: EmulatorFactory,
) -> None:
    """KVP raises a VB error on mode 2 of a struct and sends nothing: a timeout, not a hang."""
    emu = await kvp9(emulator_factory)
    async with Client("127.0.0.1", emu.port, timeout=0.3) as kvp:
        with pytest.raises(KvpTimeoutError):
            await kvp.read_array_words("MYAXIS")
        assert await kvp.read("$OV_PRO") == "100"


async def test_request_larger_than_one_read_is_refused(emulator_factory: EmulatorFactory) -> None:
    emu = await kvp9(emulator_factory)
    async with Client("127.0.0.1", emu.port) as kvp:
        with pytest.raises(ProtocolError, match="2048"):
            await kvp.write("MYSTRING[]", '"' + "x" * 2100 + '"')
        with pytest.raises(ProtocolError):
            await kvp.read_many(["$OV_PRO", "X" * 3000])
        assert await kvp.read("$OV_PRO") == "100"
    # nothing of the refused calls reached the proxy: the one read + the id probe's two
    assert emu.stats.requests == 1 + 2


async def test_unanswered_bytes_stay_within_one_tcp_segment(
    emulator_factory: EmulatorFactory,
) -> None:
    """On a path with a small MSS a 2048-byte burst spans several segments, and a read can end
    between two of them. The client keeps its unanswered bytes within one segment, so every
    read the proxy makes holds whole requests only."""
    emu = await kvp9(emulator_factory)
    assert emu._server is not None
    emu._server.sockets[0].setsockopt(socket.IPPROTO_TCP, socket.TCP_MAXSEG, 536)
    async with Client("127.0.0.1", emu.port, timeout=5.0) as kvp:
        results = await kvp.read_many(["$OV_PRO"] * 500)
        assert all(r.text == "100" for r in results.values())
        info = server_info(emu)
    assert info.reads >= 500 * 14 // 536 and info.largest_read <= 536
