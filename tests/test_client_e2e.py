"""The client end to end against the real emulator over real TCP (127.0.0.1, ephemeral port)."""

from __future__ import annotations

import asyncio
from typing import Any

import numpy as np
import pytest

from pyopenshowvar import (
    Client,
    E6Axis,
    E6Pos,
    KrlEnum,
    Pos,
    Struct,
    UnknownVariableError,
    WriteRefusedError,
    parse_value,
)

HOME_AXIS = (
    "{E6AXIS: A1 0.0, A2 -90.0000, A3 90.0000, A4 0.0, A5 0.0, A6 0.0, "
    "E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)


@pytest.fixture
def emulator(ideal_emulator: Any) -> Any:
    """These tests compare exact KRC4 texts: the ideal plant (measured = set-point)."""
    return ideal_emulator


@pytest.fixture
async def kvp(emulator: Any) -> Any:
    async with Client("127.0.0.1", emulator.port, timeout=2.0) as client:
        yield client


async def test_raw_reads_match_a_krc4(kvp: Client) -> None:
    assert await kvp.read("$OV_PRO") == "100"
    assert await kvp.read("$AXIS_ACT") == HOME_AXIS
    assert await kvp.read("$axis_act") == HOME_AXIS  # KRL names are case-insensitive
    pos = await kvp.read("$POS_ACT")
    assert pos.startswith(
        "{E6POS: X 525.000, Y 0.0, Z 890.000, A 0.0, B 90.0000, C 0.0, S 2, T 2, E1"
    )


async def test_typed_reads(kvp: Client) -> None:
    axis = await kvp.read_value("$AXIS_ACT")
    assert isinstance(axis, E6Axis) and axis.a2 == -90.0 and axis.e6 == 0.0
    assert await kvp.read_value("$OV_PRO") == 100
    assert await kvp.read_value("$OV_PRO", "REAL") == 100.0
    assert isinstance(await kvp.read_value("$MODE_OP"), KrlEnum)
    assert await kvp.read_value("$DRIVES_ON") in (True, False)
    np.testing.assert_allclose(await kvp.read_joint_angles(), [0, -90, 90, 0, 0, 0])
    pose = await kvp.read_pose()
    assert isinstance(pose, E6Pos) and (pose.s, pose.t) == (2, 2)
    np.testing.assert_allclose(pose.to_numpy(), [525, 0, 890, 0, 90, 0], atol=1e-3)


async def test_joint_torques_in_one_request(kvp: Client) -> None:
    before = kvp.stats.count
    tau = await kvp.read_joint_torques()
    assert kvp.stats.count - before == 1
    assert tau.shape == (6,)
    np.testing.assert_allclose(tau, [0, -24.78, -25.5, -0.8, -0.6, 0], atol=0.05)


async def test_writes_typed_and_raw(kvp: Client, emulator: Any) -> None:
    assert await kvp.write("$OV_PRO", 50) == "50"
    assert await kvp.read("$OV_PRO") == "50"
    target = E6Axis(
        a1=10.0,
        a2=-80.0,
        a3=95.5,
        a4=0.0,
        a5=30.0,
        a6=-45.0,
        e1=0.0,
        e2=0.0,
        e3=0.0,
        e4=0.0,
        e5=0.0,
        e6=0.0,
    )
    await kvp.write("MYAXIS", target)
    assert await kvp.read_value("MYAXIS") == target
    # raw text, partial aggregate: only A1 changes, as in KRL
    await kvp.write("MYAXIS", "{A1 -12.5}")
    got = await kvp.read_value("MYAXIS")
    assert isinstance(got, Struct) and got.a1 == -12.5 and got.a3 == 95.5
    await kvp.write("MYPOS", Pos(x=1.5, y=2.0, z=3.0, a=0.0, b=0.0, c=0.0, s=6, t=19))
    assert (await kvp.read_value("MYPOS")) == Pos(
        x=1.5, y=2.0, z=3.0, a=0.0, b=0.0, c=0.0, s=6, t=19
    )


async def test_refused_write_raises_and_changes_nothing(kvp: Client) -> None:
    with pytest.raises(WriteRefusedError) as info:
        await kvp.write("$AXIS_ACT", "{A1 10.0}")
    assert "$AXIS_ACT" in str(info.value)
    assert await kvp.read("$AXIS_ACT") == HOME_AXIS
    with pytest.raises(WriteRefusedError):
        await kvp.write("$OV_PRO", "TRUE")  # type mismatch
    assert await kvp.read("$OV_PRO") == "100"


async def test_unknown_variable_is_distinct(kvp: Client) -> None:
    with pytest.raises(UnknownVariableError):
        await kvp.read("NO_SUCH_VARIABLE")
    reply = await kvp.read_reply("NO_SUCH_VARIABLE")
    assert reply.ok and reply.value == b""


async def test_long_names_and_values(kvp: Client, emulator: Any) -> None:
    with pytest.raises(UnknownVariableError):
        await kvp.read("X" * 300)  # name length high byte used
    emulator.store.declare("LONGSTR", "CHAR", dims=(2000,))
    text = '"' + "k" * 1500 + '"'
    assert await kvp.write("LONGSTR[]", text) == text
    assert await kvp.read("LONGSTR[]") == text


async def test_read_many_pipelined(kvp: Client) -> None:
    names = [f"MYE6ARRAY[{i}]" for i in range(1, 51)] + ["$OV_PRO", "NOPE", "$AXIS_ACT"] * 10
    results = await kvp.read_many(names, typed=True)
    assert list(results) == list(dict.fromkeys(names))
    assert results["$OV_PRO"].value == 100
    assert isinstance(results["NOPE"].error, UnknownVariableError)
    assert results["$AXIS_ACT"].text == HOME_AXIS


async def test_many_tasks_share_one_client(kvp: Client) -> None:
    async def worker(i: int) -> list[str]:
        return [await kvp.read("$OV_PRO") for _ in range(40)]

    outs = await asyncio.gather(*(worker(i) for i in range(8)))
    assert all(v == "100" for out in outs for v in out)
    assert kvp.stats.count >= 320


async def test_id_wrap_against_the_emulator(kvp: Client) -> None:
    assert kvp.connection is not None
    kvp.connection.session.next_id = 65530
    results = await asyncio.gather(*(kvp.read("$OV_PRO") for _ in range(20)))
    assert results == ["100"] * 20
    assert kvp.connection.session.next_id == 14


async def test_joint_path_handshake(kvp: Client, emulator: Any) -> None:
    points = [[float(i), -90.0 + i, 90.0, 0.0, float(-i), 0.5 * i] for i in range(1, 31)]
    assert await kvp.write_joint_path(points) == 30
    assert await kvp.read_value("PATH_COUNT") == 30
    assert await kvp.read_value("PATH_START") is True
    for i in (1, 17, 30):
        axis = parse_value(emulator.store.read(f"MYE6ARRAY[{i}]"))
        assert isinstance(axis, Struct)
        np.testing.assert_allclose(
            [axis[k] for k in ("A1", "A2", "A3", "A4", "A5", "A6")], points[i - 1], atol=1e-4
        )
    with pytest.raises(ValueError):
        await kvp.write_joint_path([[0.0] * 6] * 513)


async def test_cartesian_path_and_busy_guard(kvp: Client) -> None:
    pts = [[500.0 + i, 10.0 * i, 600.0, 0.0, 90.0, 0.0] for i in range(5)]
    assert await kvp.write_cartesian_path(pts, start=False) == 5
    assert await kvp.read_value("PATH_START") is False
    first = await kvp.read_value("MYPOSARRAY[1]")
    assert isinstance(first, Struct) and first.x == 500.0 and first.b == 90.0
    await kvp.write("PATH_BUSY", True)
    with pytest.raises(RuntimeError, match="PATH_BUSY"):
        await kvp.write_cartesian_path(pts)


async def test_outputs_through_global_array(kvp: Client) -> None:
    await kvp.set_output(3, True)
    assert await kvp.read("OUTPUT_VARS[3]") == "TRUE"
    await kvp.set_outputs({1: True, 2: True, 3: False})
    assert [await kvp.read(f"OUTPUT_VARS[{i}]") for i in (1, 2, 3)] == ["TRUE", "TRUE", "FALSE"]
    # $OUT follows within one interpolation cycle: the emulator's SPS copies OUTPUT_VARS (Alg. 4.11)
    for _ in range(100):
        if await kvp.read_output(1):
            break
        await asyncio.sleep(0.005)
    assert await kvp.read_output(1) is True
    with pytest.raises(WriteRefusedError):
        await kvp.write("$OUT[1]", True)


async def test_ping_and_proxy_identity(kvp: Client) -> None:
    assert 0 < await kvp.ping() < 1.0
    assert await kvp.proxy_type()


async def test_stats_histogram(kvp: Client) -> None:
    for _ in range(50):
        await kvp.read("$OV_PRO")
    snap = kvp.stats.snapshot()
    assert snap.count >= 50 and 0 < snap.p50 <= snap.p99 <= snap.maximum
    hist = kvp.stats.histogram(10)
    assert sum(c for _, _, c in hist) == snap.window


async def test_plc_array_modes(kvp: Client, emulator: Any) -> None:
    emulator.store.declare("MYWORDS", "INT", dims=(4,))
    await kvp.write_array_words("MYWORDS[]", [1, 2, 300, 65535])
    # mode 3 writes NAME[1..k] as INT text, each word taken unsigned (VB wordToLong)
    assert [await kvp.read(f"MYWORDS[{i}]") for i in (1, 3, 4)] == ["1", "300", "65535"]
    words = await kvp.read_array_words("MYWORDS[]")
    assert words[:3] == [1, 2, 300] and len(words) == 4


async def test_wait_path_done(kvp: Client, emulator: Any) -> None:
    async def finish_later() -> None:
        await asyncio.sleep(0.1)
        emulator.store.write("PATH_DONE", "TRUE")

    task = asyncio.create_task(finish_later())
    waited = await kvp.wait_path_done(poll=0.01, timeout=5.0)
    await task
    assert 0.05 < waited < 2.0
    emulator.store.write("PATH_DONE", "FALSE")
    with pytest.raises(TimeoutError):
        await kvp.wait_path_done(poll=0.01, timeout=0.1)


def test_works_on_uvloop(emulator_thread: Any) -> None:
    uvloop = pytest.importorskip("uvloop")

    async def main() -> str:
        async with Client("127.0.0.1", emulator_thread.port) as kvp:
            return await kvp.read("$OV_PRO")

    assert uvloop.run(main()) == "100"


def test_run_uses_uvloop_when_installed(emulator_thread: Any) -> None:
    pytest.importorskip("uvloop")
    from pyopenshowvar import run

    async def main() -> tuple[str, str]:
        async with Client("127.0.0.1", emulator_thread.port) as kvp:
            return type(asyncio.get_running_loop()).__module__, await kvp.read("$OV_PRO")

    module, value = run(main())
    assert module.startswith("uvloop") and value == "100"
