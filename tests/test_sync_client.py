"""The synchronous client: the asyncio client's API on a blocking socket (issue 14, item 1)."""

from __future__ import annotations

import asyncio
import inspect
import threading
import time
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

import pyopenshowvar
from kukavarproxy_emu.emulator_thread import EmulatorThread
from kukavarproxy_emu.testing import TEST_CONFIG
from pyopenshowvar import (
    E6Axis,
    KvpConnectionError,
    KvpStalledError,
    KvpTimeoutError,
    UnknownVariableError,
    WriteRefusedError,
    sync,
)
from pyopenshowvar.protocol import Request
from pyopenshowvar.testing import FakeProxy, answer

HOME = "{E6AXIS: A1 0.0, A2 -90.0000, A3 90.0000, A4 0.0, A5 0.0, A6 0.0, E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"


#: exact KRC4 texts are compared: the ideal plant (measured = set-point)
IDEAL = replace(TEST_CONFIG, plant="ideal")


@pytest.fixture(scope="module")
def emu() -> Any:
    with EmulatorThread(IDEAL) as emu:
        yield emu


@pytest.fixture
def kvp(emu: Any) -> Any:
    with sync.Client("127.0.0.1", emu.port, timeout=2.0) as client:
        yield client


def _public(cls: type) -> dict[str, inspect.Signature]:
    return {
        name: inspect.signature(member)
        for name, member in inspect.getmembers(cls, callable)
        if not name.startswith("_")
    }


def test_same_methods_and_signatures_as_the_asyncio_client() -> None:
    ours, theirs = _public(sync.Client), _public(pyopenshowvar.Client)
    assert ours.keys() == theirs.keys()
    for name, sig in theirs.items():
        assert ours[name].parameters == sig.parameters, name
    assert inspect.signature(sync.Client) == inspect.signature(pyopenshowvar.Client)
    for name in ("read", "write", "read_many", "read_joint_angles", "write_joint_path"):
        assert not inspect.iscoroutinefunction(getattr(sync.Client, name))
        assert inspect.iscoroutinefunction(getattr(pyopenshowvar.Client, name))
        assert getattr(sync.Client, name).__doc__ == getattr(
            pyopenshowvar.Client, name
        ).__doc__ or (
            name in ("read", "write", "read_many")  # one-paragraph docstrings of their own
        )


def test_reads_writes_and_helpers_against_the_emulator(kvp: sync.Client) -> None:
    assert kvp.read("$OV_PRO") == "100"
    assert kvp.read_value("$OV_PRO") == 100
    axis = kvp.read_value("$AXIS_ACT")
    assert isinstance(axis, E6Axis) and axis.a2 == -90.0
    np.testing.assert_allclose(kvp.read_joint_angles(), [0, -90, 90, 0, 0, 0])
    assert kvp.read_joint_torques().shape == (6,)
    assert kvp.read_pose().to_numpy()[0] == pytest.approx(525.0)
    assert kvp.write("MYINT", 7) == "7" and kvp.read_value("MYINT") == 7
    res = kvp.read_many(["$OV_PRO", "NOPE", "$AXIS_ACT"], typed=True)
    assert res["$OV_PRO"].value == 100 and res["$AXIS_ACT"].text == HOME
    assert isinstance(res["NOPE"].error, UnknownVariableError)
    kvp.write_many([("MYINT", 3), ("MYREAL", 1.5)])
    assert kvp.read_many(["MYINT", "MYREAL"], typed=True)["MYREAL"].value == 1.5
    with pytest.raises(UnknownVariableError):
        kvp.read("NOPE")
    with pytest.raises(WriteRefusedError) as refused:
        kvp.write("$AXIS_ACT", "{A1 1}")
    assert refused.value.value == "{A1 1}"
    assert kvp.write_joint_path([[1, -90, 90, 0, 0, 0], [2, -80, 95, 0, 30, 0]]) == 2
    assert kvp.read_value("PATH_COUNT") == 2 and kvp.read_value("PATH_START") is True
    kvp.set_outputs({2: True, 3: False})
    kvp.set_output(1, True)
    assert kvp.read_value("OUTPUT_VARS[1]") is True
    assert kvp.ping() > 0 and kvp.proxy_type() is not None
    snap = kvp.stats.snapshot()
    assert snap.count >= 20 and snap.p50 > 0
    assert kvp.connection is not None and kvp.connection.session.ids == "echoed"


def test_many_threads_share_one_client(kvp: sync.Client) -> None:
    errors: list[BaseException] = []

    def worker() -> None:
        try:
            for _ in range(50):
                assert kvp.read("$OV_PRO") == "100"
        except BaseException as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=worker) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []


async def test_works_inside_a_running_event_loop(emu: Any) -> None:
    # a Jupyter cell runs inside an event loop: a blocking client must not need one
    with sync.Client("127.0.0.1", emu.port) as kvp:
        assert kvp.read("$OV_PRO") == "100"
    await asyncio.sleep(0)


def test_legacy_proxy_is_proven_and_matched_in_order() -> None:
    config = replace(IDEAL, quirks=frozenset({"legacy-ids"}))
    with EmulatorThread(config) as emu, sync.Client("127.0.0.1", emu.port) as kvp:
        names = [f"OUTPUT_VARS[{i}]" for i in range(1, 17)] * 3
        res = kvp.read_many(names)
        assert all(r.text == "FALSE" for r in res.values())
        assert kvp.connection is not None and kvp.connection.session.ids == "legacy"


def test_timeout_then_the_late_reply_is_discarded() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "SLOW":
            await asyncio.sleep(0.3)
        w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=0.1) as kvp:
        t0 = time.monotonic()
        with pytest.raises(KvpTimeoutError, match="SLOW"):
            kvp.read("SLOW")
        assert 0.09 < time.monotonic() - t0 < 0.5
        assert kvp.read("FAST", timeout=2.0) == "v:FAST"


def test_unsolicited_reply_and_lost_connection_fail_loudly() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        w.write(answer(req))
        if req.name == "TWICE":
            w.write(answer(req))
        if req.name == "BYE":
            w.close()

    with FakeProxy(handler) as port:
        with sync.Client(port=port) as kvp:
            assert kvp.read("TWICE") == "v:TWICE"
            with pytest.raises(KvpConnectionError, match="answers no request"):
                kvp.read("NEXT")
            assert not kvp.connected
        with sync.Client(port=port, auto_reconnect=True) as kvp:
            assert kvp.read("BYE") == "v:BYE"
            with pytest.raises(KvpConnectionError, match="closed the connection"):
                kvp.read("NEXT")
            assert kvp.read("AGAIN") == "v:AGAIN" and kvp.reconnects == 1


def test_stalled_server_is_reported_and_replaced() -> None:
    conns: list[asyncio.StreamWriter] = []  # the writers themselves: ids get reused

    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        if w not in conns:
            conns.append(w)
        first = conns[0] is w
        w.write(b"".join(answer(r) for r in reqs if r.name == "$OV_PRO" or not first))

    with FakeProxy(on_read=on_read) as port:
        with sync.Client(port=port, timeout=0.05, max_in_flight=4) as kvp:
            for i in range(4):  # each times out and keeps its place until answered
                with pytest.raises(KvpTimeoutError):
                    kvp.read(f"S{i}")
            assert kvp.connected
            with pytest.raises(KvpStalledError, match="stopped answering"):
                kvp.read("NEXT")
            assert not kvp.connected
        conns.clear()
        kw: dict[str, Any] = {"timeout": 0.05, "max_in_flight": 4, "auto_reconnect": True}
        with sync.Client(port=port, **kw) as kvp:
            for i in range(4):
                with pytest.raises(KvpTimeoutError):
                    kvp.read(f"S{i}")
            assert kvp.read("AFTER", timeout=1.0) == "v:AFTER" and kvp.reconnects == 1


def test_against_the_wire_faithful_kvp9_emulator() -> None:
    # --wire kvp9 parses every 2048-byte read alone: a burst cut at a read boundary would lose
    # or garble requests, and a request over 2048 bytes would be cut
    config = replace(IDEAL, wire="kvp9", robot=False)
    with EmulatorThread(config) as emu, sync.Client("127.0.0.1", emu.port, timeout=5.0) as kvp:
        names = [f"MYE6ARRAY[{i}]" for i in range(1, 201)]
        kvp.write_many([(n, f"{{A1 {i}.5}}") for i, n in enumerate(names, 1)])
        res = kvp.read_many(names, typed=True)
        assert [res[n].unwrap().a1 for n in names] == [i + 0.5 for i in range(1, 201)]
        with pytest.raises(pyopenshowvar.ProtocolError, match="2048"):
            kvp.write("MYSTRING[]", '"' + "x" * 2100 + '"')
        assert kvp.read("$OV_PRO") == "100"
