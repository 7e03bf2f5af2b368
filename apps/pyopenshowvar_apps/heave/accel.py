"""The accelerometer on the platform and its Arduino board: sensor model, firmware, serial link.

Thesis §4.2.3.1: an accelerometer on the platform, read by an Arduino Uno that filters the raw
data and sends roll and pitch to the server over USB. We model all three parts:

* **sensor**: the specific force in the plate's frame, f = Rᵀ·(a − g), in g, plus white noise
  (default σ = 0.01 g per axis, a cheap MEMS part with some vibration). With R = Rot_y(θ)·Rot_x(φ)
  at rest f = (−sinθ, sinφ·cosθ, cosφ·cosθ); the heave acceleration adds to the vertical.
* **firmware** (what ``arduino/accel_stream.ino`` does on the board): a first-order low-pass
  on each axis (default cut-off 5 Hz), then φ = atan2(f_y, f_z), θ = atan2(−f_x, √(f_y² + f_z²)),
  at 100 Hz;
* **link**: USB serial at 115200 Bd, one ASCII line per sample, ``<millis>,<roll>,<pitch>\\n``
  (degrees with 3 decimals; 20-odd bytes, 100 Hz needs a fifth of the line's capacity).

The simulator writes the lines into a pseudo-terminal, so the server opens the simulated board
exactly like the real one, as a serial device (``/dev/pts/N`` instead of ``/dev/ttyACM0``)
through pyserial. :class:`AccelReader` reads it without a thread (the event loop watches the
file descriptor) and keeps only the latest sample; its line buffer is bounded.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .geometry import PlatformPose

__all__ = ["AccelFirmware", "AccelReader", "AccelSample", "format_line", "parse_line"]

log = logging.getLogger(__name__)

G = 9.80665
#: Longest line accepted; longer runs without a newline are dropped as garbage.
MAX_LINE = 96


@dataclass(frozen=True)
class AccelSample:
    """Roll and pitch (deg) from the board, its ``millis()`` and the local receive time."""

    millis: int
    roll: float
    pitch: float
    received: float


def format_line(millis: int, roll: float, pitch: float) -> bytes:
    return f"{millis},{roll:.3f},{pitch:.3f}\n".encode("ascii")


def parse_line(line: bytes) -> tuple[int, float, float]:
    """``millis,roll,pitch`` → values; ValueError for anything else."""
    parts = line.strip().split(b",")
    if len(parts) != 3:
        raise ValueError(f"expected millis,roll,pitch, got {line[:40]!r}")
    millis, roll, pitch = int(parts[0]), float(parts[1]), float(parts[2])
    if not (math.isfinite(roll) and math.isfinite(pitch)) or abs(roll) > 90 or abs(pitch) > 90:
        raise ValueError(f"angles out of range in {line[:40]!r}")
    return millis, roll, pitch


class AccelFirmware:
    """Sensor + the board's filter: feed the true motion, get the angles it would send."""

    def __init__(
        self,
        *,
        noise: float = 0.01,
        cutoff: float = 5.0,
        rate: float = 100.0,
        seed: int | None = None,
    ) -> None:
        if not (noise >= 0 and cutoff > 0 and rate > 0):
            raise ValueError("noise >= 0, cutoff > 0 and rate > 0 are required")
        self.noise, self.rate = noise, rate
        self._alpha = 1.0 - math.exp(-2.0 * math.pi * cutoff / rate)
        self._rng = np.random.default_rng(seed)
        self._filtered: np.ndarray[Any, np.dtype[np.float64]] | None = None

    def raw(
        self, pose: PlatformPose, heave_accel_mm_s2: float = 0.0
    ) -> np.ndarray[Any, np.dtype[np.float64]]:
        """Specific force in the sensor's axes (g), with noise."""
        phi, theta = math.radians(pose.phi), math.radians(pose.theta)
        up = 1.0 + heave_accel_mm_s2 / 1000.0 / G  # world-vertical specific force, g
        f = up * np.array(
            [-math.sin(theta), math.sin(phi) * math.cos(theta), math.cos(phi) * math.cos(theta)]
        )
        return f + self._rng.normal(0.0, self.noise, 3)

    def sample(self, pose: PlatformPose, heave_accel_mm_s2: float = 0.0) -> tuple[float, float]:
        """One 1/rate step of the board: roll, pitch (deg) after the low-pass."""
        raw = self.raw(pose, heave_accel_mm_s2)
        if self._filtered is None:
            self._filtered = raw
        else:
            self._filtered = self._filtered + self._alpha * (raw - self._filtered)
        fx, fy, fz = self._filtered
        roll = math.degrees(math.atan2(fy, fz))
        pitch = math.degrees(math.atan2(-fx, math.hypot(fy, fz)))
        return roll, pitch


class AccelReader:
    """Reads the board's lines from a serial device (real or a simulator's pty)."""

    def __init__(self, port: str, *, baudrate: int = 115200) -> None:
        self.port = port
        self.baudrate = baudrate
        self.latest: AccelSample | None = None
        #: Called with every sample parsed (the control server feeds its estimator with it).
        self.on_sample: Callable[[AccelSample], None] | None = None
        self.received = 0
        self.rejected = 0
        self._buffer = bytearray()
        #: False from :meth:`open` until the first line end: bytes before it are the tail of a
        #: line the board sent before we listened, not a line of its own
        self._synced = True
        self._serial: Any = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._changed = asyncio.Event()

    async def open(self, timeout: float = 2.0) -> AccelReader:
        """Open the device and start reading; waits up to ``timeout`` for the first sample."""
        import serial  # pyserial

        try:
            self._serial = serial.Serial(self.port, self.baudrate, timeout=0)
        except (serial.SerialException, OSError) as exc:
            raise ConnectionError(f"accelerometer {self.port}: {exc}") from exc
        # What the port buffered before we opened it is stale (old samples) and may begin or
        # end in the middle of a line, like what arrives at once: both are dropped, not
        # counted as rejected lines.
        self._serial.reset_input_buffer()
        self._buffer.clear()
        self._synced = False
        self._loop = asyncio.get_running_loop()
        self._loop.add_reader(self._serial.fileno(), self._on_readable)
        try:
            await asyncio.wait_for(self._changed.wait(), timeout)
        except TimeoutError:
            self.close()
            raise TimeoutError(
                f"no accelerometer line from {self.port} within {timeout} s"
            ) from None
        return self

    def close(self) -> None:
        if self._serial is not None:
            if self._loop is not None:
                self._loop.remove_reader(self._serial.fileno())
            self._serial.close()
            self._serial = None

    async def __aenter__(self) -> AccelReader:
        return await self.open()

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    def _on_readable(self) -> None:
        try:
            chunk = self._serial.read(4096)
        except Exception as exc:  # device unplugged: stop watching, keep the last sample
            log.warning("accelerometer %s: %s", self.port, exc)
            self.close()
            return
        self.feed(chunk, time.monotonic())

    def feed(self, chunk: bytes, now: float) -> None:
        """Take received bytes: complete lines update :attr:`latest`; bounded buffering."""
        if not self._synced:
            _torn, newline, chunk = chunk.partition(b"\n")
            if not newline:  # still inside the first, partial line
                return
            self._synced = True
        self._buffer += chunk
        *lines, rest = bytes(self._buffer).split(b"\n")
        if len(rest) > MAX_LINE:
            self.rejected += 1
            rest = b""
        self._buffer = bytearray(rest)
        for line in lines:  # at most one read (4 kB) of lines: bounded work per event
            try:
                millis, roll, pitch = parse_line(line)
            except ValueError:
                self.rejected += 1
                continue
            self.latest = AccelSample(millis, roll, pitch, now)
            self.received += 1
            if self.on_sample is not None:
                self.on_sample(self.latest)
        if lines:
            self._changed.set()
