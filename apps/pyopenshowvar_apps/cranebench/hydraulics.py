"""The crane's hydraulics: valve-controlled cylinders and a slewing motor, with their limits.

A deliberately simple model (the thesis models the hydraulics but prints no parameters):

* **valve**: a proportional directional valve; its spool ``u`` ∈ [−1, 1] follows the command
  as a first-order lag of time constant ``valve_tau`` (a typical proportional valve's
  bandwidth of a few hertz). Flow ``Q = u·Q_max`` (rated flow at full spool; the pressure
  drop across the valve is taken as constant, so flow does not fall with load);
* **cylinder**: incompressible oil turns flow into rod speed, ``v = Q/A_p`` extending and
  ``Q/A_r`` retracting (piston and annulus areas of the bore and rod diameters); the
  cylinder's length follows the lever geometry of its two mounting points,
  ``L(q) = √(a² + b² − 2ab·cos(φ0 + q))``, and its lever arm is ``r(q) = dL/dq``, so the joint
  sees ``τ = F·r`` and the cylinder moves at ``v = r·q̇``;
* **relief valve**: the pressure never exceeds ``p_relief``, so the rod force is limited to
  ``p_relief·A_p`` pushing and ``p_relief·A_r`` pulling: a load above it makes the cylinder
  yield (the joint then moves with the load, the relief valve open);
* **slewing motor**: a hydraulic motor of displacement ``D`` through a pinion/slew-ring
  ratio ``N``: ``ω = Q/(D·N)``, torque limit ``η·Δp_max·D·N``.

How the oil column enforces the flow: a stiff damper ``F = c_h·(v_valve − v)`` (saturated by
the relief limits) stands in for the incompressible column; MuJoCo integrates it implicitly
(``implicitfast``) so the stiffness needs no tiny time step. ``c_h`` is chosen so the column
settles in a few milliseconds under the link inertias, faster than the valve.

Every number here is this toolkit's assumption for a crane of this size (bores, rods and the
250 bar relief pressure are common catalogue values of mobile/marine crane cylinders; the
thesis gives none); docs/maritime.md tabulates them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

__all__ = ["Cylinder", "Hydraulics", "SlewMotor", "Valve"]

FloatArray = npt.NDArray[np.float64]
LPM = 1.0 / 60000.0  # litres per minute in m³/s
BAR = 1.0e5  # Pa


@dataclass(frozen=True)
class Valve:
    """A proportional valve: rated flow (L/min) and the spool's first-order time constant (s)."""

    q_max_lpm: float
    tau: float = 0.05

    @property
    def q_max(self) -> float:
        """Rated flow in m³/s."""
        return self.q_max_lpm * LPM


@dataclass(frozen=True)
class Cylinder:
    """A double-acting cylinder between two links: bore and rod (m), mounting geometry
    ``a``, ``b`` (m, distances of the two pins from the joint) and ``phi0`` (rad, the angle
    between them at q = 0), its valve, relief pressure (bar) and column damping c_h (N·s/m)."""

    bore: float
    rod: float
    a: float
    b: float
    phi0: float
    valve: Valve
    p_relief_bar: float = 250.0
    damping: float = 5.0e6

    @property
    def area_piston(self) -> float:
        return math.pi * self.bore**2 / 4.0

    @property
    def area_annulus(self) -> float:
        return math.pi * (self.bore**2 - self.rod**2) / 4.0

    @property
    def force_push(self) -> float:
        """Largest extending force (N): relief pressure on the piston area."""
        return self.p_relief_bar * BAR * self.area_piston

    @property
    def force_pull(self) -> float:
        """Largest retracting force (N): relief pressure on the annulus area."""
        return self.p_relief_bar * BAR * self.area_annulus

    def length(self, q: float) -> float:
        """Pin-to-pin length (m) at joint angle ``q`` (rad)."""
        phi = self.phi0 + q
        return math.sqrt(self.a**2 + self.b**2 - 2.0 * self.a * self.b * math.cos(phi))

    def lever(self, q: float) -> float:
        """r(q) = dL/dq (m/rad): the joint torque per newton of rod force."""
        return self.a * self.b * math.sin(self.phi0 + q) / self.length(q)

    def rod_speed(self, spool: float) -> float:
        """Rod speed (m/s, + extending) the valve's flow gives at ``spool``."""
        q = spool * self.valve.q_max
        return q / (self.area_piston if q >= 0.0 else self.area_annulus)

    def torque_range(self, q: float) -> tuple[float, float]:
        """The joint torque limits (N·m) the relief valve allows at ``q``."""
        r = self.lever(q)
        lo, hi = -self.force_pull * r, self.force_push * r
        return (min(lo, hi), max(lo, hi))


@dataclass(frozen=True)
class SlewMotor:
    """The slewing drive: motor displacement (cm³/rev), gear ratio, pressure limit (bar),
    mechanical efficiency, its valve and the column damping in joint space (N·m·s/rad)."""

    displacement_cc: float
    ratio: float
    valve: Valve
    dp_max_bar: float = 250.0
    efficiency: float = 0.9
    damping: float = 2.0e6

    @property
    def d_rad(self) -> float:
        """Displacement per radian of the motor shaft (m³/rad)."""
        return self.displacement_cc * 1e-6 / (2.0 * math.pi)

    @property
    def torque_max(self) -> float:
        """Largest slewing torque (N·m) at the slew ring."""
        return self.efficiency * self.dp_max_bar * BAR * self.d_rad * self.ratio

    def joint_speed(self, spool: float) -> float:
        """Slewing speed (rad/s) the valve's flow gives at ``spool``."""
        return spool * self.valve.q_max / (self.d_rad * self.ratio)


@dataclass(frozen=True)
class Hydraulics:
    """The knuckle-boom crane's three drives: slewing motor, boom and jib cylinders."""

    slew: SlewMotor = field(
        default_factory=lambda: SlewMotor(500.0, 120.0, Valve(120.0, 0.05), damping=2.0e6)
    )
    boom: Cylinder = field(
        default_factory=lambda: Cylinder(
            0.20, 0.14, 2.0, 3.0, math.radians(50.0), Valve(400.0, 0.05), damping=2.0e7
        )
    )
    jib: Cylinder = field(
        default_factory=lambda: Cylinder(
            0.16, 0.10, 2.2, 1.2, math.radians(155.0), Valve(250.0, 0.05), damping=1.0e7
        )
    )

    def joint_speeds(self, spool: FloatArray, q: FloatArray) -> FloatArray:
        """Joint speeds (rad/s) the valves ask for at spools ``spool`` and angles ``q`` (rad)."""
        w0 = self.slew.joint_speed(float(spool[0]))
        w1 = self.boom.rod_speed(float(spool[1])) / self.boom.lever(float(q[1]))
        w2 = self.jib.rod_speed(float(spool[2])) / self.jib.lever(float(q[2]))
        return np.array([w0, w1, w2])

    def torque_ranges(self, q: FloatArray) -> FloatArray:
        """Per joint (lo, hi) torque limits (N·m) at angles ``q`` (rad): ``(3, 2)``."""
        m = self.slew.torque_max
        return np.array(
            [(-m, m), self.boom.torque_range(float(q[1])), self.jib.torque_range(float(q[2]))]
        )

    def joint_damping(self, q: FloatArray) -> FloatArray:
        """The oil column's damping in joint space (c_h·r² for the cylinders)."""
        return np.array([
            self.slew.damping,
            self.boom.damping * self.boom.lever(float(q[1])) ** 2,
            self.jib.damping * self.jib.lever(float(q[2])) ** 2,
        ])  # fmt: skip

    def rod_forces(self, tau: FloatArray, q: FloatArray) -> FloatArray:
        """Cylinder rod forces (N) behind the boom and jib torques: ``(2,)``."""
        return np.array(
            [tau[1] / self.boom.lever(float(q[1])), tau[2] / self.jib.lever(float(q[2]))]
        )
