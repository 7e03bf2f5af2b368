"""The benchmark loop: one run of a profile, one solver, on the plant, calm or on a ship.

Per sample (``log_period_s``, 50 Hz by default): every ``control_period_s`` the solver maps
the target ``x_d`` to joint angles ``θ_c`` from the plant's actual angles θ_a (position mode,
eq. 2.9), or the speed towards the next target sample to joint speeds integrated into the
previous command (velocity mode, eq. 2.10: ``θ_c ← θ_c + θ̇·Δt``);
``x_c`` is the description's forward kinematics of θ_c (the thesis' "calculated" position).
A joint PI loop (the thesis' "PID regulation") turns ``θ_c − θ_a`` into valve commands, by
the controller's own nominal full-spool speeds (as set at commissioning, not the plant's
lever geometry); the plant's tip is the "actual" position.

On a ship (the heave test, §5.2.1.2), the target stays where it would be on a still ship,
in the earth frame; uncompensated, the crane keeps tracking x_d in its own frame and the ship
carries the tip away; compensated, the measured ship pose gives the target as the moving base
sees it, ``δx = x_t − x_d`` (eq. 5.8) and ``δθ = J⁻¹(θ_a)·δx`` (eq. 5.9) is added to θ_c, its
rate fed forward to the valves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from pyopenshowvar.arms import Arm
from pyopenshowvar.universal import Solver

from . import metrics
from .plant import CranePlant, PlantParams
from .profiles import Profile, Run
from .scenario import Ship

__all__ = ["Controller", "Trace", "run_once", "summarise"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Controller:
    """The joint PI loop: gains (1/s, 1/s²) and the nominal joint speed at full spool (deg/s)."""

    kp: float = 6.0
    ki: float = 3.0
    full_spool_deg_s: tuple[float, float, float] = (12.0, 6.0, 10.0)
    settle_s: float = 3.0
    #: low-pass time constant (s) of the compensation's rate feed-forward: the measured
    #: ship pose is noisy, its raw derivative would shake the valves
    ff_tau: float = 0.15


@dataclass
class Trace:
    """The sampled series of one run (deg, mm, N·m, s); ``earth_*`` only on a ship."""

    t: FloatArray
    x_d: FloatArray
    x_t: FloatArray
    x_c: FloatArray
    x_a: FloatArray
    theta_t: FloatArray
    theta_c: FloatArray
    theta_a: FloatArray
    tau: FloatArray
    spool: FloatArray
    rod_force: FloatArray
    solve_ms: FloatArray
    earth_target: FloatArray | None = None
    earth_actual: FloatArray | None = None
    info: dict[str, Any] = field(default_factory=dict)


def run_once(
    run: Run,
    profile: Profile,
    arm: Arm,
    solver: Solver,
    t: FloatArray,
    theta_t: FloatArray,
    *,
    ship: Ship | None = None,
    compensate: bool = False,
    plant_params: PlantParams | None = None,
    controller: Controller | None = None,
) -> Trace:
    """Fly one run on the plant and record it (see the module docstring)."""
    ctl = controller or Controller()
    params = plant_params or PlantParams()
    n, dt = len(t), profile.log_period_s
    every = round(profile.control_period_s / dt)
    x_d = solver.fk(theta_t)
    plant = CranePlant(params, run.payload_kg, theta_t[0])
    valve = _Valves(ctl, plant, dt)
    if ship is not None:
        plant.set_gravity(ship.g_base[0])
    for _ in range(round(ctl.settle_s / dt)):  # the crane holds its start before the run
        plant.step(valve(theta_t[0], np.zeros(3)), dt)
    solver.reset()
    cols = {
        k: np.empty((n, 3)) for k in ("x_t", "x_c", "x_a", "theta_c", "theta_a", "tau", "spool")
    }
    rod, solve_ms = np.empty((n, 2)), np.full(n, np.nan)
    earth_target = ship.still(x_d) if ship is not None else None
    theta_c, dtheta_prev, x_t = theta_t[0].copy(), np.zeros(3), x_d[0]
    ramp_from, rate, ff_comp = theta_c.copy(), np.zeros(3), np.zeros(3)
    smooth = 1.0 - math.exp(-dt / ctl.ff_tau)
    for k in range(n):
        q_a = plant.q
        if k % every == 0:
            ramp_from = theta_c
            # the solver works in the local workspace: it sees the crane without the
            # compensation currently applied (an iterative solver stopped by its budget would
            # otherwise return part of δθ, which would then be added again)
            q_s = np.clip(q_a - dtheta_prev, arm.lower, arm.upper)
            ahead = x_d[min(k + every, n - 1)]
            theta_c, x_t = _solve(run.mode, solver, x_d[k], ahead, every * dt, theta_c, q_s)
            solve_ms[k] = 1000.0 * solver.last.time_s
            rate = (theta_c - ramp_from) / (every * dt)
        # the valves follow θ_c as a ramp over the control period (first-order hold), its
        # rate fed forward: a step every 0.1 s would only jerk the hydraulics
        cmd = ramp_from + rate * dt * (k % every + 1)
        ff = np.radians(rate)
        if ship is not None and compensate and earth_target is not None:
            dx = ship.local(earth_target[k], k) - x_d[k]  # eq. 5.8, in the crane's frame
            jac = arm.jacobian(q_a)[:3]  # mm per rad
            dtheta = np.degrees(metrics.compensation(jac, dx))  # eq. 5.9
            cmd = np.clip(cmd + dtheta, arm.lower, arm.upper)
            raw = np.radians(dtheta - dtheta_prev) / dt if k else np.zeros(3)
            ff_comp += smooth * (raw - ff_comp)
            ff, dtheta_prev = ff + ff_comp, dtheta
        cols["x_t"][k], cols["x_c"][k], cols["x_a"][k] = x_t, solver.fk(theta_c), plant.tip()
        cols["theta_c"][k], cols["theta_a"][k], cols["tau"][k] = theta_c, q_a, plant.torque
        rod[k] = plant.rod_forces()
        if ship is not None:
            plant.set_gravity(ship.g_base[k])
        u = valve(cmd, ff)
        cols["spool"][k] = np.clip(u, -1.0, 1.0)
        plant.step(u, dt)
    info = {"control_every": every}
    trace = Trace(t, x_d, cols["x_t"], cols["x_c"], cols["x_a"], theta_t, cols["theta_c"], cols["theta_a"],
                  cols["tau"], cols["spool"], rod, solve_ms, earth_target, info=info)  # fmt: skip
    if ship is not None:
        trace.earth_actual = ship.earth(trace.x_a)
    return trace


class _Valves:
    """The crane's valve servo: the command's rate fed forward plus PI on the joint error
    (rad), the integral clamped to half a full spool; the output in full-spool units."""

    def __init__(self, ctl: Controller, plant: CranePlant, dt: float) -> None:
        self.ctl, self.plant, self.dt = ctl, plant, dt
        self.full = np.radians(np.asarray(ctl.full_spool_deg_s))
        self.integ = np.zeros(3)

    def __call__(self, cmd: FloatArray, ff: FloatArray) -> FloatArray:
        ctl, full = self.ctl, self.full
        e = np.radians(cmd - self.plant.q)
        self.integ = np.clip(self.integ + e * self.dt, -0.5 * full / ctl.ki, 0.5 * full / ctl.ki)
        return np.asarray((ff + ctl.kp * e + ctl.ki * self.integ) / full)


def _solve(
    mode: str,
    solver: Solver,
    target: FloatArray,
    ahead: FloatArray,
    span: float,
    theta_c: FloatArray,
    q_s: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """The server's command for one control period of ``span`` s and the target it aimed at:
    ``target`` is this sample's, ``ahead`` the one a period later; ``q_s`` is the crane as the
    solver sees it (without the compensation applied)."""
    if mode == "position":
        return solver.position(target, q_s), target  # eq. 5.3: the target the solver was given
    # velocity mode integrates the server's own command (its θ_a is the commanded
    # configuration, as a servoed arm reports it), steering towards the next target sample:
    # x_t = x_c + ẋ·Δt
    xdot = (ahead - solver.fk(theta_c)) / span
    return theta_c + solver.velocity(theta_c, xdot, span) * span, ahead


def summarise(trace: Trace, profile: Profile) -> dict[str, Any]:
    """The direct metrics of a trace (eqs. 5.2, 5.4–5.7) and its actual tracking error."""
    a = metrics.position_error(trace.x_t, trace.x_c)
    # eq. 5.4 against the joint target of the sample the solver was given (as x_t, eq. 5.3)
    every = int(trace.info.get("control_every", 1))
    held = (np.arange(len(trace.t)) // every) * every
    b = metrics.joint_error(trace.theta_t[held], trace.theta_c)
    cost = metrics.composed_cost(a, b, profile.alpha, profile.beta)
    effort = metrics.joint_effort(trace.t, trace.tau)
    solve = trace.solve_ms[np.isfinite(trace.solve_ms)]
    return {
        "position_error_mm": metrics.summary(a),
        "actual_error_mm": metrics.summary(metrics.position_error(trace.x_d, trace.x_a)),
        "joint_error_deg": metrics.summary(b),
        "cost": {"mean": float(np.mean(cost)), "max": float(np.max(cost))},
        "joint_effort": {
            "slew": float(effort[0]),
            "boom": float(effort[1]),
            "jib": float(effort[2]),
            "total": float(np.sum(effort)),
        },
        "solve_ms": {"mean": float(np.mean(solve)), "max": float(np.max(solve))},
        "duration_s": float(trace.t[-1]),
    }


def heave_rms(trace: Trace) -> tuple[float, float]:
    """RMS and maximum of ``|δx|`` (eq. 5.8) in the earth frame (mm)."""
    assert trace.earth_target is not None and trace.earth_actual is not None
    e = metrics.position_error(trace.earth_target, trace.earth_actual)
    return float(math.sqrt(np.mean(e**2))), float(np.max(e))
