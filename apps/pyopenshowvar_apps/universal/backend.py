"""What the control server drives: an arm that takes joint velocity commands and reports θ_a.

The thesis' server forwards its set-points to "the visualisation environment" and gets "the
actual joint angles θ_a and joint velocities θ̇_a" back (§2.2.2); in its section 4 the same
architecture drives the OSC crane simulator (protobuf) and, through JOpenShowVar, real KUKA
arms. Here each of those is an :class:`ArmBackend`:

* :class:`~.sim.SimulatedArm` — an arm simulated in this process (MuJoCo where the arm
  description has inertials, else a kinematic simulation of its drives);
* :class:`~.protolink.ProtoArm` — an external simulator over TCP with the thesis' protobuf
  messages (and :class:`~.protolink.StandInSimulator`, the small one shipped for tests);
* :class:`~.kvparm.KvpArm` — a KUKA robot (or the emulator) over KVP, through the shipped
  KVP_JOG program.

A backend takes joint **velocity** commands (deg/s; mm/s for prismatic joints), the one
interface hydraulic valves, drives in velocity mode and a KRC's jog increments share.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from pyopenshowvar.arms import Arm

__all__ = ["ArmBackend", "BackendError", "JointState"]

FloatArray = npt.NDArray[np.float64]


class BackendError(RuntimeError):
    """The arm behind the server failed or refused (one line saying why)."""


@dataclass(frozen=True)
class JointState:
    """θ_a (deg, mm) and θ̇_a (deg/s, mm/s) at time ``t`` (the backend's clock, s)."""

    t: float
    q: FloatArray
    qdot: FloatArray


class ArmBackend(ABC):
    """An arm the server drives (see the module docstring)."""

    #: Shown in the status line and the 3D view.
    name = "arm"
    #: Whether :meth:`set_arm` may change the arm at run time (a simulator: yes; a KRC: no).
    switchable = False

    def __init__(self, arm: Arm) -> None:
        self.arm = arm

    def speed_caps(self) -> FloatArray | None:
        """Joint speeds this arm may be commanded at, if lower than the arm's own limits."""
        return None

    @abstractmethod
    async def start(self) -> JointState:
        """Connect or start; returns the first state."""

    @abstractmethod
    async def feedback(self) -> JointState:
        """The latest θ_a, θ̇_a."""

    @abstractmethod
    async def command(self, u: FloatArray, dt: float) -> None:
        """Joint velocity command for about the next ``dt`` seconds."""

    @abstractmethod
    async def stop(self) -> None:
        """Stop now: zero velocity (the arm keeps its position)."""

    async def set_arm(self, arm: Arm) -> JointState:
        """Change the arm (simulators only)."""
        raise BackendError(f"{self.name}: the arm cannot be changed at run time")

    async def close(self) -> None:  # noqa: B027 - optional hook
        """Release connections; the arm is stopped first by the server."""
