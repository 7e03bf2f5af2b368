"""The universal input device: anything that yields a 3-vector signal, polled by the server.

The thesis' input device "sends a vector signal with no semantic, s" that the server reads as
a desired position or velocity (eqs. 2.7, 2.8). Here a device is an :class:`InputDevice`:
``poll(now)`` returns the latest :class:`InputSample` — the signal in [−1, 1]³ (zero when
released), when it was produced, whether the device is still connected, and run-time commands
(switch arm, solver or mode; quit). The server stops the arm when the device disconnects or
falls silent (no fresh sample within its deadline), so a device must produce samples at its own
rate while it is in use.

Devices: :class:`ScriptedInput` (a function of time, for tests and demos), :class:`KeyboardInput`
(a terminal), :class:`LeapInput` (the Leap-style hand of the teleoperation case study),
:class:`~.gamepad.GamepadInput` (pygame) and :class:`~.web.WebInput` (the web jog pad's
page). Adding one is a subclass with ``start``, ``poll`` and ``close`` (docs/universal.md).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import sys
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .backend import FloatArray

__all__ = [
    "InputDevice",
    "InputSample",
    "InputUnavailable",
    "KeyboardInput",
    "LeapInput",
    "ScriptedInput",
    "circle",
    "hold",
    "square",
]

Command = tuple[str, str]


class InputUnavailable(RuntimeError):
    """The device cannot be used (missing library, nothing connected): one line saying why."""


@dataclass(frozen=True)
class InputSample:
    """One reading: ``t`` (the server's monotonic clock, s), ``signal`` in [−1, 1]³."""

    t: float
    signal: FloatArray
    connected: bool = True
    commands: tuple[Command, ...] = ()


class InputDevice(ABC):
    """A device the server polls (see the module docstring)."""

    name = "device"

    async def start(self) -> None:  # noqa: B027 - optional hook
        """Open the device; raise :class:`InputUnavailable` if it cannot be used."""

    @abstractmethod
    def poll(self, now: float) -> InputSample | None:
        """The latest sample (None before the first one)."""

    async def close(self) -> None:  # noqa: B027 - optional hook
        """Release the device (restore the terminal, close the joystick)."""


# --- scripted ------------------------------------------------------------------------------
Script = Callable[[float], Sequence[float]]


def circle(level: float = 0.5, period: float = 4.0) -> Script:
    """The signal going round a horizontal circle of radius ``level`` (starts at +x)."""
    w = 2 * math.pi / period
    return lambda t: (level * math.cos(w * t), level * math.sin(w * t), 0.0)


def square(level: float = 0.5, leg: float = 1.0) -> Script:
    """+x, +y, −x, −y for ``leg`` seconds each, then released."""
    legs = ((1, 0, 0), (0, 1, 0), (-1, 0, 0), (0, -1, 0))

    def at(t: float) -> Sequence[float]:
        k = int(t // leg)
        return tuple(level * v for v in legs[k]) if 0 <= k < 4 else (0.0, 0.0, 0.0)

    return at


def hold(vector: Sequence[float], until: float = math.inf) -> Script:
    """A constant deflection until ``until`` s, then released."""
    v = tuple(float(x) for x in vector)
    return lambda t: v if t < until else (0.0, 0.0, 0.0)


class ScriptedInput(InputDevice):
    """``script(t)`` for ``duration`` seconds from the first poll; afterwards the device
    ``end``\\ s: ``"silent"`` (its last sample grows stale: the server's deadline stops the
    arm), ``"disconnect"`` (it reports itself gone) or ``"release"`` (zero signal, still
    there). ``commands`` are ``(t, key, value)`` switches delivered once each at time t."""

    name = "script"

    def __init__(
        self,
        script: Script,
        *,
        duration: float = math.inf,
        end: str = "release",
        commands: Sequence[tuple[float, str, str]] = (),
    ) -> None:
        if end not in ("silent", "disconnect", "release"):
            raise ValueError(f"end must be silent, disconnect or release, not {end!r}")
        self.script, self.duration, self.end = script, duration, end
        self.t0: float | None = None
        self._pending = sorted(commands)
        self._last: InputSample | None = None

    def poll(self, now: float) -> InputSample | None:
        if self.t0 is None:
            self.t0 = now
        t = now - self.t0
        if t > self.duration:
            if self.end == "silent":
                return self._last
            if self.end == "disconnect":
                return InputSample(now, np.zeros(3), connected=False)
            return InputSample(now, np.zeros(3))
        due = tuple((k, v) for at, k, v in self._pending if at <= t)
        self._pending = [c for c in self._pending if c[0] > t]
        s = np.clip(np.asarray(self.script(t), dtype=np.float64), -1.0, 1.0)
        self._last = InputSample(now, s, True, due)
        return self._last


# --- keyboard ------------------------------------------------------------------------------
#: Run-time commands on the keyboard (and what the page's buttons send).
KEY_COMMANDS: dict[str, Command] = {
    "m": ("mode", "toggle"), "n": ("solver", "next"), "b": ("arm", "next"), "q": ("quit", ""),
}  # fmt: skip


class KeyboardInput(InputDevice):
    """Arrows/WASD move in x/y, R/F (PgUp/PgDn) in z, ``+``/``-`` change the level, M toggles
    the mode, N the solver, B the arm, Q quits. A terminal reports presses, not releases: a
    key counts as held for ``hold`` seconds after its last (auto-repeated) press."""

    name = "keyboard"

    def __init__(self, *, hold: float = 0.6, level: float = 0.5) -> None:
        self.hold, self.level = hold, level
        self._until = np.zeros(3)
        self._dir = np.zeros(3)
        self._saved: Any = None
        self._fd = -1

    async def start(self) -> None:  # pragma: no cover - needs a terminal
        if not sys.stdin.isatty():
            raise InputUnavailable("the keyboard input needs a terminal (stdin is not a tty)")
        import termios
        import tty

        self._fd = sys.stdin.fileno()
        self._saved = termios.tcgetattr(self._fd)
        tty.setcbreak(self._fd)
        os.set_blocking(self._fd, False)

    def keys(self, text: str, now: float) -> tuple[Command, ...]:
        """Apply raw terminal input (pure: tested without a terminal)."""
        from ..casestudies.devices import KEYMAP, decode_keys

        commands = []
        for key in decode_keys(text):
            if key in KEY_COMMANDS:
                commands.append(KEY_COMMANDS[key])
            elif key in ("+", "="):
                self.level = min(1.0, self.level + 0.1)
            elif key == "-":
                self.level = max(0.1, self.level - 0.1)
            elif key in KEYMAP:
                move = np.array(KEYMAP[key], dtype=np.float64)
                axis = int(np.argmax(np.abs(move)))
                self._dir[axis] = move[axis]
                self._until[axis] = now + self.hold
        return tuple(commands)

    def poll(self, now: float) -> InputSample | None:
        text = ""
        if self._fd >= 0:  # pragma: no cover - needs a terminal
            with contextlib.suppress(BlockingIOError):
                text = os.read(self._fd, 256).decode(errors="ignore")
        commands = self.keys(text, now)
        signal = np.where(self._until > now, self.level * self._dir, 0.0)
        return InputSample(now, signal, True, commands)

    async def close(self) -> None:  # pragma: no cover - needs a terminal
        if self._saved is not None:
            import termios

            os.set_blocking(self._fd, True)
            termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)
            self._saved = None


# --- the Leap-style hand -------------------------------------------------------------------
class LeapInput(InputDevice):
    """The teleoperation case study's hand device (:mod:`..casestudies.devices`): the hand's
    offset from the centre of the sensor's space, outside the 4 cm dead zone, over ``reach``
    mm is the signal. The stream ending (script over, hand gone) makes the device silent."""

    name = "leap"

    def __init__(self, hand: Any, *, reach: float = 200.0) -> None:
        from ..casestudies.devices import Clock

        self.hand, self.reach = hand, reach
        self._clock = Clock()
        self._task: asyncio.Task[None] | None = None
        self._latest: InputSample | None = None

    async def start(self) -> None:
        self._task = asyncio.create_task(self._read(), name="leap-input")

    async def _read(self) -> None:
        from ..casestudies.teleop import dead_zone

        async for sample in self.hand.samples(self._clock):
            offset = dead_zone(np.asarray(sample.position) - np.asarray(self.hand.centre))
            signal = np.clip(offset / self.reach, -1.0, 1.0)
            self._latest = InputSample(time.monotonic(), signal)

    def poll(self, now: float) -> InputSample | None:
        if self._task is not None and self._task.done() and not self._task.cancelled():
            self._task.result()  # a failed device raises here, in the server
        return self._latest

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        self.hand.close()
