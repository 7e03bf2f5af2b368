"""Fault injection: make the emulator misbehave on purpose so clients can test their recovery.

A :class:`Fault` says *what* goes wrong (drop, delay, split, close mid-frame, corrupt length,
wrong id) and *when*: the ``nth`` request of a connection (1-based), optionally only on
connection number ``connection`` (1-based, in accept order), at most ``count`` times (default
once; None = every time). :class:`FaultSet` is the live, thread-safe list an emulator consults
for every reply (``emu.faults.add(Fault("drop", nth=3))``); :func:`send_reply` applies the
matching faults to one encoded reply.

Command-line syntax (``--fault SPEC``, see docs/emulator.md)::

    KIND[:VALUE][@NTH][,conn=C][,count=K][,pause=S]

    drop:3              drop the reply to the 3rd request (VALUE is NTH for kinds without value)
    delay:0.5@2         delay the reply to the 2nd request by 0.5 s
    split:1@1,pause=0.01  send the 1st reply one byte at a time, 10 ms apart
    close@4,conn=2      2nd connection: half of the 4th reply, then close
    wrong-id,count=0    every reply carries a wrong id (count=0: unlimited)
"""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

__all__ = ["KINDS", "Fault", "FaultSet", "send_reply"]

log = logging.getLogger(__name__)

#: Every fault kind. "close" sends half of the reply and then closes the connection.
KINDS = ("drop", "delay", "split", "close", "corrupt-length", "wrong-id")
_ALIASES = {"close-mid-frame": "close", "corrupt": "corrupt-length", "truncate": "close"}
#: XORed into the id by "wrong-id": far from any id a client has in flight.
WRONG_ID_MASK = 0x8000


@dataclass(frozen=True, slots=True)
class Fault:
    """One injected fault; see the module docstring for the matching rules."""

    kind: str
    nth: int | None = None
    connection: int | None = None
    count: int | None = 1
    #: delay: seconds to hold the reply back.
    seconds: float = 0.0
    #: split: bytes per segment and the pause between segments.
    size: int = 1
    pause: float = 0.002

    def __post_init__(self) -> None:
        kind = _ALIASES.get(self.kind, self.kind)
        if kind not in KINDS:
            raise ValueError(f"unknown fault kind {self.kind!r} (choose from {', '.join(KINDS)})")
        object.__setattr__(self, "kind", kind)
        if self.nth is not None and self.nth < 1:
            raise ValueError("fault nth counts requests from 1")
        if self.connection is not None and self.connection < 1:
            raise ValueError("fault connection counts connections from 1")
        if self.count is not None and self.count < 1:
            raise ValueError("fault count must be >= 1 (None: unlimited)")
        if self.seconds < 0 or self.pause < 0 or self.size < 1:
            raise ValueError("fault seconds/pause must be >= 0 and size >= 1")

    def matches(self, connection: int, nth: int) -> bool:
        return (self.nth is None or self.nth == nth) and (
            self.connection is None or self.connection == connection
        )

    @classmethod
    def parse(cls, spec: str) -> Fault:
        """Parse ``KIND[:VALUE][@NTH][,key=value...]`` (keys: conn, count, pause, size)."""
        head, *options = [part.strip() for part in spec.strip().split(",")]
        try:
            nth: int | None = None
            if "@" in head:
                head, at = head.split("@", 1)
                nth = int(at)
            name, _, value = head.partition(":")
            kind = _ALIASES.get(name.strip().lower(), name.strip().lower())
            defaults = cls("drop")
            seconds, size, pause = defaults.seconds, defaults.size, defaults.pause
            connection: int | None = None
            count: int | None = 1
            if value:
                if kind == "delay":
                    seconds = float(value)
                elif kind == "split":
                    size = int(value)
                elif nth is None:
                    nth = int(value)
                else:
                    raise ValueError(f"{kind} takes no value besides @NTH")
            elif kind == "delay":
                raise ValueError("delay needs a duration, e.g. delay:0.5@2")
            for option in options:
                key, sep, text = option.partition("=")
                key = key.strip().lower()
                if not sep:
                    raise ValueError(f"option {option!r} is not key=value")
                if key in ("conn", "connection"):
                    connection = int(text)
                elif key == "count":
                    count = None if text.strip() in ("0", "all") else int(text)
                elif key == "pause":
                    pause = float(text)
                elif key == "size":
                    size = int(text)
                else:
                    raise ValueError(f"unknown option {key!r}")
            return cls(kind, nth, connection, count, seconds=seconds, size=size, pause=pause)
        except ValueError as exc:
            raise ValueError(f"bad fault spec {spec!r}: {exc}") from None


@dataclass(slots=True)
class _Armed:
    fault: Fault
    remaining: int | None


class FaultSet:
    """The faults currently armed on an emulator. Safe to change from any thread."""

    def __init__(self, faults: Sequence[Fault] = ()) -> None:
        self._lock = threading.Lock()
        self._armed = [_Armed(f, f.count) for f in faults]
        #: How many times a fault fired (for tests and logs).
        self.fired = 0

    def add(self, fault: Fault) -> Fault:
        with self._lock:
            self._armed.append(_Armed(fault, fault.count))
        return fault

    def remove(self, fault: Fault) -> None:
        with self._lock:
            self._armed = [a for a in self._armed if a.fault is not fault]

    def clear(self) -> None:
        with self._lock:
            self._armed.clear()

    def __bool__(self) -> bool:
        # Read without the lock on the hot path: a list's truth value is one atomic look-up.
        return bool(self._armed)

    def __len__(self) -> int:
        return len(self._armed)

    def __iter__(self) -> Iterator[Fault]:
        with self._lock:
            return iter([a.fault for a in self._armed])

    def match(self, connection: int, nth: int) -> list[Fault]:
        """The faults for request ``nth`` of ``connection``; each use is counted down."""
        hits: list[Fault] = []
        with self._lock:
            for armed in self._armed:
                if armed.fault.matches(connection, nth):
                    hits.append(armed.fault)
                    if armed.remaining is not None:
                        armed.remaining -= 1
            if hits:
                self._armed = [a for a in self._armed if a.remaining != 0]
                self.fired += len(hits)
        return hits


async def send_reply(
    transport: asyncio.WriteTransport, frame: bytes, faults: Sequence[Fault]
) -> bool:
    """Write one encoded reply through ``faults``; False when the connection was closed."""
    kinds = {f.kind for f in faults}
    for fault in faults:
        if fault.kind == "delay":
            await asyncio.sleep(fault.seconds)
    if "drop" in kinds:
        log.info("fault: dropping reply %s", frame[:2].hex())
        return True
    data = bytearray(frame)
    if "wrong-id" in kinds:
        data[0] ^= WRONG_ID_MASK >> 8
    if "corrupt-length" in kinds:
        # One less than the truth: a strict client sees an inconsistent frame at once, and the
        # byte left over desynchronises the stream like a real corruption would.
        length = (int.from_bytes(data[2:4], "big") - 1) & 0xFFFF
        data[2:4] = length.to_bytes(2, "big")
    if transport.is_closing():
        return False
    if "close" in kinds:
        transport.write(bytes(data[: max(1, len(data) // 2)]))
        transport.close()
        log.info("fault: closed the connection in the middle of a reply")
        return False
    split = next((f for f in faults if f.kind == "split"), None)
    if split is None:
        transport.write(bytes(data))
        return True
    for start in range(0, len(data), split.size):
        if transport.is_closing():
            return False
        transport.write(bytes(data[start : start + split.size]))
        if start + split.size < len(data):
            await asyncio.sleep(split.pause)
    return True
