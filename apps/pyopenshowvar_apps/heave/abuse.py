"""Hostile Modbus masters against the wave-platform simulator: the abuse suite's and bench's tools.

``tests/abuse/test_abuse_platform.py`` and ``bench/app_abuse.py`` attack ``kvp platform`` with:

* :class:`PlatformProcess` — ``kvp platform --port 0`` in its own process (its memory is its own);
* :func:`silent_master` — a master switches the drives and the PLC's own waves on, then
  disconnects without a word; a reader (reads never feed the watchdog) times how long the
  platform keeps moving;
* :func:`write_refusal` — one write of a register or coil by any client: the Modbus exception
  code it got (0: accepted);
* the abusers, coroutines that misbehave until cancelled and count what they see in an
  :class:`~pyopenshowvar_apps.abusekit.AttackTally`: :func:`garbage` (random frames and
  broken MBAP headers), :func:`flood` (reads back to back, as fast as answered) and :func:`idle`
  (connections that say nothing);
* :func:`probe` — the bystander: a master reading the state block, one request at a time
  (:func:`probe_process`: the same in a process of its own).

Nothing here asserts: the suite and the bench decide what is acceptable. Every wait is bounded.
"""

from __future__ import annotations

import asyncio
import random
import struct
import sys
import time
from collections.abc import Callable
from typing import Self

from ..abusekit import AppProcess, AttackTally, ChildProbe, run_child_probe
from . import registers as reg

__all__ = [
    "PlatformProcess",
    "flood",
    "garbage",
    "idle",
    "probe",
    "probe_process",
    "silent_master",
    "write_refusal",
]


class PlatformProcess(AppProcess):
    """``kvp platform --port 0 ARGS...`` in its own process."""

    def __init__(self, *args: str) -> None:
        super().__init__("platform", "--port", "0", *args, expect="platform PLC on modbus://")

    def start(self) -> Self:
        super().start()
        host, _, port = self.first.removeprefix("platform PLC on modbus://").rpartition(":")
        self.host, self.port = host, int(port)
        return self


async def _client(host: str, port: int) -> object:
    from pymodbus.client import AsyncModbusTcpClient

    client = AsyncModbusTcpClient(host, port=port, timeout=1.0, retries=0, reconnect_delay=0)
    if not await client.connect():
        client.close()
        raise ConnectionError(f"platform {host}:{port}: cannot connect")
    return client


async def silent_master(host: str, port: int, watch: float, *, run: float = 1.5) -> float:
    """Drives and the PLC's waves on, ``run`` seconds of waves with a heartbeat every 0.1 s,
    then the master disconnects. Returns the seconds the platform kept moving after its last
    write (``watch`` when it still moved at the end)."""
    from .master import PlatformClient

    async with PlatformClient(host, port) as master:
        await master.configure(watchdog=1.0)
        await master.enable(True)
        await master.wave(True)
        end = time.monotonic() + run
        while time.monotonic() < end:  # a live master: its heartbeat feeds the watchdog
            await master.heartbeat()
            await asyncio.sleep(0.1)
        await master.heartbeat()
    gone = time.monotonic()  # the master's last write, and its disconnect
    async with PlatformClient(host, port) as reader:  # reads only: they never feed the watchdog
        last = 0.0
        while (now := time.monotonic()) - gone < watch:
            state = await reader.read_state()
            if state.flag("moving"):
                last = now - gone
            await asyncio.sleep(0.02)
    return last


async def write_refusal(host: str, port: int, kind: str, address: int, value: int) -> int:
    """One write (``kind`` "register" or "coil") by a fresh client: its exception code, or 0."""
    client = await _client(host, port)
    try:
        if kind == "coil":
            response = await client.write_coil(address, bool(value), device_id=1)  # type: ignore[attr-defined]
        else:
            response = await client.write_register(address, value, device_id=1)  # type: ignore[attr-defined]
        return int(getattr(response, "exception_code", 0)) if response.isError() else 0
    finally:
        client.close()  # type: ignore[attr-defined]


def _frame(tid: int, pdu: bytes) -> bytes:
    return struct.pack(">HHHB", tid & 0xFFFF, 0, len(pdu) + 1, 1) + pdu


async def garbage(host: str, port: int, tally: AttackTally, *, seed: int = 0) -> None:
    """Connect, send one broken frame, wait briefly for an answer or the close; again."""
    rng = random.Random(seed)
    while True:
        try:
            reader, writer = await asyncio.open_connection(host, port)
        except OSError as exc:
            tally.error(f"connect: {exc}")
            await asyncio.sleep(0.01)
            continue
        tally.connections += 1
        kind = rng.randrange(5)
        if kind == 0:
            data = rng.randbytes(rng.randint(1, 600))
        elif kind == 1:  # an MBAP header announcing 65535 bytes that never come
            data = struct.pack(">HHHB", 1, 0, 0xFFFF, 1) + rng.randbytes(100)
        elif kind == 2:  # a read of 2000 registers at the end of the address space
            data = _frame(2, struct.pack(">BHH", 3, 0xFFF0, 2000))
        elif kind == 3:  # unknown function codes
            data = _frame(3, bytes([rng.randrange(0x40, 0x80)]) + rng.randbytes(4))
        else:  # a write of undefined coils, all of them
            data = _frame(4, struct.pack(">BHHB", 15, 0, 2000, 250) + bytes(250))
        writer.write(data)
        tally.bytes_sent += len(data)
        try:
            async with asyncio.timeout(0.2):
                while await reader.read(4096):
                    pass
            tally.closed_by_server += 1
        except (TimeoutError, OSError):
            pass
        finally:
            writer.close()


async def flood(host: str, port: int, tally: AttackTally) -> None:
    """Reads of the whole state block back to back, as fast as the answers come. (One at a time:
    pymodbus' server takes one frame per received segment and keeps the rest until the next
    one arrives, so a pipelining master stalls itself; that is not the attack measured here.)"""
    reader, writer = await asyncio.open_connection(host, port)
    tally.connections += 1
    answer = 9 + 2 * reg.INPUT_COUNT
    n = 0
    try:
        while True:
            n += 1
            request = _frame(n, struct.pack(">BHH", 4, 0, reg.INPUT_COUNT))
            writer.write(request)
            tally.bytes_sent += len(request)
            tally.requests += 1
            try:
                async with asyncio.timeout(2.0):
                    data = await reader.readexactly(answer)
            except TimeoutError:
                tally.error("no answer to a read within 2 s")
                continue
            except asyncio.IncompleteReadError:
                tally.closed_by_server += 1
                return
            tally.replies += int(data[:2] == request[:2])
    finally:
        writer.close()


async def idle(host: str, port: int, tally: AttackTally, *, sockets: int = 50) -> None:
    """Hold ``sockets`` connections that never send anything, until cancelled."""
    writers = []
    try:
        for _ in range(sockets):
            try:
                _, writer = await asyncio.open_connection(host, port)
            except OSError as exc:
                tally.error(f"connect: {exc}")
                continue
            tally.connections += 1
            writers.append(writer)
        await asyncio.Event().wait()
    finally:
        for writer in writers:
            writer.close()


async def probe(
    host: str, port: int, seconds: float, *, ready: Callable[[], None] | None = None
) -> list[tuple[float, float]]:
    """The bystander: read the state block one request at a time for ``seconds`` (``ready``
    is called once connected); each read as (``time.monotonic()`` when it started, round trip
    in ms). A failed read raises."""
    from .master import PlatformClient

    out: list[tuple[float, float]] = []
    async with PlatformClient(host, port, timeout=2.0) as master:
        await master.read_state()
        if ready is not None:
            ready()
        end = time.monotonic() + seconds
        while (t0 := time.monotonic()) < end:
            start = time.perf_counter()
            await master.read_state()
            out.append((t0, (time.perf_counter() - start) * 1e3))
            await asyncio.sleep(0.005)
    return out


def probe_process(host: str, port: int, seconds: float) -> ChildProbe:
    """:func:`probe` in a process of its own (``await start()``, then ``await result()``: a
    list of [monotonic start, ms])."""
    return ChildProbe(__name__, host, str(port), str(seconds), seconds=seconds)


if __name__ == "__main__":  # python -m pyopenshowvar_apps.heave.abuse HOST PORT SECONDS
    run_child_probe(
        lambda ready: probe(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), ready=ready)
    )
