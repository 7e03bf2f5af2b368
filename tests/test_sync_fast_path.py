"""The synchronous client's serial read fast path (issue 14): the cases it must hand over.

``BlockingConnection.read_text`` accepts a read when one whole reply with its id arrives in one
recv; everything else goes to the general path, which must still match, check and time out
exactly as before. Each test drives one such case through a deliberately odd server.
"""

from __future__ import annotations

import asyncio

import pytest

from pyopenshowvar import KvpConnectionError, KvpTimeoutError, sync
from pyopenshowvar.protocol import Mode, Reply, Request, encode_reply
from pyopenshowvar.testing import FakeProxy, answer


def test_reply_split_over_two_recvs_is_reassembled() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        reply = answer(req, b"{E6AXIS: A1 1.5, A2 -90.0}")
        w.write(reply[:9])  # the head and two bytes of the value
        await w.drain()
        await asyncio.sleep(0.02)  # the client's first recv returns the cut reply
        w.write(reply[9:])

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=2.0) as kvp:
        for _ in range(3):  # the first learns the shape, the next take the prefix check
            assert kvp.read("$AXIS_ACT") == "{E6AXIS: A1 1.5, A2 -90.0}"
        assert kvp.stats.count == 3  # one sample each (the id probe, abandoned, has none)
        assert kvp.connected and kvp.connection is not None
        assert kvp.connection.in_flight == 0


def test_reply_with_another_id_is_never_taken_as_the_value() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "STALE":
            # the answer of an earlier request (id - 1), then silence
            w.write(encode_reply(Reply((req.msg_id - 1) & 0xFFFF, Mode.READ, b"v:OLD", 1)))
            return
        w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=1.0) as kvp:
        assert kvp.read("FIRST") == "v:FIRST"
        with pytest.raises(KvpConnectionError, match="answers no request"):
            kvp.read("STALE")
        assert not kvp.connected


def test_a_variable_whose_reply_changes_type_is_refused_on_the_prefix_path() -> None:
    texts = iter([b"{E6AXIS: A1 1.0}", b"{E6AXIS: A1 2.0}", b"{E6POS: X 1.0}"])

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        w.write(answer(req, next(texts) if req.name == "MYAXIS" else None))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=1.0) as kvp:
        assert kvp.read("MYAXIS") == "{E6AXIS: A1 1.0}"  # learns the shape
        assert kvp.read("MYAXIS") == "{E6AXIS: A1 2.0}"  # accepted by its prefix
        with pytest.raises(KvpConnectionError, match="reads like"):
            kvp.read("MYAXIS")
        assert not kvp.connected


def test_timeout_on_the_fast_path_keeps_the_connection_in_step() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "SLOW":
            await asyncio.sleep(0.25)
        w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=0.05) as kvp:
        with pytest.raises(KvpTimeoutError, match="SLOW"):
            kvp.read("SLOW")
        # the late reply is still owed: the next read must not take it for its own
        assert kvp.read("NEXT", timeout=2.0) == "v:NEXT"
        assert kvp.read("AGAIN") == "v:AGAIN"  # idle again: the fast path once more
        assert kvp.connection is not None and kvp.connection.in_flight == 0
