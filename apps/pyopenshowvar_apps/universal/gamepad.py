"""A gamepad or joystick as the universal input device (pygame, the ``gamepad`` extra).

The thesis used a Logitech Extreme 3D Pro (GA, §3.2.1.1) and an Xbox 360 pad (PSO, §3.2.2.1):
"each degree of freedom of the joystick corresponds to a translational axis". Sticks spring
back to the centre, so a released pad sends zero: in velocity mode the arm stops, in position
mode the tip returns to its start.

* Extreme 3D Pro (or any stick with a twist axis): forward/back → x, left/right → y, twist → z.
* Xbox-style pads: left stick → x/y, right stick vertical → z.
* Buttons: 0 (A / trigger) toggles the mode, 1 (B) the next solver, 2 (X) the next arm,
  7 (Start) quits. Unplugging the pad disconnects the device (the server stops the arm).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from .inputs import Command, InputDevice, InputSample, InputUnavailable

__all__ = ["BUTTONS", "GamepadInput", "axes_to_signal"]

#: Deflections below this are the noise of a released stick.
DEAD_BAND = 0.08
BUTTONS: dict[int, Command] = {
    0: ("mode", "toggle"), 1: ("solver", "next"), 2: ("arm", "next"), 7: ("quit", ""),
}  # fmt: skip


def axes_to_signal(name: str, axes: list[float]) -> np.ndarray:
    """The signal of a pad's raw axes (screen convention: up is negative), dead band applied."""
    from ..heave.operator import dead_band

    a = list(axes) + [0.0] * (4 - len(axes))
    twist = "3d pro" in name.lower() or "extreme" in name.lower()
    z = -a[2] if twist else -a[3]
    return np.asarray(dead_band(np.array([-a[1], -a[0], z]), DEAD_BAND))


class GamepadInput(InputDevice):  # pragma: no cover - needs a gamepad
    """The first joystick pygame sees."""

    name = "gamepad"

    def __init__(self, index: int = 0) -> None:
        self.index = index
        self._pg: Any = None
        self._stick: Any = None
        self._connected = False

    async def start(self) -> None:
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        try:
            import pygame
        except ImportError as exc:
            raise InputUnavailable(
                "the gamepad input needs pygame: pip install 'pyopenshowvar[gamepad]'"
            ) from exc
        pygame.display.init()
        pygame.joystick.init()
        if pygame.joystick.get_count() <= self.index:
            raise InputUnavailable("no gamepad connected (pygame sees no joystick)")
        self._pg = pygame
        self._stick = pygame.joystick.Joystick(self.index)
        self._stick.init()
        self._connected = True
        self.name = f"gamepad ({self._stick.get_name()})"

    def poll(self, now: float) -> InputSample | None:
        pg = self._pg
        commands: list[Command] = []
        for event in pg.event.get():
            if event.type == pg.JOYBUTTONDOWN and event.button in BUTTONS:
                commands.append(BUTTONS[event.button])
            elif event.type == getattr(pg, "JOYDEVICEREMOVED", -1):
                self._connected = False
        if not self._connected:
            return InputSample(now, np.zeros(3), connected=False)
        axes = [self._stick.get_axis(i) for i in range(min(4, self._stick.get_numaxes()))]
        return InputSample(now, axes_to_signal(self._stick.get_name(), axes), True,
                           tuple(commands))  # fmt: skip

    async def close(self) -> None:
        if self._pg is not None:
            self._pg.joystick.quit()
