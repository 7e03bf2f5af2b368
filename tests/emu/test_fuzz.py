"""Hypothesis fuzzing: whatever one client sends, the server survives and others are served.

One emulator per mode (fast path, and the queued path through the service worker) runs in a
thread; a well-behaved client keeps asking between examples and must get exact answers, and
every connection's buffers must stay within their bounds.
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Iterator
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kukavarproxy_emu import EmulatorThread
from kukavarproxy_emu.kvp_connection import FRAMED_READ_BYTES

# the fixtures (the root conftest may also load them as a plugin)
from kukavarproxy_emu.testing import *  # noqa: F403
from kukavarproxy_emu.testing import TEST_CONFIG, EmulatorFactory, RawClient
from pyopenshowvar.protocol import (
    ReplyDecoder,
    encode_read,
    encode_read_array,
    encode_write,
    encode_write_array,
)

MAX_FRAME = 512
MAX_PENDING = 16
CONFIG = replace(TEST_CONFIG, max_frame=MAX_FRAME, max_pending=MAX_PENDING, max_clients=0)
# The bystander reads a read-only variable: the fuzzer may legitimately change $OV_PRO.
GOOD_NAME = "$KR_SERIALNO"

names = st.sampled_from(["$OV_PRO", "MYINT", "$AXIS_ACT", "PING", "NOPE", "MYARR[]", "@PROXY_TYPE"])
values = st.text(st.characters(max_codepoint=255), max_size=20)
ids = st.integers(0, 0xFFFF)
valid_frame = st.one_of(
    st.builds(encode_read, ids, names),
    st.builds(encode_write, ids, names, values),
    st.builds(encode_read_array, ids, names),
    st.builds(encode_write_array, ids, names, st.lists(st.integers(0, 0xFFFF), max_size=4)),
    st.builds(
        lambda i, m, b: i.to_bytes(2, "big") + (len(b) + 1).to_bytes(2, "big") + bytes([m]) + b,
        ids,
        st.integers(4, 255),
        st.binary(max_size=8),
    ),
)


@st.composite
def mutated(draw: st.DrawFn) -> bytes:
    data = bytearray(b"".join(draw(st.lists(valid_frame, min_size=1, max_size=4))))
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["flip", "cut", "insert"]))
        pos = draw(st.integers(0, len(data)))
        if op == "flip" and pos < len(data):
            data[pos] = draw(st.integers(0, 255))
        elif op == "cut":
            del data[pos:]
        else:
            data[pos:pos] = draw(st.binary(min_size=1, max_size=4))
    return bytes(data)


payloads = st.one_of(st.binary(max_size=600), mutated(), st.lists(valid_frame).map(b"".join))


@pytest.fixture(scope="module", params=["fast", "queued"])
def fuzz_emulator(request: pytest.FixtureRequest) -> Iterator[tuple[EmulatorThread, socket.socket]]:
    config = CONFIG if request.param == "fast" else replace(CONFIG, latency="fixed:0")
    with EmulatorThread(config) as emu, socket.create_connection((emu.host, emu.port), 2) as good:
        yield emu, good


def exchange(emu: EmulatorThread, payload: bytes, cuts: list[int]) -> bytes:
    """Send ``payload`` in pieces, half-close, and collect everything until the server closes."""
    received = bytearray()
    with socket.create_connection((emu.host, emu.port), 2) as sock:
        sock.settimeout(2)
        try:
            last = 0
            for cut in sorted({c % (len(payload) + 1) for c in cuts} | {len(payload)}):
                sock.sendall(payload[last:cut])
                last = cut
            sock.shutdown(socket.SHUT_WR)
            while chunk := sock.recv(65536):
                received += chunk
        except OSError:
            pass  # the server may close on garbage while we are still sending
    return bytes(received)


@settings(max_examples=150, deadline=None)
@given(payload=payloads, cuts=st.lists(st.integers(0, 10_000), max_size=4))
def test_fuzz_server_survives(
    fuzz_emulator: tuple[EmulatorThread, socket.socket], payload: bytes, cuts: list[int]
) -> None:
    emu, good = fuzz_emulator
    replies = ReplyDecoder().feed_replies(exchange(emu, payload, cuts))
    assert all(r.mode is None or r.mode <= 3 for r in replies)
    # the other client is unaffected
    good.sendall(encode_read(9, GOOD_NAME))
    reply = ReplyDecoder().feed_replies(good.recv(256))
    assert (
        len(reply) == 1
        and reply[0].msg_id == 9
        and reply[0].ok
        and reply[0].value == emu.store.read(GOOD_NAME).encode("latin-1")
    )
    for info in emu.call(emu.emulator.connections):
        assert info.buffered < MAX_FRAME
        assert info.pending <= MAX_PENDING + FRAMED_READ_BYTES // 7
        assert info.write_buffer < 1 << 20


@settings(max_examples=60, deadline=None)
@given(
    frames=st.lists(valid_frame, min_size=1, max_size=30), cuts=st.lists(st.integers(), max_size=6)
)
def test_valid_frames_any_segmentation_answered_in_order(
    fuzz_emulator: tuple[EmulatorThread, socket.socket], frames: list[bytes], cuts: list[int]
) -> None:
    emu, _ = fuzz_emulator
    replies = ReplyDecoder().feed_replies(exchange(emu, b"".join(frames), cuts))
    assert [r.msg_id for r in replies] == [int.from_bytes(f[:2], "big") for f in frames]


@pytest.mark.parametrize("latency", ["none", "fixed:0"])
async def test_flood_without_reading_stays_bounded(
    emulator_factory: EmulatorFactory, latency: str
) -> None:
    emu = await emulator_factory(latency=latency, max_pending=MAX_PENDING)
    # Small kernel buffers on both ends, so replies pile up in the server process quickly.
    sock = socket.socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect((emu.host, emu.port))
    sock.setblocking(False)
    c = RawClient(*await asyncio.open_connection(sock=sock))
    await c.request(encode_read(0, "PING"))
    server_sock = emu._connections[1].transport.get_extra_info("socket")  # type: ignore[union-attr]
    server_sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
    n = 50_000
    c.writer.write(encode_read(1, "$OV_PRO") * n)  # the client side buffers what is not read
    # backpressure: the server stops reading this socket once its unsent output is full (how
    # soon depends on the latency scheduler and the machine's load, so wait for it, bounded)
    for _ in range(200):  # at most 10 s
        (info,) = emu.connections()
        if info.reading_paused:
            break
        await asyncio.sleep(0.05)
    assert info.reading_paused
    assert info.received < n
    assert info.pending <= MAX_PENDING + FRAMED_READ_BYTES // 14
    assert info.write_buffer < 1 << 20
    assert info.buffered < 14
    # now read everything: nothing was lost and the order is intact
    decoder = ReplyDecoder()
    got = 0
    async with asyncio.timeout(20):
        while got < n:
            got += len(decoder.feed_replies(await c.reader.read(1 << 16)))
    assert got == n and emu.stats.requests == n + 1
    await c.close()
