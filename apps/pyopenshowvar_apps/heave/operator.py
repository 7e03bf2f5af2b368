"""The operator's input device: a gamepad, else the keyboard, else a scripted operator.

Thesis §4.2.3.1: "each degree of freedom of the joystick corresponds to a translational axis";
the stick is a *velocity* command ``i`` in [−1, 1]³ (it springs back to the centre, and the
end-effector keeps its position), scaled by ``k`` into the set-point update of eq. 4.15. Every
device is polled by the control server (``poll(t)``) and returns an :class:`OperatorCommand`:
the stick, a request to toggle the compensation, a request to quit.

* :class:`GamepadOperator` — pygame's joystick API (the standard cross-platform gamepad library;
  optional: ``pip install pygame``). Left stick x/y, right stick vertical z; button A (0) toggles
  the compensation, button B (1) quits.
* :class:`KeyboardOperator` — arrows/WASD for x/y, R/F for z, space toggles the compensation,
  q quits. A key press acts as the stick held for ``hold`` seconds (auto-repeat keeps it held).
* :class:`ScriptedOperator` — a function of time; :func:`square` is a slow square in the
  horizontal plane, :func:`hands_off` never touches the stick.

:func:`select_operator` picks one by name; ``"auto"`` takes the first that is present.
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..casestudies.devices import decode_keys
from .geometry import FloatArray

__all__ = [
    "GamepadOperator",
    "KeyboardOperator",
    "OperatorCommand",
    "OperatorInput",
    "ScriptedOperator",
    "hands_off",
    "select_operator",
    "square",
]

log = logging.getLogger(__name__)

#: Stick deflections below this are noise of a released stick.
DEAD_BAND = 0.08
_KEYS = {
    "up": (1, 0, 0), "w": (1, 0, 0), "down": (-1, 0, 0), "s": (-1, 0, 0),
    "left": (0, 1, 0), "a": (0, 1, 0), "right": (0, -1, 0), "d": (0, -1, 0),
    "r": (0, 0, 1), "f": (0, 0, -1), "pgup": (0, 0, 1), "pgdn": (0, 0, -1),
}  # fmt: skip


@dataclass
class OperatorCommand:
    stick: FloatArray = field(default_factory=lambda: np.zeros(3))
    toggle: bool = False
    quit: bool = False


class OperatorInput:
    """A device polled by the control server."""

    name = "none"

    def poll(self, t: float) -> OperatorCommand:
        return OperatorCommand()

    def close(self) -> None:
        """Release the device (restore the terminal, close the joystick)."""


def dead_band(stick: FloatArray, band: float = DEAD_BAND) -> FloatArray:
    """Zero inside ``band``, rescaled outside so the output stays continuous and reaches ±1."""
    s = np.clip(np.asarray(stick, dtype=np.float64), -1.0, 1.0)
    return np.where(np.abs(s) < band, 0.0, (s - np.sign(s) * band) / (1.0 - band))


class ScriptedOperator(OperatorInput):
    """The stick as a function of time since the first poll."""

    name = "scripted"

    def __init__(self, script: Callable[[float], FloatArray]) -> None:
        self.script = script
        self._t0: float | None = None

    def poll(self, t: float) -> OperatorCommand:
        if self._t0 is None:
            self._t0 = t
        return OperatorCommand(np.clip(self.script(t - self._t0), -1.0, 1.0))


def hands_off(t: float) -> FloatArray:
    return np.zeros(3)


def square(start: float, leg: float = 1.5, level: float = 0.2) -> Callable[[float], FloatArray]:
    """Four legs of ``leg`` seconds at ``level`` stick (+x, +y, −x, −y) from ``start`` on."""
    moves = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], dtype=np.float64)

    def script(t: float) -> FloatArray:
        k = int((t - start) // leg)
        if t < start or k >= 4:
            return np.zeros(3)
        return np.asarray(level * moves[k], dtype=np.float64)

    return script


class KeyboardOperator(OperatorInput):  # pragma: no cover - needs a terminal
    """Keys on stdin in cbreak mode (POSIX terminals)."""

    name = "keyboard"

    def __init__(self, *, hold: float = 0.15, level: float = 0.5) -> None:
        import termios
        import tty

        self.hold, self.level = hold, level
        self._fd = sys.stdin.fileno()
        self._saved: Any = termios.tcgetattr(self._fd)
        tty.setcbreak(self._fd)
        os.set_blocking(self._fd, False)
        self._until = np.zeros(3)
        self._dir = np.zeros(3)

    def poll(self, t: float) -> OperatorCommand:
        cmd = OperatorCommand()
        try:
            text = os.read(self._fd, 256).decode(errors="ignore")
        except BlockingIOError:
            text = ""
        for key in decode_keys(text):
            if key == "space":
                cmd.toggle = True
            elif key == "q":
                cmd.quit = True
            elif key in _KEYS:
                move = np.array(_KEYS[key], dtype=np.float64)
                axis = int(np.argmax(np.abs(move)))
                self._dir[axis] = move[axis]
                self._until[axis] = t + self.hold
        active = self._until > t
        cmd.stick = np.where(active, self.level * self._dir, 0.0)
        return cmd

    def close(self) -> None:
        import termios

        os.set_blocking(self._fd, True)
        termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)


class GamepadOperator(OperatorInput):  # pragma: no cover - needs a gamepad
    """The first joystick pygame sees."""

    name = "gamepad"

    def __init__(self) -> None:
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
        import pygame

        pygame.joystick.init()
        pygame.display.init()
        if pygame.joystick.get_count() == 0:
            raise LookupError("no gamepad connected")
        self._pygame = pygame
        self.stick = pygame.joystick.Joystick(0)
        self.stick.init()
        self.name = f"gamepad ({self.stick.get_name()})"

    def poll(self, t: float) -> OperatorCommand:
        pg = self._pygame
        cmd = OperatorCommand()
        for event in pg.event.get():
            if event.type == pg.JOYBUTTONDOWN:
                cmd.toggle |= event.button == 0
                cmd.quit |= event.button == 1
        axes = [self.stick.get_axis(i) for i in range(min(4, self.stick.get_numaxes()))]
        axes += [0.0] * (4 - len(axes))
        # screen convention: stick up is negative; forward (+x) is stick up
        cmd.stick = dead_band(np.array([-axes[1], -axes[0], -axes[3]]))
        return cmd

    def close(self) -> None:
        self._pygame.joystick.quit()


def select_operator(name: str, script: Callable[[float], FloatArray] = hands_off) -> OperatorInput:
    """``gamepad``, ``keyboard``, ``scripted`` or ``auto`` (the first of them that is present)."""
    if name not in ("auto", "gamepad", "keyboard", "scripted"):
        raise ValueError(f"unknown operator {name!r}: auto, gamepad, keyboard or scripted")
    if name in ("auto", "gamepad"):
        try:
            return GamepadOperator()
        except (ImportError, LookupError, OSError) as exc:
            if name == "gamepad":
                raise LookupError(f"no gamepad: {exc}") from exc
            log.info("no gamepad (%s)", exc)
    if name in ("auto", "keyboard") and sys.stdin.isatty() and os.name == "posix":
        return KeyboardOperator()
    if name == "keyboard":
        raise LookupError("the keyboard operator needs an interactive terminal")
    return ScriptedOperator(script)
