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
* :func:`page_load` — ``GET /`` over a fresh connection, timed; :func:`bystander` — a
  legitimate page loading and following the live stream (:func:`bystander_process`: the same in
  a process of its own);
* :func:`axis_motion` — the robot seen over KVP for a while: how far and how fast it moved.

Nothing here asserts: the suite and the bench decide what is acceptable. Every wait is bounded.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import random
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Self

import numpy as np

from pyopenshowvar import Client

from ..abusekit import AppProcess, AttackTally, ChildProbe, run_child_probe

__all__ = [
    "CRAFTED",
    "ROGUE_WRITES",
    "AttackTally",
    "Motion",
    "WebProcess",
    "axis_motion",
    "bystander",
    "bystander_process",
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


class WebProcess(AppProcess):
    """``kvp --port KVP_PORT web --http-port 0 ARGS...`` in its own process."""

    def __init__(self, kvp_port: int, *args: str, token: str | None = None) -> None:
        extra = ["--token", token] if token else []
        super().__init__("--port", str(kvp_port), "web", "--http-port", "0", *extra, *args,
                         expect="serving on http://")  # fmt: skip
        self.token = token

    def start(self) -> Self:
        super().start()
        self.port = int(self.first.removeprefix("serving on ").rstrip("/").rpartition(":")[2])
        return self

    @property
    def ws_url(self) -> str:
        query = f"?token={self.token}" if self.token else ""
        return f"ws://127.0.0.1:{self.port}/ws{query}"


def _local(source: str | None) -> dict[str, Any]:
    """``create_connection`` arguments binding the client to ``source`` (another loopback
    address is another client address to the server)."""
    return {"local_addr": (source, 0)} if source else {}


async def rogue_page(
    ws_url: str,
    writes: tuple[tuple[str, str], ...] = ROGUE_WRITES,
    *,
    vanish: str = "close",
    timeout: float = 5.0,
    source: str | None = None,
) -> list[dict[str, Any]]:
    """Connect, send each ``(name, value)`` as a watch-list write, wait for every answer, then
    vanish (``"close"``: a closing handshake; ``"abort"``: the TCP connection just drops).
    Returns the server's answers in order (``result``, ``error`` or the close)."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    answers: list[dict[str, Any]] = []
    async with asyncio.timeout(timeout):
        ws = await connect(ws_url, max_queue=None, open_timeout=timeout, **_local(source))
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
    seconds (never finishing it); when the server closes one, connect again on the next tick
    (``interval`` later, as slowloris does). Until cancelled."""
    head = b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: " + b"a" * 10_000

    async def one() -> None:
        while True:
            try:
                reader, writer = await asyncio.open_connection(host, port, **_local(source))
            except OSError as exc:
                tally.error(f"connect: {exc}")
                await asyncio.sleep(interval)
                continue
            tally.connections += 1
            try:
                for i in range(len(head)):
                    writer.write(head[i : i + 1])
                    tally.bytes_sent += 1
                    try:
                        # the server closing shows as EOF (or data: a refusal) before the next byte
                        await asyncio.wait_for(reader.read(1024), interval)
                    except TimeoutError:
                        continue
                    break
                tally.closed_by_server += 1
            except OSError:
                tally.closed_by_server += 1
            finally:
                writer.close()
            await asyncio.sleep(interval)

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
            reader, writer = await asyncio.open_connection(host, port, **_local(source))
            try:
                writer.write(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
                data = await reader.read()
            finally:
                writer.close()
    except (OSError, TimeoutError):
        return 0, time.monotonic() - t0
    status = int(data[9:12]) if data.startswith(b"HTTP/1.1 ") and len(data) >= 12 else 0
    return status, time.monotonic() - t0


async def crafted(
    ws_url: str, message: str | bytes, *, timeout: float = 5.0, source: str | None = None
) -> tuple[int, str]:
    """Send one crafted ``message``; (close code, close reason) as the server closed, or
    (0, what it answered instead) when it kept the connection open for ``timeout`` s."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    ws = await connect(ws_url, max_queue=None, open_timeout=timeout, **_local(source))
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


async def closing_pages(
    ws_url: str, pages: int = 20, *, seed: int = 0, source: str | None = None
) -> int:
    """``pages`` pages at once that press a jog button (1 % jog override), and close or drop
    their connection after a random 20-300 ms, half each, while the server streams to them
    and answers their press. Returns the pages that connected."""
    from websockets.asyncio.client import connect
    from websockets.exceptions import WebSocketException

    rng = random.Random(seed)
    press = '{"t": "jog", "press": 1, "frame": "axis", "key": "A1", "dir": 1, "ov": 1}'

    async def one(n: int, wait: float) -> int:
        try:
            ws = await connect(ws_url, max_queue=None, open_timeout=5.0, **_local(source))
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


async def bystander(
    port: int, ws_url: str, seconds: float, *, ready: Callable[[], None] | None = None
) -> dict[str, list[list[float]]]:
    """A legitimate page for ``seconds``: ``GET /`` every 50 ms (``loads``: monotonic start,
    HTTP status, seconds) while it follows the live stream (``states``: monotonic arrival of
    each state). ``ready`` is called once the page is connected."""
    from websockets.asyncio.client import connect

    loads: list[list[float]] = []
    states: list[list[float]] = []
    ws = await connect(ws_url, max_queue=None, open_timeout=5.0)

    async def follow() -> None:
        async for raw in ws:
            if json.loads(raw).get("t") == "state":
                states.append([time.monotonic()])

    follower = asyncio.create_task(follow())
    if ready is not None:
        ready()
    end = time.monotonic() + seconds
    try:
        while (t0 := time.monotonic()) < end:
            status, took = await page_load("127.0.0.1", port)
            loads.append([t0, float(status), took])
            await asyncio.sleep(0.05)
    finally:
        follower.cancel()
        await asyncio.gather(follower, return_exceptions=True)
        await ws.close()
    return {"loads": loads, "states": states}


def bystander_process(port: int, ws_url: str, seconds: float) -> ChildProbe:
    """:func:`bystander` in a process of its own (``await start()``, then ``await result()``)."""
    return ChildProbe(__name__, str(port), ws_url, str(seconds), seconds=seconds)


if __name__ == "__main__":  # python -m pyopenshowvar_apps.web.abuse HTTP_PORT WS_URL SECONDS
    run_child_probe(
        lambda ready: bystander(int(sys.argv[1]), sys.argv[2], float(sys.argv[3]), ready=ready)
    )
