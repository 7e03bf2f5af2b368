"""Regression tests of issue 16 (emulator): bounded memory, no stalls, clean closes, safe logs.

Each test pins one failure measured on the emulator before the fix; CPU-time bounds use
``time.process_time`` (immune to a loaded machine) with a wide margin, and stalls are checked
structurally (does the event loop run while a costly batch is being answered?) rather than by
wall-clock latency. The latency figures themselves are asserted in ``tests/abuse``.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import struct
import subprocess
import sys
import textwrap
import time
import tracemalloc

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from kukavarproxy_emu import Emulator, EmulatorConfig, kvp_connection
from kukavarproxy_emu.__main__ import build_parser, config_from_args
from kukavarproxy_emu.responder import Responder
from kukavarproxy_emu.store import VariableStore
from kukavarproxy_emu.testing import EmulatorFactory, RawClient
from pyopenshowvar.protocol import (
    Mode,
    Request,
    encode_read,
    encode_write,
)

H = bytes.fromhex
#: The documented bound on a connection's unsent output (docs/emulator.md): 64 KiB plus one
#: reply, the largest being 4 + 0xFFFF bytes.
OUTPUT_BOUND = 64 * 1024 + 4 + 0xFFFF
E6 = "{A1 %d.125, A2 -90.0625, A3 90.03125, A4 1.0, A5 2.0, A6 3.0, E1 0, E2 0, E3 0, E4 0}"


async def connect(emu: Emulator) -> RawClient:
    return await RawClient.connect(emu.host, emu.port)


async def raw_socket(emu: Emulator, rcvbuf: int = 4096) -> socket.socket:
    """A non-blocking socket with a small receive buffer (a client that reads nothing)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    sock.setblocking(False)
    await asyncio.get_running_loop().sock_connect(sock, (emu.host, emu.port))
    return sock


# --- 1. bounded memory ---------------------------------------------------------------------


def test_distinct_long_names_do_not_accumulate() -> None:
    store = VariableStore()
    store.read("$OV_PRO")  # warm up everything that is cached legitimately
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for i in range(600):
            with pytest.raises(LookupError):
                store.read(f"N{i:06d}" + "X" * 16_000)
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert grown < 2_000_000  # before the fix every name stayed cached: ~19 MB here


async def test_unsent_output_is_bounded_and_reading_stops(
    emulator_factory: EmulatorFactory,
) -> None:
    emu = await emulator_factory(robot=False)
    loop = asyncio.get_running_loop()
    sock = await raw_socket(emu)
    try:
        # 2000 reads of $IN[] (~24 KB each) in one go, and never a byte read back
        await loop.sock_sendall(sock, b"".join(encode_read(i, "$IN[]") for i in range(2000)))
        for _ in range(100):
            await asyncio.sleep(0.01)
            (info,) = emu.connections()
            assert info.write_buffer <= OUTPUT_BOUND
            if info.reading_paused and info.pending:
                break
        assert info.reading_paused and info.pending  # the rest waits for the client to read
        async with await connect(emu) as other:  # and the server still answers others
            assert (await other.request(encode_read(1, "$OV_PRO")))[7:-3] == b"100"
    finally:
        sock.close()


# --- 2. a dropped client is gone -----------------------------------------------------------


async def test_idle_drop_of_a_non_reading_client_frees_its_slot(
    emulator_factory: EmulatorFactory,
) -> None:
    emu = await emulator_factory(robot=False, max_clients=1, idle_timeout=0.3)
    loop = asyncio.get_running_loop()
    sock = await raw_socket(emu)
    try:
        await loop.sock_sendall(sock, b"".join(encode_read(i, "$IN[]") for i in range(300)))
        for _ in range(150):  # idle drop after 0.3..0.375 s
            await asyncio.sleep(0.01)
            if emu.stats.idle_drops:
                break
        assert emu.stats.idle_drops == 1
        assert emu.stats.clients == 0 and emu.connections() == []
        async with await connect(emu) as newcomer:  # the slot is free: not refused
            assert (await newcomer.request(encode_read(2, "PING")))[7:-3] == b"PONG"
        assert emu.stats.rejected == 0
    finally:
        sock.close()


async def test_garbage_after_unread_requests_frees_the_slot_after_the_grace(
    emulator_factory: EmulatorFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(kvp_connection, "ERROR_GRACE", 0.3)
    emu = await emulator_factory(robot=False, max_clients=1, idle_timeout=0)
    loop = asyncio.get_running_loop()
    sock = await raw_socket(emu)
    try:
        junk = b"".join(encode_read(i, "$IN[]") for i in range(300)) + H("0001 0000")
        await loop.sock_sendall(sock, junk)  # then it never reads the replies it is owed
        for _ in range(200):
            await asyncio.sleep(0.01)
            if emu.stats.clients == 0:
                break
        assert emu.stats.clients == 0 and emu.stats.protocol_errors == 1
        async with await connect(emu) as newcomer:
            assert (await newcomer.request(encode_read(2, "PING")))[7:-3] == b"PONG"
    finally:
        sock.close()


def test_idle_reset_option_on_the_command_line() -> None:
    args = build_parser().parse_args(["--idle-reset", "requests"])
    assert config_from_args(args).idle_reset == "requests"
    assert config_from_args(build_parser().parse_args([])).idle_reset == "bytes"
    with pytest.raises(ValueError, match="idle_reset"):
        EmulatorConfig(idle_reset="sometimes")


# --- 3. no request or batch holds the loop -------------------------------------------------


async def test_costly_pipelined_batch_lets_the_loop_run(
    emulator_factory: EmulatorFactory,
) -> None:
    emu = await emulator_factory(robot=False)
    for i in range(1, 513):
        emu.store.write(f"MYE6ARRAY[{i}]", E6 % i)
    pairs = [
        encode_write(2 * i, f"MYE6ARRAY[{i % 512 + 1}]", f"{{A1 {i}.5}}")
        + encode_read(2 * i + 1, "MYE6ARRAY[]")
        for i in range(300)
    ]
    total = 600
    seen: list[int] = []

    def heartbeat() -> None:  # one sample per event-loop iteration
        seen.append(emu.stats.requests)
        if emu.stats.requests < total:
            asyncio.get_running_loop().call_soon(heartbeat)

    async with await connect(emu) as c:
        heartbeat()
        await c.send(b"".join(pairs))
        replies = [await c.read_reply(timeout=10.0) for _ in range(total)]
    assert [r.msg_id for r in replies] == list(range(total))
    # The loop ran while the batch was half answered: it was cut into slices.
    assert any(0 < n < total for n in seen)
    assert all(r.ok for r in replies[0::2])


def test_write_then_whole_array_read_formats_one_element() -> None:
    store = VariableStore()
    for i in range(1, 513):
        store.write(f"MYE6ARRAY[{i}]", E6 % i)
    responder = Responder(store)
    responder.answer(Request(1, Mode.READ, "MYE6ARRAY[]", None), 1)
    start = time.process_time()
    for i in range(50):
        store.write(f"MYE6ARRAY[{i + 1}]", f"{{A1 {i}.5}}")
        responder.answer(Request(1, Mode.READ, "MYE6ARRAY[]", None), 1)
    per_pair = (time.process_time() - start) / 50
    assert per_pair < 0.002  # before: every read formatted 512 elements (~10-15 ms)
    expected = "".join(f"{store.read(f'MYE6ARRAY[{i}]')} " for i in range(1, 513))
    assert store.read("MYE6ARRAY[]") == expected


def test_whole_array_read_after_rewriting_every_element_is_cheap() -> None:
    store = VariableStore()
    for i in range(1, 513):
        store.write(f"MYE6ARRAY[{i}]", E6 % i)
    store.read("MYE6ARRAY[]")  # read whole once: from now on its element texts are kept
    for i in range(1, 513):  # every element rewritten, one write each
        store.write(f"MYE6ARRAY[{i}]", E6 % (i + 1000))
    start = time.process_time()
    text = store.read("MYE6ARRAY[]")
    assert time.process_time() - start < 0.003  # a join; formatting 512 E6AXIS is ~10 ms
    assert text == "".join(f"{store.read(f'MYE6ARRAY[{i}]')} " for i in range(1, 513))


def test_largest_mode3_frame_is_cheap_and_exact() -> None:
    store = VariableStore()
    store.declare("WORDS", "INT", (600,), "0")
    store.declare("LIMITED", "REAL", (4,), "0.0", ranges=(0.0, 100.0))
    responder = Responder(store)
    payload = bytes(range(256)) * 255 + b"\x00\x07"  # 32 641 words: the largest frame
    start = time.process_time()
    reply = responder.answer(Request(1, Mode.WRITE_ARRAY, "WORDS[]", payload), 1)
    assert time.process_time() - start < 0.05  # before: 0.25-0.4 s
    assert not reply.ok  # elements beyond WORDS[600] fail; only the last status counts
    assert store.get("WORDS[1]") == 0x0001 and store.get("WORDS[600]") == 0xAEAF
    assert responder.answer(Request(2, Mode.WRITE_ARRAY, "WORDS", b"\x00\x07\x00\x08"), 2).ok
    assert store.get("WORDS[2]") == 8
    # per element: 150 is out of range, the last (50) is in range and decides the status
    words = b"\x00\x0a\x00\x96\x00\x14\x00\x32"
    assert responder.answer(Request(3, Mode.WRITE_ARRAY, "LIMITED", words), 3).ok
    assert store.get("LIMITED") == [10.0, 0.0, 20.0, 50.0]
    for name in ("$IN", "MYE6ARRAY", "MYSTRING", "NOPE", "OUTPUT_VARS"):  # no digits there
        assert not responder.answer(Request(4, Mode.WRITE_ARRAY, name, b"\x00\x01"), 4).ok


def test_the_emulator_process_freezes_its_start_up_heap() -> None:
    # A full collection over the start-up heap (store, robot, numpy, physics) paused the loop
    # for ~90 ms under a flood of requests; kukavarproxy-emu freezes that heap after start.
    script = textwrap.dedent(
        """
        import asyncio, gc, os, signal
        from kukavarproxy_emu import EmulatorConfig
        from kukavarproxy_emu.__main__ import serve
        async def main():
            task = asyncio.create_task(serve(EmulatorConfig(port=0, discovery=False)))
            for _ in range(500):
                await asyncio.sleep(0.01)
                if gc.get_freeze_count():
                    break
            print("frozen", gc.get_freeze_count() > 10_000, flush=True)
            os.kill(os.getpid(), signal.SIGTERM)
            await task
        asyncio.run(main())
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False
    )
    assert "frozen True" in proc.stdout, proc.stderr[-2000:]


# --- 4. requests before a malformed header -------------------------------------------------


async def test_requests_before_a_bad_header_in_the_same_segment_are_answered(
    emulator: Emulator,
) -> None:
    async with await connect(emulator) as c:
        await c.send(encode_read(1, "$OV_PRO") + encode_read(2, "PING") + H("0003 0000 00"))
        assert (await c.read_frame())[:2] == H("0001")
        assert (await c.read_frame())[7:-3] == b"PONG"
        assert await c.is_closed_by_peer()
    assert emulator.stats.protocol_errors == 1


# --- 6. logs cannot be forged --------------------------------------------------------------


async def test_network_text_is_escaped_in_logs(
    emulator: Emulator, caplog: pytest.LogCaptureFixture
) -> None:
    forged = "X\n2024-01-01 00:00:00 CRITICAL kukavarproxy_emu: forged"
    with caplog.at_level(logging.DEBUG, logger="kukavarproxy_emu"):
        async with await connect(emulator) as c:
            await c.request(encode_write(1, forged, "1\r\nforged too"))
            await c.request(encode_write(2, "$OV_PRO", "{\nX}"))
            await c.request(encode_write(3, "Y" * 5000, "1"))
    messages = [r.getMessage() for r in caplog.records]
    assert any("forged" in m for m in messages)  # the refusal is logged ...
    assert not any("\n" in m or "\r" in m for m in messages)  # ... on one line
    assert max(len(m) for m in messages) < 1000  # and a 5000-character name is clipped


async def test_discovery_answers_are_rate_limited(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(discovery=True, udp_port=0, udp_reply_port=0)
    assert emu.udp_port
    loop = asyncio.get_running_loop()
    answers = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.setblocking(False)
        for _ in range(200):
            sock.sendto(b"WHEREAREYOU?", ("127.0.0.1", emu.udp_port))
        while True:
            try:
                await asyncio.wait_for(loop.sock_recv(sock, 1024), 0.3)
            except TimeoutError:
                break
            answers += 1
    assert 1 <= answers <= 40  # a burst of 20, then 10 per second
    assert emu.discovery is not None and emu.discovery.refused >= 150


# --- 7. slow clients -----------------------------------------------------------------------


@pytest.mark.parametrize("reset", ["bytes", "requests"])
async def test_idle_reset_bytes_like_kvp_or_requests_only(
    emulator_factory: EmulatorFactory, reset: str
) -> None:
    emu = await emulator_factory(robot=False, idle_timeout=0.3, idle_reset=reset)
    frame = encode_read(1, "$OV_PRO")  # 12 bytes, one every 0.1 s: 1.2 s for the request
    async with await connect(emu) as c:
        for i in range(len(frame) - 1):
            await c.send(frame[i : i + 1])
            await asyncio.sleep(0.1)
            if emu.stats.idle_drops:
                break
        if reset == "bytes":  # KVP: every read event resets the timer, so the trickle lives
            assert emu.stats.idle_drops == 0
            await c.send(frame[-1:])
            assert (await c.read_frame())[7:-3] == b"100"
        else:
            assert emu.stats.idle_drops == 1
            assert await c.is_closed_by_peer()


def _reference_words(store: VariableStore, name: str, words: list[int]) -> bool:
    """Mode 3 as KVP does it: NAME[k] = str(word) one by one; the last status counts."""
    ok = False
    for k, word in enumerate(words, start=1):
        try:
            store.write(f"{name}[{k}]", str(word))
            ok = True
        except (LookupError, ValueError):
            ok = False
    return ok


@settings(max_examples=150, deadline=None)
@given(
    kind=st.sampled_from(["INT", "REAL", "BOOL", "E6AXIS", "CHAR"]),
    dims=st.sampled_from([(1,), (5,), (12,), (3, 4)]),
    limited=st.booleans(),
    read_only=st.booleans(),
    words=st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=16),
    name=st.sampled_from(["V", "v", "V[]", "NOPE", "V.X", " V"]),
)
def test_bulk_mode3_write_equals_element_by_element(
    kind: str,
    dims: tuple[int, ...],
    limited: bool,
    read_only: bool,
    words: list[int],
    name: str,
) -> None:
    assume(not (kind == "CHAR" and len(dims) > 1))  # not declarable
    stores = []
    for _ in range(2):
        store = VariableStore(system=False, default_config=False)
        ranges = (0.0, 30_000.0) if limited and kind in ("INT", "REAL") else None
        store.declare("V", kind, dims, None, read_only, ranges)
        stores.append(store)
    base = name.removesuffix("[]")
    expected = _reference_words(stores[0], base, words)
    assert stores[1].write_words(base, words) is expected
    assert stores[1].snapshot() == stores[0].snapshot()


def test_whole_array_reads_after_mode3_writes_stay_cheap() -> None:
    store = VariableStore()
    store.declare("BIGI", "INT", (32_000,), "0")
    store.declare("BIGR", "REAL", (30_000,), "0.0")
    store.declare("HUGE", "INT", (200_000,), "1")
    responder = Responder(store)
    payload = bytes(range(256)) * 250  # 32 000 words
    for name in ("BIGI", "BIGR", "HUGE"):
        responder.answer(Request(1, Mode.READ, f"{name}[]", None), 1)  # first read: warm-up
        start = time.process_time()
        assert responder.answer(Request(2, Mode.WRITE_ARRAY, name, payload), 2).ok is (
            name != "BIGR"  # 32 000 words, 30 000 elements: the last write fails
        )
        as_text = responder.answer(Request(3, Mode.READ, f"{name}[]", None), 3)
        as_words = responder.answer(Request(4, Mode.READ_ARRAY, f"{name}[]", None), 4)
        assert time.process_time() - start < 0.05, name  # before: up to seconds
        assert not as_text.ok  # no text of 30 000 numbers fits a reply
        if name == "BIGI":  # 32 000 words do fit a mode-2 reply, and they are the ones written
            assert as_words.ok and as_words.value == payload
        else:
            assert as_words.ok is (name == "BIGR")
    assert (
        store.read("BIGI[]") == " ".join(str(w) for (w,) in struct.iter_unpack(">H", payload)) + " "
    )
    assert store.get("BIGR[2]") == 0x0203 and store.read("BIGR[2]") == "515.000"


@given(
    st.lists(
        st.one_of(
            st.integers(-(2**40), 2**40).map(str),
            st.floats(allow_nan=True, allow_infinity=True).map(repr),
            st.sampled_from(["2.5", "-0.5", "1E+03", "TRUE", "#T1", "1.5e300", "9007199254740993"]),
        ),
        min_size=2,
        max_size=8,
    )
)
def test_mode2_words_equal_vb_clng_element_by_element(tokens: list[str]) -> None:
    from kukavarproxy_emu.responder import _pack_words, _to_word  # the fast path, and VB's rule

    try:
        expected: bytes | None = b"".join(struct.pack(">H", _to_word(t)) for t in tokens)
    except (ValueError, OverflowError):
        expected = None
    assert _pack_words(tokens) == expected
