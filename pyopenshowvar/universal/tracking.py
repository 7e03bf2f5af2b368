"""Trajectory and per-joint PID between the solver and the arm (thesis §2.2.2, Fig. 2.15).

"Each mapping method works as a motion planner": its set-points (θ_d in position mode, θ̇_d in
velocity mode) come at an irregular rate and, for the stochastic solvers, with jumps. Before
they reach the arm, two stages make them a motion the arm can follow:

* :class:`Trajectory` — a reference (θ_ref, θ̇_ref) that moves towards θ_d (position mode) or
  at θ̇_d (velocity mode) within each joint's speed and acceleration limits (the velocity
  vector is scaled as a whole, so the joints stay in step and the tip keeps its direction),
  braking in time to stop on θ_d, and never leaving the joint limits ("a well-suited trajectory ensures that
  no kinematic nor dynamic limits are exceeded");
* :class:`TrackingPID` — one PID per joint on the reference: the joint velocity command
  ``u = θ̇_ref + Kp·e + Ki·∫e + Kd·(θ̇_ref − θ̇_a)``, e = θ_ref − θ_a, clamped to the speed
  limits (the integral accumulates only while the joint's reference stands still and the
  command is not clamped). A velocity command suits every arm behind the
  server: hydraulic valves (the crane simulator), drives in velocity mode (the simulated
  arms), increments per interpolation cycle (a KRC over KVP).

:func:`joint_limits` gives speed and acceleration limits; where the arm description has none
(the thesis' crane and the SCARA) it uses :data:`DEFAULT_SPEED` and :data:`DEFAULT_ACCEL`.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..arms.model import Arm
from ..kinematics.frames import FloatArray

__all__ = ["DEFAULT_ACCEL", "DEFAULT_SPEED", "TrackingPID", "Trajectory", "joint_limits"]

#: Joint speed where the arm gives none: (revolute deg/s, prismatic mm/s).
DEFAULT_SPEED = (30.0, 200.0)
#: Joint acceleration where the arm gives none, in speeds per second.
DEFAULT_ACCEL = 4.0


def joint_limits(arm: Arm) -> tuple[FloatArray, FloatArray]:
    """(max speed, max acceleration) per joint, defaults filled in (see the module doc)."""
    default = np.where(arm.revolute, DEFAULT_SPEED[0], DEFAULT_SPEED[1])
    speed = np.where(np.isfinite(arm.max_speed), arm.max_speed, default)
    accel = np.where(np.isfinite(arm.max_accel), arm.max_accel, DEFAULT_ACCEL * speed)
    return np.asarray(speed), np.asarray(accel)


class Trajectory:
    """The reference the joints follow (see the module docstring)."""

    def __init__(
        self, arm: Arm, q0: npt.ArrayLike, *, speed: FloatArray | None = None,
        accel: FloatArray | None = None,
    ) -> None:  # fmt: skip
        default_speed, default_accel = joint_limits(arm)
        self.speed = default_speed if speed is None else np.asarray(speed, dtype=np.float64)
        self.accel = default_accel if accel is None else np.asarray(accel, dtype=np.float64)
        self.lower, self.upper = np.array(arm.lower), np.array(arm.upper)
        self.ref = np.array(q0, dtype=np.float64)
        self.ref_dot = np.zeros_like(self.ref)

    def hold(self, q: npt.ArrayLike) -> None:
        """Stand still at ``q`` (after a stop, or when the arm changes)."""
        self.ref = np.clip(np.array(q, dtype=np.float64), self.lower, self.upper)
        self.ref_dot = np.zeros_like(self.ref)

    def _advance(self, wanted: FloatArray, dt: float) -> None:
        # the whole vector is scaled, never a joint alone: joints that reach their speed at
        # different times would bend the tip's path off the commanded direction
        over = float(np.max(np.abs(wanted) / self.speed))
        if over > 1.0:
            wanted = wanted / over
        change = wanted - self.ref_dot
        ratio = float(np.max(np.abs(change) / (self.accel * dt)))
        self.ref_dot = self.ref_dot + (change / ratio if ratio > 1.0 else change)
        nxt = self.ref + self.ref_dot * dt
        wall = (nxt < self.lower) | (nxt > self.upper)
        self.ref = np.clip(nxt, self.lower, self.upper)
        self.ref_dot = np.where(wall, 0.0, self.ref_dot)

    def to_position(self, theta_d: npt.ArrayLike, dt: float) -> None:
        """Move towards ``theta_d``: as fast as allowed, slow enough to stop on it."""
        target = np.clip(np.asarray(theta_d, dtype=np.float64), self.lower, self.upper)
        err = target - self.ref
        # the speed from which the joint can still brake to rest at the target
        brake = np.sqrt(2.0 * self.accel * np.abs(err))
        wanted = np.sign(err) * np.minimum(np.minimum(self.speed, brake), np.abs(err) / dt)
        self._advance(wanted, dt)

    def with_velocity(self, theta_dot_d: npt.ArrayLike, dt: float) -> None:
        """Move at ``theta_dot_d`` (within the speed and acceleration limits)."""
        self._advance(np.asarray(theta_dot_d, dtype=np.float64), dt)


class TrackingPID:
    """Per-joint PID from the reference to a joint velocity command (deg/s, mm/s)."""

    def __init__(
        self, speed: FloatArray, *, kp: float = 8.0, ki: float = 0.5, kd: float = 0.5
    ) -> None:
        self.speed = np.asarray(speed, dtype=np.float64)
        self.kp, self.ki, self.kd = kp, ki, kd
        self.integral = np.zeros_like(self.speed)

    def reset(self) -> None:
        self.integral = np.zeros_like(self.speed)

    def update(
        self, ref: FloatArray, ref_dot: FloatArray, q: FloatArray, qdot: FloatArray, dt: float
    ) -> FloatArray:
        e = ref - q
        trial = self.integral + e * dt
        raw = ref_dot + self.kp * e + self.ki * trial + self.kd * (ref_dot - qdot)
        u = np.clip(raw, -self.speed, self.speed)
        # conditional integration: only while the joint's reference stands still (the integral
        # holds against a steady load; integrating the lag of a moving joint would push it
        # past the point where it is told to stop) and its command is not clamped
        hold = (ref_dot == 0.0) & (u == raw)
        self.integral = np.where(hold, trial, self.integral)
        return np.asarray(u)
