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

What the kernel runs is a :class:`Profile`: ``ṡ²`` as a piecewise-linear function of ``s``
(the phase plane). A straight piece is a constant acceleration, so a trapezoid is three pieces,
a LIN limited by its axes near a singularity is many, and re-timing the tail of a segment for an
approximation is the pointwise minimum of two such functions (:func:`pl_min`): a curve below
both is reachable whenever both are, since the speed never has to jump.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["Profile", "Trapezoid", "pl_min", "ptp_profile", "ramp_curve", "scalar_limits"]

FloatArray = npt.NDArray[np.float64]

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


Curve = tuple[FloatArray, FloatArray]
#: Nodes of a curve closer than this (in s) are merged: a sliver would divide by ~0.
NODE_EPS = 1e-12


def pl_min(a: Curve, b: Curve) -> Curve:
    """Pointwise minimum of two piecewise-linear curves ``(s, x)`` over the span of ``a``.

    ``b`` is evaluated by linear interpolation (held constant beyond its ends). The result has
    a node wherever either curve has one and wherever they cross, so it is exact.
    """
    sa, xa = a
    sb, xb = b
    s = np.sort(np.concatenate([sa, sb[(sb > sa[0]) & (sb < sa[-1])]]))
    d = np.interp(s, sa, xa) - np.interp(s, sb, xb)
    k = np.flatnonzero(d[:-1] * d[1:] < 0.0)
    if len(k):
        s = np.sort(np.concatenate([s, s[k] + (s[k + 1] - s[k]) * d[k] / (d[k] - d[k + 1])]))
    # (np.union1d would do, but its first call imports numpy.ma: 40 ms inside an IPO cycle)
    # merge slivers: keep a node when the next one is farther away; keep both ends
    keep = np.concatenate([np.diff(s) > NODE_EPS, [True]])
    if len(s) > 1 and not keep[0]:
        keep[0], keep[1] = True, False
    s = s[keep]
    return s, np.minimum(np.interp(s, sa, xa), np.interp(s, sb, xb))


def ramp_curve(s0: float, x0: float, s1: float, x1: float, x_max: float, a_max: float) -> Curve:
    """The fastest constant-limit profile from ``(s0, ṡ²=x0)`` to ``(s1, x1)``: accelerate at
    ``a_max``, cruise at ``√x_max``, decelerate at ``a_max`` (a trapezoid, or a triangle).

    Raises ``ValueError`` when the end state cannot be reached (too fast to stop in time).
    """
    span = s1 - s0
    reach = 2.0 * a_max * span
    if x0 > x1 + reach + 1e-12 or x1 > x0 + reach + 1e-12:
        raise ValueError("the end speed cannot be reached within the distance")
    # closed form (this runs for every PTP): the accelerating and braking lines meet at s_m
    s_m = min(max(0.5 * (s0 + s1) + (x1 - x0) / (4.0 * a_max), s0), s1)
    x_m = x0 + 2.0 * a_max * (s_m - s0)
    if x_m <= x_max:
        nodes, values = [s0, s_m, s1], [x0, x_m, x1]
    else:  # cruise at the cap in between
        s_a = s0 + max(x_max - x0, 0.0) / (2.0 * a_max)
        s_d = s1 - max(x_max - x1, 0.0) / (2.0 * a_max)
        nodes, values = [s0, s_a, s_d, s1], [x0, x_max, x_max, x1]
    keep = [0] + [i for i in range(1, len(nodes)) if nodes[i] - nodes[i - 1] > NODE_EPS]
    if keep[-1] != len(nodes) - 1:
        keep[-1] = len(nodes) - 1
    return np.array([nodes[i] for i in keep]), np.array([values[i] for i in keep])


class Profile:
    """A motion's path parameter over time, from its phase-plane curve ``ṡ² = x(s)``.

    Between two nodes the acceleration is constant, so ``s(t)`` is exact (no integration
    error) and the time of each node is ``2·Δs / (ṡ_k + ṡ_k+1)``. ``Profile.instant()`` is a
    zero-length motion (``duration == 0``).
    """

    __slots__ = ("_s", "_t", "_x", "duration", "s", "t", "x")

    def __init__(self, s: FloatArray, x: FloatArray) -> None:
        # plain floats: profiles are built for every PTP and looked up every cycle, and
        # numpy's per-call overhead dominates on a handful of nodes
        s_list = [float(v) for v in s]
        x_list = [max(float(v), 0.0) for v in x]
        t_list = [0.0]
        v_prev = math.sqrt(x_list[0])
        for k in range(1, len(s_list)):
            v = math.sqrt(x_list[k])
            span = s_list[k] - s_list[k - 1]
            if span > 0.0:
                if v_prev + v <= 0.0:
                    raise ValueError("the profile stops inside the motion")
                t_list.append(t_list[-1] + 2.0 * span / (v_prev + v))
            else:
                t_list.append(t_list[-1])
            v_prev = v
        self._s, self._x, self._t = s_list, x_list, t_list
        self.s, self.x, self.t = np.array(s_list), np.array(x_list), np.array(t_list)
        self.duration = t_list[-1]

    @classmethod
    def instant(cls) -> Profile:
        return cls(np.array([1.0]), np.array([0.0]))

    @classmethod
    def trapezoid(cls, v_max: float, a_max: float) -> Profile:
        """The rest-to-rest profile of :meth:`Trapezoid.plan` (inf limits = no motion)."""
        if math.isinf(v_max) and math.isinf(a_max):
            return cls.instant()
        return cls(*ramp_curve(0.0, 0.0, 1.0, 0.0, v_max * v_max, a_max))

    def curve(self) -> Curve:
        return self.s, self.x

    def _piece(self, t: float) -> tuple[int, float]:
        k = min(bisect_right(self._t, t) - 1, len(self._t) - 2)
        return k, t - self._t[k]

    def _accel(self, k: int) -> float:
        span = self._s[k + 1] - self._s[k]
        return (self._x[k + 1] - self._x[k]) / (2.0 * span) if span > 0.0 else 0.0

    def at(self, t: float) -> tuple[float, float, float]:
        """``(s, ṡ, s̈)`` at time ``t`` (clamped to the profile)."""
        if t >= self.duration:
            return self._s[-1], 0.0, 0.0
        if t <= 0.0:
            return self._s[0], math.sqrt(self._x[0]), 0.0
        k, tau = self._piece(t)
        v0, u = math.sqrt(self._x[k]), self._accel(k)
        s = min(self._s[k] + v0 * tau + 0.5 * u * tau * tau, self._s[k + 1])
        return s, max(v0 + u * tau, 0.0), u

    def s_at(self, t: float) -> float:
        return self.at(t)[0]

    def x_at(self, s: float) -> float:
        """``ṡ²`` where the path parameter is ``s``."""
        return float(np.interp(s, self.s, self.x))

    def time_at(self, s: float) -> float:
        """When the path parameter reaches ``s``."""
        if s <= self._s[0]:
            return 0.0
        if s >= self._s[-1]:
            return self.duration
        k = bisect_right(self._s, s) - 1
        v0, v1 = math.sqrt(self._x[k]), math.sqrt(self.x_at(s))
        return float(self._t[k] + 2.0 * (s - self._s[k]) / (v0 + v1))
