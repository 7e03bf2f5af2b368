"""Input devices for teleoperation: a stream of hand positions with timestamps.

The thesis drives the robot with a Leap Motion Controller, which sees a hand in a hemisphere of
about 1 m above the sensor (case study 3). We model exactly that and nothing more:

* :class:`HandDevice` — the interface: ``samples(clock)`` is an async stream of
  :class:`HandSample` (time in the control loop's clock, position in mm in the device frame,
  x forward, y left, z up, origin on the sensor, so the hemisphere is z ≥ 0, |p| ≤ 1000 mm).
  A new device is one subclass implementing ``samples``.
* :class:`ScriptedDevice` — deterministic synthetic trajectories (:func:`circle`,
  :func:`figure_eight`, :func:`step`) or a recorded CSV (:func:`replay_csv`); the tests and the
  demo use these, so runs are reproducible.
* :class:`KeyboardDevice` — a live source everyone has: arrow keys / WASD move the hand in the
  horizontal plane, R/F (or PgUp/PgDn) up/down, space recentres, q quits. It puts the terminal in
  raw mode with termios; the key→position mapping (:func:`apply_key`) is a pure function so it
  can be tested without a terminal.

Positions are returned relative to the sensor; the teleoperation maps them relative to
:attr:`HandDevice.centre` (the centre of the monitoring space, where the dead zone sits).
"""

from __future__ import annotations

import asyncio
import csv
import math
import time
from abc import ABC, abstractmethod
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = [
    "CENTRE",
    "RADIUS",
    "Clock",
    "HandDevice",
    "HandSample",
    "KeyboardDevice",
    "ScriptedDevice",
    "apply_key",
    "circle",
    "clamp_hemisphere",
    "decode_keys",
    "figure_eight",
    "replay_csv",
    "step",
    "write_csv_trajectory",
]

FloatArray = npt.NDArray[np.float64]
Trajectory = Callable[[float], FloatArray]

#: Centre of the monitoring space (mm above the sensor; a Leap sees a hand best ~25 cm up).
CENTRE = (0.0, 0.0, 250.0)
#: Radius of the observed hemisphere (mm): "a roughly hemispherical area, to about 1 m".
RADIUS = 1000.0


class Clock:
    """Control-loop time: simulated seconds when the emulator runs ``time_scale`` × faster.

    Every app, device and Δt works in this time base, so a 3 s scripted gesture lasts 3 s of
    robot time at any emulator speed factor.
    """

    def __init__(self, time_scale: float = 1.0) -> None:
        if not time_scale > 0:
            raise ValueError("time_scale must be > 0")
        self.time_scale = time_scale
        self._t0 = time.monotonic()

    def now(self) -> float:
        return (time.monotonic() - self._t0) * self.time_scale

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(max(seconds, 0.0) / self.time_scale)


@dataclass(frozen=True, slots=True)
class HandSample:
    """One hand position: ``t`` in clock seconds, ``position`` (x, y, z) mm in the device frame."""

    t: float
    position: FloatArray


def clamp_hemisphere(p: npt.ArrayLike, radius: float = RADIUS) -> FloatArray:
    """``p`` projected into the observable hemisphere (z ≥ 0, |p| ≤ radius)."""
    q = np.array(p, dtype=np.float64)
    q[2] = max(q[2], 0.0)
    norm = float(np.linalg.norm(q))
    return q * (radius / norm) if norm > radius else q


class HandDevice(ABC):
    """An input device: subclasses implement :meth:`samples`; that is the whole plug-in API."""

    name = "device"
    #: Centre of the monitoring space (mm, device frame): the dead zone's centre.
    centre: tuple[float, float, float] = CENTRE

    @abstractmethod
    def samples(self, clock: Clock) -> AsyncIterator[HandSample]:
        """Hand positions as they arrive, stamped with ``clock.now()``; ends when the device
        stops (end of a script, user quit)."""

    def close(self) -> None:  # noqa: B027 - optional hook, most devices hold nothing
        """Release what the device holds (terminal mode, files)."""


# --- scripted trajectories (offsets from the centre, mm) ---------------------------------------
def circle(radius: float = 120.0, period: float = 4.0, plane: str = "xy") -> Trajectory:
    """A circle of ``radius`` mm in ``plane`` ("xy", "xz", "yz"), starting at +radius on the
    first axis of the plane, one turn per ``period`` s."""
    i, j = ("xyz".index(plane[0]), "xyz".index(plane[1]))

    def at(t: float) -> FloatArray:
        p = np.zeros(3)
        w = 2 * math.pi * t / period
        p[i], p[j] = radius * math.cos(w), radius * math.sin(w)
        return p

    return at


def figure_eight(size: float = 120.0, period: float = 6.0, height: float = 40.0) -> Trajectory:
    """A Lissajous figure eight (1:2) in the horizontal plane with a slow vertical bob."""

    def at(t: float) -> FloatArray:
        w = 2 * math.pi * t / period
        return np.array([size * math.sin(w), size * math.sin(2 * w) / 2, height * math.sin(w)])

    return at


def step(amplitude: float = 100.0, axis: str = "x", at_time: float = 0.5) -> Trajectory:
    """A step of ``amplitude`` mm along ``axis`` at ``at_time`` s (PID step responses)."""
    k = "xyz".index(axis)

    def at(t: float) -> FloatArray:
        p = np.zeros(3)
        p[k] = amplitude if t >= at_time else 0.0
        return p

    return at


def replay_csv(path: str | Path) -> Trajectory:
    """A recorded trajectory (CSV columns ``t, x, y, z``; offsets from the centre in mm),
    linearly interpolated and held at its ends."""
    with Path(path).open(newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.DictReader(fh)]
    if not rows:
        raise ValueError(f"{path}: no samples")
    data = np.array([[float(r[k]) for k in ("t", "x", "y", "z")] for r in rows])

    def at(t: float) -> FloatArray:
        return np.array([np.interp(t, data[:, 0], data[:, k]) for k in (1, 2, 3)])

    return at


def write_csv_trajectory(path: str | Path, samples: Sequence[tuple[float, npt.ArrayLike]]) -> Path:
    """Write ``(t, (x, y, z))`` offsets as the CSV :func:`replay_csv` reads (for recordings)."""
    path = Path(path)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["t", "x", "y", "z"])
        for t, p in samples:
            w.writerow([t, *np.asarray(p, dtype=np.float64).tolist()])
    return path


class ScriptedDevice(HandDevice):
    """A trajectory played at ``rate_hz`` (Leap: ~100 Hz to the app) for ``duration`` s.

    The positions are a pure function of the clock time, so two runs give the same hand path
    whatever the scheduling jitter (:meth:`at` is what the stream samples).
    """

    name = "scripted"

    def __init__(
        self, trajectory: Trajectory, *, duration: float = 10.0, rate_hz: float = 100.0
    ) -> None:
        self.trajectory = trajectory
        self.duration = duration
        self.period = 1.0 / rate_hz

    def at(self, t: float) -> FloatArray:
        """Device-frame position (mm) at clock time ``t``."""
        return clamp_hemisphere(np.asarray(self.centre) + self.trajectory(t))

    async def samples(self, clock: Clock) -> AsyncIterator[HandSample]:
        while (t := clock.now()) <= self.duration:
            yield HandSample(t, self.at(t))
            await clock.sleep(self.period)


# --- keyboard --------------------------------------------------------------------------------
#: Escape sequences and letters → unit moves (x forward, y left, z up).
KEYMAP: dict[str, tuple[float, float, float]] = {
    "up": (1, 0, 0), "w": (1, 0, 0),
    "down": (-1, 0, 0), "s": (-1, 0, 0),
    "left": (0, 1, 0), "a": (0, 1, 0),
    "right": (0, -1, 0), "d": (0, -1, 0),
    "pageup": (0, 0, 1), "r": (0, 0, 1),
    "pagedown": (0, 0, -1), "f": (0, 0, -1),
}  # fmt: skip
_ESCAPES = {
    "\x1b[A": "up", "\x1b[B": "down", "\x1b[C": "right", "\x1b[D": "left",
    "\x1b[5~": "pageup", "\x1b[6~": "pagedown",
}  # fmt: skip


def decode_keys(text: str) -> list[str]:
    """Split raw terminal input into key names (arrow escapes, lower-cased letters, "space")."""
    keys, i = [], 0
    while i < len(text):
        for seq, name in _ESCAPES.items():
            if text.startswith(seq, i):
                keys.append(name)
                i += len(seq)
                break
        else:
            ch = text[i]
            keys.append("space" if ch == " " else ch.lower())
            i += 1
    return keys


def apply_key(
    position: npt.ArrayLike, key: str, step_mm: float = 20.0, centre: npt.ArrayLike = CENTRE
) -> FloatArray:
    """The hand position after one key press: a ``step_mm`` move, or the centre for space.

    Unknown keys leave the position unchanged; the result stays inside the hemisphere.
    """
    if key == "space":
        return np.asarray(centre, dtype=np.float64).copy()
    move = KEYMAP.get(key)
    if move is None:
        return np.asarray(position, dtype=np.float64).copy()
    return clamp_hemisphere(np.asarray(position, dtype=np.float64) + step_mm * np.asarray(move))


class KeyboardDevice(HandDevice):
    """The hand is a point moved by the keyboard (raw terminal mode on stdin; POSIX only).

    Each press moves it ``step_mm``; it stays where it is released, so in position mode the
    robot holds its pose and in velocity mode it keeps moving until the hand is recentred
    (space) — the same semantics as a hand held still over a Leap.
    """

    name = "keyboard"

    def __init__(self, *, step_mm: float = 20.0, rate_hz: float = 100.0) -> None:
        self.step_mm = step_mm
        self.period = 1.0 / rate_hz
        self.position = np.asarray(self.centre, dtype=np.float64).copy()
        self._saved: list[Any] | None = None
        self.quit = False

    async def samples(self, clock: Clock) -> AsyncIterator[HandSample]:  # pragma: no cover - tty
        import os
        import sys
        import termios
        import tty

        fd = sys.stdin.fileno()
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)  # keys arrive one by one, no echo; Ctrl-C still interrupts
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[str] = asyncio.Queue()
        loop.add_reader(fd, lambda: queue.put_nowait(os.read(fd, 64).decode(errors="ignore")))
        try:
            while not self.quit:
                while not queue.empty():
                    for key in decode_keys(queue.get_nowait()):
                        if key == "q":
                            self.quit = True
                        self.position = apply_key(self.position, key, self.step_mm, self.centre)
                yield HandSample(clock.now(), self.position.copy())
                await clock.sleep(self.period)
        finally:
            loop.remove_reader(fd)
            self.close()

    def close(self) -> None:  # pragma: no cover - tty
        if self._saved is not None:
            import sys
            import termios

            termios.tcsetattr(sys.stdin.fileno(), termios.TCSADRAIN, self._saved)
            self._saved = None
