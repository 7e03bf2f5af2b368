"""Abusers of the KVP core: coroutines that misbehave until cancelled and count what they see.

:func:`garbage`, :func:`non_reader`, :func:`long_names`, :func:`costly_pipeline` and
:func:`mode3_flood` each count in an :class:`AbuseTally` and never assert; ``errors`` counts
what a well-behaved server should never cause (a refused connect, an unexpected close, a reply
that does not parse). :data:`RUNAWAY_KRL` is a robot program that never stops wasting time
(slow functions, nested calls, a big local array).
"""

from __future__ import annotations

import asyncio
import random
import socket
from collections import deque
from dataclasses import dataclass

from pyopenshowvar.protocol import (
    Reply,
    ReplyDecoder,
    encode_read,
    encode_write,
    encode_write_array,
)

__all__ = [
    "RUNAWAY_KRL",
    "AbuseTally",
    "costly_pipeline",
    "garbage",
    "long_names",
    "mode3_flood",
    "non_reader",
]

#: A robot program that wastes its whole budget every cycle, forever: a function called in a
#: loop that runs 20 000 iterations calling another function, and a routine with a 200 000
#: element local array. It never ends and never fails.
RUNAWAY_KRL = """\
DEF RUNAWAY()
  DECL INT R
  LOOP
    R = SLOW()
    BIG()
  ENDLOOP
END

DEFFCT INT SLOW()
  DECL INT I, S
  S = 0
  FOR I = 1 TO 20000
    S = S + ONE()
  ENDFOR
  RETURN S
ENDFCT

DEFFCT INT ONE()
  RETURN 1
ENDFCT

DEF BIG()
  DECL INT A[200000]
  A[1] = 1
END
"""

_E6 = "{A1 %d.125, A2 -90.0625, A3 90.03125, A4 1.5, A5 2.5, A6 3.5, E1 0, E2 0, E3 0, E4 0}"


@dataclass
class AbuseTally:
    """What the abusers did and saw (plain counters)."""

    connections: int = 0
    requests: int = 0
    replies: int = 0
    #: Replies with a wrong id or an impossible status/value (for abusers that read).
    wrong: int = 0
    errors: int = 0


class _Replies:
    """Replies off a stream, many per read (cheap for the abuser, so the emulator gets the CPU)."""

    def __init__(self, reader: asyncio.StreamReader) -> None:
        self.reader = reader
        self.decoder = ReplyDecoder()
        self.ready: deque[Reply] = deque()

    async def next(self, timeout: float = 10.0) -> Reply:
        async with asyncio.timeout(timeout):
            while not self.ready:
                data = await self.reader.read(262_144)
                if not data:
                    raise ConnectionError("closed by the emulator")
                self.ready.extend(self.decoder.feed_replies(data))
        return self.ready.popleft()


def _garbage_frame(rng: random.Random) -> bytes:
    kind = rng.randrange(6)
    if kind == 0:  # random bytes
        return rng.randbytes(rng.randint(1, 4096))
    if kind == 1:  # a good request, then a length field of 0 in the same segment
        return encode_read(1, "$OV_PRO") + b"\x00\x02\x00\x00"
    if kind == 2:  # a 64 KB frame that never completes
        return b"\x00\x03\xff\xff\x00" + rng.randbytes(2000)
    if kind == 3:  # blocks that do not add up to the length
        return bytes.fromhex("0004 0004 00 0009 41")
    if kind == 4:  # unknown modes and names full of control characters
        name = "".join(chr(rng.randrange(256)) for _ in range(40))
        return bytes((0, 5, 0, 3 + len(name), rng.randrange(4, 256), 0, len(name))) + name.encode(
            "latin-1"
        )
    return b"\x00\x06" + rng.randbytes(2)  # a header whose length is anything


async def garbage(host: str, port: int, tally: AbuseTally, *, seed: int = 0) -> None:
    """Connect, send garbage, wait briefly for the close, disconnect; again, until cancelled."""
    rng = random.Random(seed)
    while True:
        try:
            reader, writer = await asyncio.open_connection(host, port)
        except OSError:
            tally.errors += 1
            await asyncio.sleep(0.01)
            continue
        tally.connections += 1
        try:
            writer.write(_garbage_frame(rng))
            async with asyncio.timeout(0.2):
                while await reader.read(65536):
                    pass
        except (TimeoutError, OSError):
            pass
        finally:
            writer.close()


async def non_reader(host: str, port: int, tally: AbuseTally, *, name: str = "$IN[]") -> None:
    """Send reads of a large variable as fast as the emulator takes them, never read a reply."""
    loop = asyncio.get_running_loop()
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.setblocking(False)
    try:
        await loop.sock_connect(sock, (host, port))
        tally.connections += 1
        chunk = b"".join(encode_read(i, name) for i in range(200))
        while True:
            await loop.sock_sendall(sock, chunk)  # waits once the emulator stops reading
            tally.requests += 200
    except OSError:
        tally.errors += 1
    finally:
        sock.close()


async def long_names(
    host: str, port: int, tally: AbuseTally, *, size: int = 65_000, depth: int = 4
) -> None:
    """Read variables with distinct ``size``-character names, ``depth`` at a time."""
    reader, writer = await asyncio.open_connection(host, port)
    replies = _Replies(reader)
    tally.connections += 1
    # One frame, patched in place: id in bytes 0-1, a 9-digit counter after the "N".
    template = bytearray(encode_read(0, "N000000000" + "X" * (size - 10)))
    n = 0
    try:
        while True:
            batch = bytearray()
            for k in range(depth):
                n += 1
                template[0:2] = k.to_bytes(2, "big")
                template[8:17] = b"%09d" % n
                batch += template
            writer.write(batch)
            await writer.drain()
            tally.requests += depth
            for k in range(depth):
                reply = await replies.next()
                tally.replies += 1
                if reply.msg_id != k or reply.text != "":  # unknown: empty with success
                    tally.wrong += 1
    finally:
        writer.close()


async def costly_pipeline(host: str, port: int, tally: AbuseTally, *, pairs: int = 300) -> None:
    """Fill ``MYE6ARRAY``, then send ``pairs`` "write one element / read ``MYE6ARRAY[]``"
    pairs in one segment and read the replies, again and again."""
    reader, writer = await asyncio.open_connection(host, port)
    replies = _Replies(reader)
    tally.connections += 1
    try:
        writer.write(b"".join(encode_write(i, f"MYE6ARRAY[{i}]", _E6 % i) for i in range(1, 513)))
        for _ in range(512):
            await replies.next()
        n = 0
        while True:
            frames = []
            for i in range(pairs):
                n += 1
                frames.append(encode_write(2 * i, f"MYE6ARRAY[{n % 512 + 1}]", f"{{A1 {n}.5}}"))
                frames.append(encode_read(2 * i + 1, "MYE6ARRAY[]"))
            writer.write(b"".join(frames))
            await writer.drain()
            tally.requests += 2 * pairs
            for i in range(2 * pairs):
                reply = await replies.next()
                tally.replies += 1
                if reply.msg_id != i or (i % 2 == 0 and not reply.ok):
                    tally.wrong += 1
    finally:
        writer.close()


async def mode3_flood(host: str, port: int, tally: AbuseTally, *, name: str) -> None:
    """Write the largest mode-3 frames (32 000 words) to ``name``, one after the other."""
    reader, writer = await asyncio.open_connection(host, port)
    replies = _Replies(reader)
    tally.connections += 1
    frame = bytearray(encode_write_array(0, name, list(range(32_000))))
    try:
        n = 0
        while True:
            n = (n + 1) & 0xFFFF
            frame[0:2] = n.to_bytes(2, "big")
            writer.write(bytes(frame))
            await writer.drain()
            tally.requests += 1
            reply = await replies.next()
            tally.replies += 1
            if reply.msg_id != n:
                tally.wrong += 1
    finally:
        writer.close()
