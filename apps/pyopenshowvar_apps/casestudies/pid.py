"""Per-joint PID trajectory smoother (thesis §4.2.2.3, Figure 4.18).

The custom control of case study 3 computes a target configuration θ_t from the hand at an
irregular rate (every access has a non-deterministic delay). Sent raw, θ_t is a staircase with
jumps; the thesis generates "well-suited trajectories" from it with one PID per joint. We do the
same: each joint has a smoothed state θ_s that a PID drives towards θ_t,

    θ̇_s = Kp·e + Ki·∫e dt + Kd·ė,   e = θ_t − θ_s,

with the output speed clamped to a fraction of the axis' maximum speed (so the command never
asks more than the drive can do) and the acceleration clamped likewise. θ_s is what goes to
MYAXIS. The PI part makes it follow a ramp (a hand moving at constant speed) without a
steady-state lag; the clamps are the anti-windup (the integral stops while the output saturates).

``dt`` is the loop's measured period, which jitters; a step larger than ``max_dt`` is cut
because an explicit PID update with Kp·dt ≳ 1 overshoots and then diverges.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["JointPID"]

FloatArray = npt.NDArray[np.float64]


class JointPID:
    """Vector PID over n joints (deg, s); ``update(target, dt)`` returns the new smoothed θ_s."""

    def __init__(
        self,
        initial: npt.ArrayLike,
        *,
        kp: float = 25.0,
        ki: float = 150.0,
        kd: float = 0.02,
        max_speed: npt.ArrayLike = np.inf,
        max_accel: npt.ArrayLike = np.inf,
        max_dt: float = 0.02,
    ) -> None:
        self.state = np.array(initial, dtype=np.float64)
        n = self.state.shape[0]
        self.kp, self.ki, self.kd = kp, ki, kd
        self.max_speed = np.broadcast_to(np.asarray(max_speed, dtype=np.float64), (n,)).copy()
        self.max_accel = np.broadcast_to(np.asarray(max_accel, dtype=np.float64), (n,)).copy()
        self.max_dt = max_dt
        self.integral = np.zeros(n)
        self.speed = np.zeros(n)  # deg/s, the last output
        self._last_error: FloatArray | None = None

    def reset(self, state: npt.ArrayLike) -> None:
        """Restart from ``state`` at rest (e.g. re-anchor on the measured axes)."""
        self.state = np.array(state, dtype=np.float64)
        self.integral[:] = 0.0
        self.speed[:] = 0.0
        self._last_error = None

    def update(self, target: npt.ArrayLike, dt: float) -> FloatArray:
        """Advance by ``dt`` seconds towards ``target``; returns a copy of the new state."""
        dt = min(max(float(dt), 0.0), self.max_dt)
        if dt == 0.0:
            return self.state.copy()
        error = np.asarray(target, dtype=np.float64) - self.state
        derivative = (
            np.zeros_like(error) if self._last_error is None else (error - self._last_error) / dt
        )
        self._last_error = error
        trial = self.integral + error * dt
        raw = self.kp * error + self.ki * trial + self.kd * derivative
        # speed then acceleration clamp: what the drive can follow
        limit = self.speed + self.max_accel * dt
        lower = self.speed - self.max_accel * dt
        speed = np.clip(raw, np.maximum(-self.max_speed, lower), np.minimum(self.max_speed, limit))
        # anti-windup: integrate only the joints whose output is not saturated in the error's
        # direction (conditional integration)
        saturated = (speed != raw) & (np.sign(error) == np.sign(raw))
        self.integral = np.where(saturated, self.integral, trial)
        self.speed = speed
        self.state = self.state + speed * dt
        return self.state.copy()
