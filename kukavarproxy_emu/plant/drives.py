"""The drives of the dynamic plant: joint servos and joint friction, one physics step at a time.

Per axis a cascaded servo (position P → velocity PI, velocity and acceleration feed-forward)
computes the motor torque, saturated at the motor's limit; the joints carry a Stribeck
friction curve (:func:`friction`). The gains are **scheduled on the inertia each axis sees
now**, the diagonal of M(q) (motor + links + payload) at the start of each IPO cycle, so every
axis has the same bandwidth in every pose and with every ``$LOAD``.

**Why implicit.** Both the velocity loop (``−Kd·q̇``) and the friction near zero speed (slope
``Fc/v_s``) are stiff dampers. Evaluated explicitly once per 2 ms step they are stable only
while ``h·M⁻¹·(Kd + Fc/v_s)`` stays below 2; with a payload the wrist's coupled inertia M⁻¹
exceeds that in most poses and the loop chatters at the step rate. Here both act at the *end*
of the step, the friction linearised about its start (a linearly implicit Euler step):
``friction(q̇⁺) ≈ f(q̇) + f'(q̇)·(q̇⁺ − q̇)`` with ``f' ≥ 0`` (a falling Stribeck branch stays
explicit) and the motor torque ``A − Kd·q̇⁺``. MuJoCo's Euler integrator already treats joint
damping this way, solving ``(M + h·D)·q̈ = τ − D·q̇ − bias`` in C: the step sets the damping
``D = Kd + f'`` and applies the rest as a generalised force, which is stable for any inertia
and gain. An axis whose torque ``A − Kd·q̇⁺`` would exceed its motor's limit is saturated there
(its ``Kd`` leaves the damping: the torque is then a constant) and the step is repeated.
Afterwards M(q)·q̈ + bias = τ_motor − τ_friction + τ_ext holds exactly with q̈ = (q̇⁺ − q̇)/h.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from .frames import FloatArray
from .params import Bodies, PlantParams

__all__ = ["Drives", "friction"]


def friction(
    bodies: Bodies, smoothing: float, stribeck: float, qd: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Joint friction torque (Nm, opposing ``qd``) and its slope d/dq̇ at speeds ``qd`` (rad/s):
    ``(Fc + (Fs − Fc)·exp(−(q̇/v_st)²))·tanh(q̇/v_s) + Fv·q̇``."""
    t = np.tanh(qd / smoothing)
    e = np.exp(-np.square(qd / stribeck))
    hump = bodies.static - bodies.coulomb
    dry = bodies.coulomb + hump * e
    f = dry * t + bodies.viscous * qd
    slope = dry * (1.0 - t * t) / smoothing - hump * e * (2.0 * qd / stribeck**2) * t
    return f, slope + bodies.viscous


class Drives:
    """The six servos of one arm: :meth:`schedule` once per IPO cycle, :meth:`step` per
    physics step (it steps MuJoCo)."""

    def __init__(self, params: PlantParams, bodies: Bodies, h: float) -> None:
        self.h = h
        self.bodies = bodies
        self.kp = params.position_gain
        self.bandwidth = params.velocity_bandwidth
        self.corner = params.integral_corner
        self.feedforward = params.acceleration_feedforward
        self.smoothing = params.friction_smoothing
        self.stribeck = params.stribeck_velocity
        self.limit = np.asarray(bodies.max_torque, dtype=np.float64)
        # per-axis constants as Python floats (see step)
        self._lims = self.limit.tolist()
        self._fc = bodies.coulomb.tolist()
        self._hump = (bodies.static - bodies.coulomb).tolist()
        self._fv = bodies.viscous.tolist()
        self._integral = [0.0] * 6
        self._full = np.zeros((6, 6))
        self._kd = [0.0] * 6
        self._kdc = [0.0] * 6
        self._ff = [0.0] * 6

    @property
    def integral(self) -> FloatArray:
        """The velocity PI's integral (Nm): preloaded with the holding torque at rest."""
        return np.array(self._integral)

    @integral.setter
    def integral(self, value: FloatArray) -> None:
        self._integral = [float(v) for v in value]

    def schedule(self, m: Any, d: Any) -> None:
        """Gains from M(q) of the state in ``d`` (forward-computed)."""
        mujoco.mj_fullM(m, d, self._full)
        inertia = self._full.diagonal().tolist()
        self._kd = [i * self.bandwidth for i in inertia]
        self._kdc = [k * self.corner * self.h for k in self._kd]
        self._ff = inertia if self.feedforward else [0.0] * 6

    def step(
        self,
        m: Any,
        d: Any,
        ref: list[float],
        qd_ref: list[float],
        qdd_ref: list[float],
        external: list[float],
    ) -> tuple[list[float], list[float], list[float]]:
        """One physics step towards the set-point ``ref`` moving at ``qd_ref``/``qdd_ref``
        (rad, rad/s, rad/s²) under the external generalised force ``external``; returns the
        motor torque, the friction torque (Nm) and the speeds before the step (rad/s).

        Six axes: numpy's per-call cost would be the whole cost of a 6-element step, so the
        servo runs on Python floats (IEEE doubles too); MuJoCo does the solve.
        """
        kp, kd, kdc, ff = self.kp, self._kd, self._kdc, self._ff
        lims, fc, hump, fv = self._lims, self._fc, self._hump, self._fv
        inv_vs, inv_vst = 1.0 / self.smoothing, 1.0 / self.stribeck
        q, qd = d.qpos.tolist(), d.qvel.tolist()
        integral = self._integral
        drive, f0, slope, damping, push = [], [], [], [], []
        tanh, exp = math.tanh, math.exp
        for j in range(6):
            v, top = qd[j], lims[j]
            v_cmd = qd_ref[j] + kp * (ref[j] - q[j])
            # anti-windup: the integral never asks for more than the motor can give
            i = integral[j] + kdc[j] * (v_cmd - v)
            i = top if i > top else (-top if i < -top else i)
            integral[j] = i
            a = kd[j] * v_cmd + i + ff[j] * qdd_ref[j]
            x = v * inv_vst
            t, e = tanh(v * inv_vs), exp(-x * x)
            dry = fc[j] + hump[j] * e
            f = dry * t + fv[j] * v
            sl = dry * (1.0 - t * t) * inv_vs - 2.0 * hump[j] * e * x * inv_vst * t + fv[j]
            sl = sl if sl > 0.0 else 0.0  # a falling Stribeck branch stays explicit
            drive.append(a)
            f0.append(f)
            slope.append(sl)
            damping.append(kd[j] + sl)
            push.append(a - f + sl * v + external[j])
        state = (d.qpos.copy(), d.qvel.copy(), d.time)
        held: dict[int, float] = {}  # the torque of saturated axes
        while True:
            m.dof_damping[:] = damping
            d.qfrc_applied[:] = push
            mujoco.mj_step(m, d)
            qn = d.qvel.tolist()
            tau = [drive[j] - kd[j] * qn[j] for j in range(6)]
            for j, lim in held.items():
                tau[j] = lim
            over = [j for j in range(6) if abs(tau[j]) > lims[j] and j not in held]
            if not over:
                break
            for j in over:  # redo the step with those axes saturated: a constant torque
                held[j] = lim = math.copysign(lims[j], tau[j])
                damping[j] = slope[j]
                push[j] += lim - drive[j]
            d.qpos[:], d.qvel[:], d.time = state
        return tau, [f0[j] + slope[j] * (qn[j] - qd[j]) for j in range(6)], qd
