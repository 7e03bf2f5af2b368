"""Velocity profiles of the simulated controller: pure functions of time, no I/O, no store.

Every motion is described by a scalar path parameter ``s`` that runs from 0 to 1 along a
trapezoidal velocity profile (:class:`Trapezoid`); the motion's displacement at time ``t`` is
``s(t)`` times its full displacement. For a PTP that displacement is the axis vector ``Δq``, so
all axes start and stop together and have the same profile shape (phase synchronisation, the
way a KRC4 plans a synchronous PTP); for a LIN it is the Cartesian offset plus a rotation.

The limits of ``s`` are the tightest of the per-axis (or per-Cartesian-quantity) limits divided
by the distance each one has to travel, so no axis ever exceeds its own speed or acceleration
limit, and the axis that needs the most time sets the duration. Overrides are not baked in: the
kernel plans at 100 % and runs the profile's clock at ``$OV_PRO`` % (time scaling), which
scales every speed by the override and every acceleration by its square, as a KRC does.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

__all__ = ["Trapezoid", "ptp_profile", "scalar_limits"]

#: Distances below this (deg or mm) count as zero: a zero-length segment takes no time.
EPS = 1e-9


@dataclass(frozen=True, slots=True)
class Trapezoid:
    """A rest-to-rest trapezoidal (or triangular) profile of ``s`` from 0 to 1.

    ``v`` and ``a`` are the peak speed and the acceleration of ``s`` (1/s, 1/s²). ``t_acc`` is
    the length of the acceleration ramp and equally of the deceleration ramp, ``duration`` the
    whole profile. A zero-length profile has ``duration == 0``.
    """

    v: float
    a: float
    t_acc: float
    duration: float

    @classmethod
    def plan(cls, v_max: float, a_max: float) -> Trapezoid:
        """The time-optimal profile covering ``s = 0..1`` with these limits (inf = no motion)."""
        if math.isinf(v_max) and math.isinf(a_max):
            return cls(0.0, 0.0, 0.0, 0.0)
        if v_max <= 0 or a_max <= 0:
            raise ValueError("speed and acceleration limits must be positive")
        if v_max * v_max / a_max <= 1.0:  # reaches full speed: accelerate, cruise, decelerate
            t_acc = v_max / a_max
            return cls(v_max, a_max, t_acc, 1.0 / v_max + t_acc)
        t_acc = math.sqrt(1.0 / a_max)  # triangle: peak speed below the limit
        return cls(a_max * t_acc, a_max, t_acc, 2.0 * t_acc)

    def s(self, t: float) -> float:
        """Path parameter at time ``t`` (clamped to 0..1)."""
        if self.duration <= 0.0 or t >= self.duration:
            return 1.0
        if t <= 0.0:
            return 0.0
        if t < self.t_acc:
            return 0.5 * self.a * t * t
        t_dec = self.duration - self.t_acc
        if t <= t_dec:
            return 0.5 * self.a * self.t_acc**2 + self.v * (t - self.t_acc)
        rest = self.duration - t
        return 1.0 - 0.5 * self.a * rest * rest

    def ds(self, t: float) -> float:
        """Speed of ``s`` at time ``t``."""
        if self.duration <= 0.0 or t <= 0.0 or t >= self.duration:
            return 0.0
        if t < self.t_acc:
            return self.a * t
        if t <= self.duration - self.t_acc:
            return self.v
        return self.a * (self.duration - t)

    def dds(self, t: float) -> float:
        """Acceleration of ``s`` at time ``t`` (piecewise constant)."""
        if self.duration <= 0.0 or t <= 0.0 or t >= self.duration:
            return 0.0
        if t < self.t_acc:
            return self.a
        if t <= self.duration - self.t_acc:
            return 0.0
        return -self.a

    def time_at_remaining(self, remaining: float) -> float:
        """The time at which ``1 - s`` falls to ``remaining`` (0..1): where blending may start."""
        if remaining <= 0.0 or self.duration <= 0.0:
            return self.duration
        if remaining >= 1.0:
            return 0.0
        ramp = 0.5 * self.a * self.t_acc**2  # distance covered by one ramp
        if remaining <= ramp:
            return self.duration - math.sqrt(2.0 * remaining / self.a)
        if self.v <= 0.0:
            return 0.0
        return self.duration - self.t_acc - (remaining - ramp) / self.v


def scalar_limits(
    distances: Iterable[float], v_limits: Iterable[float], a_limits: Iterable[float]
) -> tuple[float, float]:
    """Speed and acceleration limits of ``s`` so that no component exceeds its own limit.

    Component ``i`` moves ``distances[i] * s``; its speed is ``|d_i| * ds``, so ``ds`` may not
    exceed ``v_i / |d_i|`` for any moving component. Returns (inf, inf) when nothing moves.
    """
    v_s = a_s = math.inf
    for d, v, a in zip(distances, v_limits, a_limits, strict=True):
        d = abs(d)
        if d > EPS:
            v_s = min(v_s, v / d)
            a_s = min(a_s, a / d)
    return v_s, a_s


def ptp_profile(
    delta: Iterable[float], v_limits: Iterable[float], a_limits: Iterable[float]
) -> Trapezoid:
    """The synchronised PTP profile for the axis displacement ``delta`` (deg).

    ``v_limits``/``a_limits`` are the per-axis limits already scaled by ``$VEL_AXIS``/
    ``$ACC_AXIS`` (deg/s, deg/s²). The axis that needs the longest time sets the duration; the
    others follow the same normalised profile and therefore stay within their own limits.
    """
    return Trapezoid.plan(*scalar_limits(delta, v_limits, a_limits))
