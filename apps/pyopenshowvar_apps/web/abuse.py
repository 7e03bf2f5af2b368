"""Hostile pages and HTTP clients against ``kvp web``: the tools of the abuse suite and bench.

``tests/abuse/test_abuse_web.py`` and ``bench/app_abuse.py`` attack a running jog pad with:

* :func:`rogue_page` — an authorised page that writes the jog program's own variables through
  the watch list's generic ``write`` (:data:`ROGUE_WRITES`, the writes that once turned A1
  152° in 3 s after the page had gone), then vanishes;
* :func:`slowloris` — sockets that send a request head one byte at a time and never finish it;
* :func:`crafted` — one WebSocket message each of :data:`CRAFTED` (numbers that overflow,
  ``NaN``, 2000-deep arrays, a binary frame), returning how the server closed;
* :func:`closing_pages` — pages that press a jog button and go away while the server answers
  and streams to them (closing, or dropping the connection);
* :func:`page_load` — the bystander: ``GET /`` over a fresh connection, timed;
* :func:`axis_motion` — the robot seen over KVP for a while: how far and how fast it moved.

Nothing here asserts: the suite and the bench decide what is acceptable. Every wait is bounded.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import random
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pyopenshowvar import Client

__all__ = [
    "CRAFTED",
    "ROGUE_WRITES",
    "AttackTally",
    "Motion",
    "axis_motion",
    "closing_pages",
    "crafted",
    "page_load",
    "rogue_page",
    "slowloris",
]

#: The jog program's own variables as the measured attack wrote them: 100 % acceleration, a
#: 2° increment per pass (3.4 times the A1 jog speed), a deadline that never comes, axis mode.
ROGUE_WRITES: tuple[tuple[str, str], ...] = (
    ("JOG_ACC", "100"),
    ("JOG_AX", "{A1 2}"),
    ("JOG_UNTIL", "1000000"),
    ("JOG_MODE", "1"),
)

#: WebSocket messages no page sends: name -> the message (``bytes`` is a binary frame).
CRAFTED: dict[str, str | bytes] = {
    "overflowing number": '{"t": "jog", "press": 1e999, "frame": "axis", "key": "A1", "dir": 1}',
    "NaN": '{"t": "jog", "press": 1, "frame": "axis", "key": "A1", "dir": 1, "ov": NaN}',
    "Infinity": '{"t": "jog", "press": 1, "frame": "axis", "key": "A1", "dir": Infinity}',
    "2000-deep arrays": '{"t": "watch", "names": ' + "[" * 2000 + "]" * 2000 + "}",
    "binary frame": b'{"t": "release"}',
    "not JSON": "{'t': 'release'",
}


@dataclass
class AttackTally:
    """What the attackers did and saw."""

    connections: int = 0
    #: Connections the server closed (or refused) on its own.
    closed_by_server: int = 0
    bytes_sent: int = 0
    #: The attackers' own failures (a connect refused, a timeout): asserted by the suite.
    errors: int = 0
    notes: list[str] = field(default_factory=list)


async def rogue_page(
    ws_url: str,
    writes: tuple[tuple[str, str], ...] = ROGUE_WRITES,
    *,
    vanish: str = "close",
    timeout: float = 5.0,
) -> list[dict[str, Any]]:
    """Connect, send each ``(name, value)`` as a watch-list write, wait for every answer, then
    vanish (``"close"``: a closing handshake; ``"abort"``: the TCP connection just drops).
    Returns the server's answers in order (``result``, ``error`` or the close)."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    answers: list[dict[str, Any]] = []
    async with asyncio.timeout(timeout):
        ws = await connect(ws_url, max_queue=None, open_timeout=timeout)
        try:
            for n, (name, value) in enumerate(writes, 1):  # one at a time, as the page does
                await ws.send(json.dumps({"t": "write", "id": n, "name": name, "value": value}))
                while True:
                    msg = json.loads(await ws.recv())
                    if msg.get("t") in ("result", "error"):
                        answers.append(msg)
                        break
        except ConnectionClosed as exc:
            answers.append({"t": "closed", "code": exc.rcvd.code if exc.rcvd else None})
        finally:
            if vanish == "abort" and ws.transport is not None:
                ws.transport.abort()
            else:
                await ws.close()
    return answers


@dataclass
class Motion:
    """The robot's axes over a watch: travel and peak speed per axis, and the last motion."""

    travel: np.ndarray
    #: deg/s, the largest mean speed over any :data:`SPEED_WINDOW` of the watch.
    peak_speed: np.ndarray
    #: Seconds from the start of the watch to the last reading that differed from the one
    #: before it by more than ``still`` degrees (0.0: it never moved).
    last_motion: float
    samples: int


#: Speeds are averaged over this long (s): $AXIS_ACT changes once per interpolation cycle, so
#: two back-to-back reads would give a speed of one cycle's step over a read's time.
SPEED_WINDOW = 0.25


async def axis_motion(host: str, port: int, seconds: float, *, still: float = 0.01) -> Motion:
    """Read ``$AXIS_ACT`` back to back for ``seconds`` over a KVP connection of its own."""
    async with Client(host, port, timeout=2.0) as kvp:
        t0 = time.monotonic()
        first = prev = await kvp.read_joint_angles()
        window_t, window_q = t0, first
        peak, last, n = np.zeros(6), 0.0, 1
        while (now := time.monotonic()) - t0 < seconds:
            q = await kvp.read_joint_angles()
            now, n = time.monotonic(), n + 1
            if np.max(np.abs(q - prev)) > still:
                last = now - t0
            prev = q
            if now - window_t >= SPEED_WINDOW:
                peak = np.maximum(peak, np.abs(q - window_q) / (now - window_t))
                window_t, window_q = now, q
        return Motion(np.abs(prev - first), peak, last, n)


async def slowloris(
    host: str,
    port: int,
    tally: AttackTally,
    *,
    sockets: int = 80,
    interval: float = 2.0,
    source: str | None = None,
) -> None:
    """Keep ``sockets`` connections each sending a request head one byte every ``interval``
    seconds (never finishing it); reconnect when the server closes one. Until cancelled."""
    head = b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: " + b"a" * 10_000

    async def one() -> None:
        while True:
            try:
                reader, writer = await asyncio.open_connection(
                    host, port, local_addr=(source, 0) if source else None
                )
            except OSError as exc:
                tally.errors += 1
                if len(tally.notes) < 5:
                    tally.notes.append(f"connect: {exc}")
                await asyncio.sleep(interval)
                continue
            tally.connections += 1
            try:
                for i in range(len(head)):
                    writer.write(head[i : i + 1])
                    tally.bytes_sent += 1
                    try:
                        # the server closing shows as EOF (or data: a refusal) before the next byte
                        data = await asyncio.wait_for(reader.read(1024), interval)
                    except TimeoutError:
                        continue
                    tally.closed_by_server += 1
                    del data
                    break
            except OSError:
                tally.closed_by_server += 1
            finally:
                writer.close()

    tasks = [asyncio.create_task(one()) for _ in range(sockets)]
    try:
        await asyncio.gather(*tasks)
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


async def page_load(
    host: str, port: int, *, source: str | None = None, timeout: float = 15.0
) -> tuple[int, float]:
    """``GET /`` on a fresh connection: (HTTP status, or 0 when the connection failed; seconds
    to the whole response)."""
    t0 = time.monotonic()
    try:
        async with asyncio.timeout(timeout):
            reader, writer = await asyncio.open_connection(
                host, port, local_addr=(source, 0) if source else None
            )
            try:
                writer.write(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
                data = await reader.read()
            finally:
                writer.close()
    except (OSError, TimeoutError):
        return 0, time.monotonic() - t0
    status = int(data[9:12]) if data.startswith(b"HTTP/1.1 ") and len(data) >= 12 else 0
    return status, time.monotonic() - t0


async def crafted(ws_url: str, message: str | bytes, *, timeout: float = 5.0) -> tuple[int, str]:
    """Send one crafted ``message``; (close code, close reason) as the server closed, or
    (0, what it answered instead) when it kept the connection open for ``timeout`` s."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    ws = await connect(ws_url, max_queue=None, open_timeout=timeout)
    try:
        await ws.send(message)
        async with asyncio.timeout(timeout):
            while True:
                msg = json.loads(await ws.recv())
                if msg.get("t") == "error":
                    return 0, str(msg.get("message"))
    except ConnectionClosed as exc:
        return (exc.rcvd.code, exc.rcvd.reason) if exc.rcvd else (1006, "no close frame")
    except TimeoutError:
        return 0, "still open"
    finally:
        await ws.close()


async def closing_pages(ws_url: str, pages: int = 20, *, seed: int = 0) -> int:
    """``pages`` pages at once that press a jog button (1 % jog override), and close or drop
    their connection after a random 20-300 ms, half each, while the server streams to them
    and answers their press. Returns the pages that connected."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import WebSocketException

    rng = random.Random(seed)
    press = '{"t": "jog", "press": 1, "frame": "axis", "key": "A1", "dir": 1, "ov": 1}'

    async def one(n: int, wait: float) -> int:
        try:
            ws = await connect(ws_url, max_queue=None, open_timeout=5.0)
        except (OSError, TimeoutError, WebSocketException):  # beyond the server's page limit
            return 0
        with contextlib.suppress(Exception):
            await ws.send(press)
        await asyncio.sleep(wait)
        if n % 2:
            ws.transport.abort()
        else:
            with contextlib.suppress(Exception):
                async with asyncio.timeout(2.0):
                    await ws.close()
        return 1

    waits = [rng.uniform(0.02, 0.3) for _ in range(pages)]
    return sum(await asyncio.gather(*(one(n, w) for n, w in enumerate(waits))))
