"""Abusers of the wire-faithful (``--wire kvp9``) and C3 Bridge (``--proxy c3bridge``) modes,
and the abuse run: tools of the abuse suite (``tests/abuse``) and of ``bench/isolation.py``,
next to the KVP-core abusers of :mod:`.abusers`.

* :func:`in_flood` — pipelined reads of the 24 KB ``$IN[]``, ``depth`` per write, every reply
  read (counted by bytes, so the abuser costs little CPU and the emulator gets the cores);
* :func:`c3_selects` — C3 Bridge program selects (#10) of one module, one after the other;
* :func:`c3_garbage` — C3 messages of every handled type with random, truncated or oversized
  payloads (and the 400-digit motion of the issue), each answered or the connection closed;
* :func:`big_module` — a valid KRL module of about ``size`` bytes (a long straight routine);
* :func:`run_abuse` — the bystander and a set of abusers against an emulator process, with
  its peak memory (:class:`~.process.PeakRss`).

Abusers count what they see in an :class:`~.abusers.AbuseTally` and never
assert; ``errors`` counts what a well-behaved server should never cause (a refused connect, an
unexpected close, a reply that does not parse).
"""

from __future__ import annotations

import asyncio
import random
import struct
from collections.abc import Callable, Coroutine, Sequence
from typing import Any

from pyopenshowvar.c3.messages import ProgramSelect
from pyopenshowvar.protocol import HEADER_SIZE, decode_reply, encode_read

from .abusers import AbuseTally
from .probe import ProbeResult, start_probe
from .process import EmulatorProcess, PeakRss

__all__ = ["Abuser", "big_module", "c3_garbage", "c3_selects", "in_flood", "run_abuse"]

#: An abuser: ``abuser(host, port, tally)`` misbehaves until cancelled.
Abuser = Callable[[str, int, AbuseTally], Coroutine[Any, Any, None]]

_U16 = struct.Struct(">H")


async def _read_exactly(reader: asyncio.StreamReader, size: int, timeout: float) -> bytes:
    async with asyncio.timeout(timeout):
        return await reader.readexactly(size)


async def _open(
    host: str, port: int, tally: AbuseTally
) -> tuple[asyncio.StreamReader, asyncio.StreamWriter] | None:
    """A connection, counted; None (an error counted) when it is refused."""
    try:
        streams = await asyncio.open_connection(host, port)
    except OSError:
        tally.errors += 1
        return None
    tally.connections += 1
    return streams


def run_abuse(
    emu: EmulatorProcess,
    abusers: Sequence[Abuser],
    seconds: float,
    *,
    done: Callable[[AbuseTally], bool] | None = None,
    patience: float = 40.0,
    min_requests: int = 0,
) -> tuple[ProbeResult, AbuseTally, float]:
    """The bystander (its own process) and ``abusers`` (this process) against ``emu`` for
    ``seconds``, then until ``done(tally)`` (at most ``patience`` more seconds: a loaded
    machine makes the abuse longer, never the abusers' counts smaller), the bystander timing
    at least ``min_requests`` round trips: (what the bystander saw, what the abusers counted,
    the emulator's peak RSS growth in MB during the abuse). An abuser that raises counts as an
    error. The bystander's result has the net round trips and the emulator's CPU time too
    (``net_*``, ``cpu_*``)."""
    peak = PeakRss(emu.pid)
    before = peak.reset()
    tally = AbuseTally()
    probe = start_probe(
        emu.host,
        emu.port,
        seconds + patience + 30.0,  # a cap only: it is stopped below
        "ABUSE_PROBE",
        emulator_pid=emu.pid,
        until_stopped=True,
        min_requests=min_requests,
    )

    async def attack() -> ProbeResult:
        tasks = [asyncio.create_task(a(emu.host, emu.port, tally)) for a in abusers]
        await asyncio.sleep(seconds)
        end = asyncio.get_running_loop().time() + patience
        # polled: the abusers bump plain counters, there is no event to wait on; what fell
        # short is for the caller's checks of the tally to say
        while done is not None and not done(tally) and asyncio.get_running_loop().time() < end:  # noqa: ASYNC110
            await asyncio.sleep(0.05)
        # the bystander ends once it has its sample, the abusers still at it
        result = await asyncio.to_thread(probe.result)
        for task in tasks:
            task.cancel()
        for outcome in await asyncio.gather(*tasks, return_exceptions=True):
            if isinstance(outcome, Exception):
                tally.errors += 1
        return result

    result = asyncio.run(attack())
    return result, tally, peak.peak_mb() - before


async def in_flood(
    host: str, port: int, tally: AbuseTally, *, name: str = "$IN[]", depth: int = 100
) -> None:
    """Send ``depth`` reads of ``name`` in one write and take all their replies, again and
    again. Each reply has the size of the first one; a batch that arrives with another size
    or header counts as wrong."""
    streams = await _open(host, port, tally)
    if streams is None:
        return
    reader, writer = streams
    try:
        writer.write(encode_read(1, name))
        head = await _read_exactly(reader, HEADER_SIZE, 10.0)
        body = await _read_exactly(reader, _U16.unpack_from(head, 2)[0], 10.0)
        reply = decode_reply(head + body)
        size = len(head) + len(body)
        tally.requests += 1
        tally.replies += 1
        batch = b"".join(encode_read(i, name) for i in range(depth))
        expected_first = encode_read(0, name)[:2] + head[2:4]
        while True:
            writer.write(batch)
            tally.requests += depth
            data = await _read_exactly(reader, size * depth, 10.0)
            tally.replies += depth
            if data[:4] != expected_first or not reply.ok:
                tally.wrong += 1
    except (OSError, asyncio.IncompleteReadError, TimeoutError):
        tally.errors += 1
    finally:
        writer.close()


def big_module(name: str, size: int) -> bytes:
    """A KRL ``.src`` of about ``size`` bytes (at most ``size``) that the emulator parses: one
    routine of ``I = I + n`` lines (parsing it is the cost; it never runs here)."""
    head = f"DEF {name}()\n  DECL INT I\n  I = 0\n"
    tail = "END\n"
    lines = [head]
    used = len(head) + len(tail)
    n = 0
    while True:
        n += 1
        line = f"  I = I + {n % 97}  ; step {n}\n"
        if used + len(line) > size:
            break
        lines.append(line)
        used += len(line)
    lines.append(tail)
    return "".join(lines).encode("latin-1")


async def c3_selects(host: str, port: int, tally: AbuseTally, *, module: str) -> None:
    """Select ``module`` (a C3 #10 select), wait for the answer, again and again; a failure
    code counts as wrong (the module is valid and nothing runs)."""
    streams = await _open(host, port, tally)
    if streams is None:
        return
    reader, writer = streams
    n = 0
    try:
        while True:
            n = (n + 1) & 0xFFFF
            writer.write(ProgramSelect(module).frame(n))
            tally.requests += 1
            head = await _read_exactly(reader, HEADER_SIZE, 30.0)
            body = await _read_exactly(reader, _U16.unpack_from(head, 2)[0], 30.0)
            reply = decode_reply(head + body)
            tally.replies += 1
            if reply.msg_id != n or not reply.ok:
                tally.wrong += 1
    except (OSError, asyncio.IncompleteReadError, TimeoutError):
        tally.errors += 1
    finally:
        writer.close()


#: Message types of C3 Bridge 1.4 that have a handler (the emulator's ``HANDLED``), without
#: those that change the robot's program or move it: garbage must not start anything.
_GARBAGE_TYPES = (0, 1, 4, 5, 6, 7, 13, 14, 17, 20, 21, 22, 23, 24, 25, 26, 27, 28, 29, 30)


def _c3_garbage_frame(rng: random.Random, msg_id: int) -> bytes:
    kind = rng.randrange(10)
    msg_type = rng.choice(_GARBAGE_TYPES)
    if kind < 4:  # random payload
        payload = rng.randbytes(rng.randint(0, 64))
    elif kind < 6:  # a length prefix announcing more than is there
        payload = bytes((rng.randrange(256),)) + b"\xff\xff" + rng.randbytes(rng.randint(0, 8))
    elif kind < 8:  # nothing at all
        payload = b""
    elif kind == 8:  # the motion of the issue: a 400-digit integer (no robot moves: no program
        # is selected, and a motion to such a target is refused whatever the robot does)
        msg_type = 11
        text = "{A1 " + "9" * 400 + "}"
        payload = b"\x01" + _U16.pack(len(text)) + text.encode("utf-16-le")
    else:  # a benchmark asking for 2**32-1 iterations of up to 10 names
        msg_type = 17
        payload = b"\x00\x0a\xff\xff\xff\xff" + b"".join(
            _U16.pack(7) + "$OV_PRO".encode("utf-16-le") for _ in range(10)
        )
    return _U16.pack(msg_id) + _U16.pack(len(payload) + 1) + bytes((msg_type,)) + payload


async def c3_garbage(host: str, port: int, tally: AbuseTally, *, seed: int = 0) -> None:
    """Send malformed C3 messages one at a time; each must be answered (with its id) —
    C3 Bridge answers every message of a handled type, malformed or not."""
    rng = random.Random(seed)
    while True:
        streams = await _open(host, port, tally)
        if streams is None:
            await asyncio.sleep(0.01)
            continue
        reader, writer = streams
        try:
            for n in range(1, 50):
                writer.write(_c3_garbage_frame(rng, n))
                tally.requests += 1
                head = await _read_exactly(reader, HEADER_SIZE, 10.0)
                await _read_exactly(reader, _U16.unpack_from(head, 2)[0], 10.0)
                tally.replies += 1
                if _U16.unpack_from(head)[0] != n:
                    tally.wrong += 1
        except (OSError, asyncio.IncompleteReadError, TimeoutError):
            tally.errors += 1
            await asyncio.sleep(0.01)
        finally:
            writer.close()
