"""The synchronous client's serial read fast path (issue 14): the cases it must hand over.

``BlockingConnection.read_text`` accepts a read when one whole reply with its id arrives in one
recv; everything else goes to the general path, which must still match, check and time out
exactly as before. Each test drives one such case through a deliberately odd server.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

import pytest

from pyopenshowvar import (
    KvpConnectionError,
    KvpTimeoutError,
    ReadFailedError,
    UnknownVariableError,
    sync,
)
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


# ---------------------------------------------------------------------------------------------
# A deliberately broken proxy against the fast path (mutation audit: every rule of read_text
# and _finish_idle that decides "this reply is the value" has a test that fails without it).


def _serve(replies: dict[str, bytes]) -> Callable[[Request, asyncio.StreamWriter, int], Any]:
    """A handler answering ``name`` with ``replies[name]`` (frame bytes, id patched to the
    request's), everything else correctly."""

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        frame = replies.get(req.name)
        w.write(answer(req) if frame is None else req.msg_id.to_bytes(2, "big") + frame[2:])

    return handler


def _reply(value: bytes, status: int = 1, mode: int | None = Mode.READ) -> bytes:
    return encode_reply(Reply(0, mode, value, status))


@pytest.mark.parametrize("twice", [False, True], ids=["first read", "prefix known"])
def test_a_failed_read_that_carries_a_value_is_never_its_text(twice: bool) -> None:
    replies = {"$AXIS_ACT": _reply(b"{E6AXIS: A1 1.0}", status=0)}
    with FakeProxy(_serve(replies)) as port, sync.Client(port=port, timeout=1.0) as kvp:
        if twice:  # the shape is known: the prefix path would accept "{E6AXIS:" at once
            replies.pop("$AXIS_ACT")
            kvp.read("$AXIS_ACT")
            replies["$AXIS_ACT"] = _reply(b"{E6AXIS: A1 1.0}", status=0)
        with pytest.raises(ReadFailedError):
            kvp.read("$AXIS_ACT")
        res = kvp.read_many(["$AXIS_ACT", "OK"])
        assert not res["$AXIS_ACT"].ok and isinstance(res["$AXIS_ACT"].error, ReadFailedError)
        assert res["OK"].text == "v:OK"
        assert kvp.connected  # a failure status is an answer, not a protocol error


def test_an_empty_value_is_unknown_not_an_empty_text() -> None:
    replies = {"NOPE": _reply(b""), "MODELESS": encode_reply(Reply(0, None))}
    with FakeProxy(_serve(replies)) as port, sync.Client(port=port, timeout=1.0) as kvp:
        with pytest.raises(UnknownVariableError):
            kvp.read("NOPE")
        assert kvp.read("NEXT") == "v:NEXT" and kvp.connected
        with pytest.raises(KvpConnectionError, match="has no mode"):  # KVP's unknown-mode answer
            kvp.read("MODELESS")  # to a read: it cannot be KVP 9.0's answer to this request


@pytest.mark.parametrize(
    "frame",
    [
        _reply(b"v:BAD")[:-1],  # the status byte missing: L says one more byte
        bytes.fromhex("0000 000A 00 0009") + b"v:BAD" + bytes.fromhex("0001 01"),  # V too big
        bytes.fromhex("0000 000C 00 0003") + b"v:BAD" + bytes.fromhex("0001 01"),  # V too small
        bytes.fromhex("0000 000B 01 0005") + b"v:BAD" + bytes.fromhex("0001 01"),  # mode 1
        # L agrees with the bytes sent, V does not (the fast path must check V too)
        bytes.fromhex("0000 000B 00 0003") + b"v:BAD" + bytes.fromhex("0001 01"),
        bytes.fromhex("0000 000B 00 0004") + b"v:BAD" + bytes.fromhex("0001 01"),
        # V agrees with the bytes sent, L does not (the fast path must check L too)
        bytes.fromhex("0000 000A 00 0005") + b"v:BAD" + bytes.fromhex("0001 01"),
        bytes.fromhex("0000 000C 00 0005") + b"v:BAD" + bytes.fromhex("0001 01"),
        bytes.fromhex("0000 0013 00 0005") + b"v:BAD" + bytes.fromhex("0001 01"),
        # L agrees, V counts the whole frame plus its head
        bytes.fromhex("0000 000B 00 0019") + b"v:BAD" + bytes.fromhex("0001 01"),
    ],
    ids=[
        *("cut", "value-length-over", "value-length-under", "write-mode", "v-3", "v-4"),
        *("l-1", "l+1", "l+8", "v+20"),
    ],
)
def test_a_malformed_or_mismatched_reply_is_never_a_value(frame: bytes) -> None:
    with (
        FakeProxy(_serve({"BAD": frame})) as port,
        sync.Client(port=port, timeout=0.3) as kvp,
    ):
        assert kvp.read("GOOD") == "v:GOOD"
        with pytest.raises((KvpConnectionError, KvpTimeoutError)):
            kvp.read("BAD")


def test_a_reply_in_two_pieces_and_two_replies_in_one_segment() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        reply = answer(req)
        if req.name == "CUT":  # the head alone, then the rest
            w.write(reply[:4])
            await w.drain()
            await asyncio.sleep(0.02)
            w.write(reply[4:])
        elif req.name == "EXTRA":  # the reply and an answer to nothing, in one segment
            w.write(reply + encode_reply(Reply(0x7777, Mode.READ, b"v:EVIL")))
        else:
            w.write(reply)

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=1.0) as kvp:
        assert kvp.read("CUT") == "v:CUT"
        assert kvp.read("CUT") == "v:CUT"
        assert kvp.stats.count == 2
        assert kvp.read("EXTRA") == "v:EXTRA"  # its own reply, proven by its id
        assert not kvp.connected  # the reply to nothing dropped the connection loudly
        with pytest.raises(KvpConnectionError, match="answers no request"):
            kvp.read("NEXT")


def test_message_ids_wrap_from_65535_to_0_on_the_fast_paths() -> None:
    seen: list[int] = []

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        seen.append(req.msg_id)
        w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=1.0) as kvp:
        assert kvp.read("A") == "v:A"  # after the id probe (ids 0 and 1)
        assert kvp.connection is not None
        kvp.connection.session.next_id = 0xFFFE
        assert [kvp.read(n) for n in ("B", "C", "D")] == ["v:B", "v:C", "v:D"]
        assert kvp.write("E", "5") == "5"  # the write takes the idle path too
        assert kvp.read("F") == "v:F"
        assert kvp.write("G", "6") == "6"
        assert kvp.read("H") == "v:H"
        assert seen[-7:] == [0xFFFE, 0xFFFF, 0, 1, 2, 3, 4]
        assert kvp.connection.in_flight == 0


def test_a_reply_with_the_previous_id_after_a_timeout_is_not_the_next_value() -> None:
    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "SLOW":
            await asyncio.sleep(0.2)
        w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=0.05) as kvp:
        with pytest.raises(KvpTimeoutError):
            kvp.read("SLOW")
        # SLOW's late reply arrives first; the fast path must not take it as FAST's value
        assert kvp.read("FAST", timeout=1.0) == "v:FAST"
        assert kvp.write("W", "1", timeout=1.0) == "1"


def test_a_pipelined_read_without_a_reply_times_out_alone_and_its_late_reply_is_dropped() -> None:
    """read_many: each unanswered name gets its own timeout error naming it, the others their
    values; the reply that comes later is discarded, and the connection stays in step."""

    async def handler(req: Request, w: asyncio.StreamWriter, n: int) -> None:
        if req.name == "LATE":
            await asyncio.sleep(0.4)
        w.write(answer(req))

    with FakeProxy(handler) as port, sync.Client(port=port, timeout=2.0) as kvp:
        kvp.read("FIRST")  # connected
        res = kvp.read_many(["A", "B", "LATE"], timeout=0.2)  # the proxy answers in order
        assert res["A"].text == "v:A" and res["B"].text == "v:B"
        error = res["LATE"].error
        assert isinstance(error, KvpTimeoutError)
        assert str(error) == f"no reply for 'LATE' from 127.0.0.1:{port} within 0.2 s"
        assert kvp.read("NEXT", timeout=2.0) == "v:NEXT"  # not LATE's reply
        assert kvp.connected
        assert kvp.connection is not None and kvp.connection.in_flight == 0


@pytest.mark.parametrize("msg_id", [0x0101, 0x0201, 0x0102])
@pytest.mark.parametrize("status", [0, 2])
def test_only_status_1_is_success_whatever_the_id(msg_id: int, status: int) -> None:
    """The fast path reads the status from the last byte, never from another byte that
    happens to be 1 (an id's low byte), and takes no other status than 1 for success."""
    replies = {"F": _reply(b"v:F", status=status)}
    with FakeProxy(_serve(replies)) as port, sync.Client(port=port, timeout=1.0) as kvp:
        assert kvp.read("OK") == "v:OK"
        assert kvp.connection is not None
        kvp.connection.session.next_id = msg_id
        with pytest.raises(ReadFailedError):
            kvp.read("F")
        assert kvp.read("OK") == "v:OK" and kvp.connected
