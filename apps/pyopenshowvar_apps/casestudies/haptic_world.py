"""The haptic case study's world around the robot: what the operator holds and what the app
sets up itself.

The operator's side is a 3-DOF handle (:class:`HapticDevice`) pulled by a scripted hand
(:func:`operator_script`, like the thesis' Figure 4.19). The app's own forces are a virtual
spring plane (:class:`Wall`) and a held payload, applied to the robot as ``EMU_WRENCH`` (or
handed to another environment) by :class:`World`, which also says what the true TCP force was,
for scoring the estimate.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

__all__ = ["Environment", "HapticDevice", "Truth", "Wall", "World", "operator_script"]

FloatArray = npt.NDArray[np.float64]
Environment = Callable[[FloatArray], Awaitable[None] | None]
Truth = Callable[[], npt.ArrayLike]
G = 9.81


@dataclass(frozen=True)
class Wall:
    """A plane ``position`` mm along base ``axis`` that the TCP may cross going ``direction``
    (+1: towards +axis); beyond it a spring of ``stiffness`` N/mm pushes back."""

    axis: int = 0
    position: float = 555.0
    stiffness: float = 2.0
    direction: float = 1.0

    def wrench(self, tcp: npt.ArrayLike) -> FloatArray:
        """The wrench the TCP exerts on the wall (EMU_WRENCH convention): +k·depth into it."""
        depth = (float(np.asarray(tcp, float)[self.axis]) - self.position) * self.direction
        w = np.zeros(6)
        if depth > 0:
            w[self.axis] = self.stiffness * depth * self.direction
        return w


class HapticDevice:
    """A 3-DOF handle (mm, relative to its centre) in a ±``reach`` cube: mass m, the operator's
    hand a spring-damper towards ``hand`` (N/mm, N·s/mm), plus the rendered force (N)."""

    def __init__(
        self, *, mass: float = 0.3, k_hand: float = 0.2, b_hand: float = 0.01, reach: float = 80.0
    ) -> None:
        self.mass, self.k_hand, self.b_hand, self.reach = mass, k_hand, b_hand, reach
        self.p = np.zeros(3)
        self.v = np.zeros(3)  # mm/s

    def step(self, hand: npt.ArrayLike, force: npt.ArrayLike, dt: float) -> FloatArray:
        """Integrate ``dt`` s (semi-implicit Euler in 4 ms substeps: the hand spring's period is
        ~0.25 s, so ω·h ≈ 0.1)."""
        n = max(1, math.ceil(dt / 0.004))
        h, f, sub = np.asarray(hand, float), np.asarray(force, float), dt / n
        for _ in range(n):
            total = self.k_hand * (h - self.p) - self.b_hand * self.v + f  # N
            self.v = self.v + total / self.mass * 1000.0 * sub  # N/kg = m/s² → mm/s²
            self.p = np.clip(self.p + self.v * sub, -self.reach, self.reach)
        return self.p.copy()


def operator_script(duration: float) -> Callable[[float], FloatArray]:
    """Where the operator's hand pulls the handle (mm): like Figure 4.19, lift up first, then
    sideways and down, then forward — into whatever is in front — hold, and let go."""
    keys = np.array([0.0, 0.06, 0.16, 0.22, 0.3, 0.36, 0.86, 0.9, 1.0]) * duration
    pts = np.array(
        [[0, 0, 0], [0, 0, 40], [0, 0, 40], [0, 30, -15], [0, 30, -15], [50, 0, 0], [50, 0, 0],
         [0, 0, 0], [0, 0, 0]], dtype=float,
    )  # fmt: skip

    def at(t: float) -> FloatArray:
        return np.array([np.interp(t, keys, pts[:, k]) for k in range(3)])

    return at


class World:
    """The forces the app sets up itself (a virtual wall, a held payload), where they go
    (``environment``) and what the true TCP force is for scoring (``truth``)."""

    def __init__(
        self,
        client: Any,
        environment: Environment | Literal["kvp"] | None,
        truth: Truth | None,
        wall: Wall | None,
        payload_kg: float,
    ) -> None:
        self.client, self.environment, self.truth, self.wall = client, environment, truth, wall
        self.payload = np.array([0, 0, payload_kg * G, 0, 0, 0], float)
        self.applied = np.zeros(6)

    async def release(self) -> None:
        """No force on the robot (before the run and after it), where there is an environment."""
        if self.environment is not None:
            await self.apply(np.zeros(6))

    async def apply(self, w: FloatArray) -> None:
        self.applied = w
        if self.environment == "kvp":
            names = ("FX", "FY", "FZ", "MX", "MY", "MZ")
            text = ", ".join(f"{n} {v:.4f}" for n, v in zip(names, w, strict=True))
            await self.client.write("EMU_WRENCH", "{" + text + "}")
        elif self.environment is not None:
            maybe = self.environment(w)
            if maybe is not None:
                await maybe

    def wrench_at(self, x: FloatArray) -> FloatArray:
        """The wall's push at TCP position ``x`` plus the payload's."""
        push = self.wall.wrench(x) if self.wall is not None else np.zeros(6)
        return np.asarray(push + self.payload, dtype=np.float64)

    async def follow(self, x: FloatArray) -> None:
        """Apply the wrench at ``x`` when it changed by more than 0.01 N or Nm."""
        new = self.wrench_at(x)
        if self.environment is not None and np.max(np.abs(new - self.applied)) > 0.01:
            await self.apply(new)

    def true_force(self) -> FloatArray:
        if self.truth is not None:
            return np.asarray(self.truth(), float)[:3]
        if self.environment is not None:
            return self.applied[:3].copy()
        return np.full(3, math.nan)
