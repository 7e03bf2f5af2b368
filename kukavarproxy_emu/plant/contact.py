"""Objects the simulated arm can push against: compliant boxes touched by the TCP.

An :class:`Obstacle` is an axis-aligned box in ``$ROBROOT`` (mm) with a linear spring-damper
surface (N/mm, N·s/mm): a foam block, a spring-mounted plate, a compliant wall. The contact
point is the TCP (``$TOOL``) with a probe radius. The force is unilateral (the object pushes,
never pulls) along the normal of the face the probe went in through the least; the surface is
frictionless. The plant evaluates it every physics step and applies it to link 6, so the
motor torques carry it like any other load; the force itself is ground truth for experiments
(``DynamicPlant.truth.contact``), never published through a KRL variable.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

__all__ = ["Obstacle", "contact_force"]

#: Stiffest surface accepted, N/mm: stiffer ones would need a shorter physics step.
MAX_STIFFNESS = 50.0


@dataclass(frozen=True)
class Obstacle:
    """A box: ``centre`` and ``half_size`` in mm ($ROBROOT axes), ``stiffness`` N/mm,
    ``damping`` N·s/mm, touched by a sphere of ``probe_radius`` mm around the TCP."""

    centre: tuple[float, float, float]
    half_size: tuple[float, float, float]
    stiffness: float = 2.0
    damping: float = 0.02
    probe_radius: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", tuple(float(v) for v in self.centre))
        object.__setattr__(self, "half_size", tuple(float(v) for v in self.half_size))
        values = (*self.centre, *self.half_size, self.stiffness, self.damping, self.probe_radius)
        if len(self.centre) != 3 or len(self.half_size) != 3 or not np.all(np.isfinite(values)):
            raise ValueError("an obstacle needs a finite centre and half size (3 values each)")
        if min(self.half_size) <= 0 or self.probe_radius < 0 or self.damping < 0:
            raise ValueError("obstacle half sizes must be > 0, damping and probe radius >= 0")
        if not 0 < self.stiffness <= MAX_STIFFNESS:
            raise ValueError(f"obstacle stiffness must be in (0, {MAX_STIFFNESS:g}] N/mm")

    @classmethod
    def parse(cls, spec: str) -> Obstacle:
        """``CX,CY,CZ,HX,HY,HZ[,STIFFNESS[,DAMPING[,RADIUS]]]`` (mm, N/mm, N·s/mm, mm)."""
        parts = [p for p in re.split(r"[,\s]+", spec.strip()) if p]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise ValueError(f"obstacle {spec!r}: numbers expected") from None
        if not 6 <= len(values) <= 9:
            raise ValueError(f"obstacle {spec!r}: CX,CY,CZ,HX,HY,HZ[,K[,B[,R]]] expected")
        return cls(
            (values[0], values[1], values[2]), (values[3], values[4], values[5]), *values[6:]
        )


def contact_force(obstacles: tuple[Obstacle, ...], p: FloatArray, v: FloatArray) -> FloatArray:
    """The force (N, $ROBROOT axes) the obstacles exert on a TCP at ``p`` (mm) moving at ``v``
    (mm/s); zeros when it touches none."""
    total = np.zeros(3)
    for ob in obstacles:
        rel = p - ob.centre
        depth = np.asarray(ob.half_size) + ob.probe_radius - np.abs(rel)
        if np.any(depth <= 0.0):
            continue
        axis = int(np.argmin(depth))
        normal = 1.0 if rel[axis] >= 0.0 else -1.0  # out of the face the probe came through
        push = ob.stiffness * depth[axis] - ob.damping * v[axis] * normal
        if push > 0.0:
            total[axis] += push * normal
    return total
