"""Case study 4: haptic force feedback with the KRC kinematics (thesis §4.2.2.2, Figure 4.19).

A simulated 3-DOF haptic device (an omega.7 stand-in: handle position in, force out) is held by
an operator modelled as a spring-damper pulling the handle towards where the hand wants to go.
The handle's offset from its centre sets the *direction* of motion (not scaled to the robot's
workspace, as in the thesis): the robot follows through MYPOS and the ACTUATOR program
(Algorithm 4.12, ``LOOP PTP_REL MYPOS C_PTP``). Each cycle:

1. ``read_joint_angles()`` and ``read_joint_torques()`` (one round trip each);
2. τ_ext = τ − τ_gravity(θ, $LOAD) — our mass model, the same one the emulator publishes;
3. solve Jᵀ F = τ_ext (eq. 4.5) for the TCP force by regularised least squares
   (:func:`estimate_force`), and render −F × gain on the handle (the operator feels the
   environment push back);
4. the virtual environment (a wall: a spring when the TCP crosses a plane; optionally a constant
   payload) is evaluated at the TCP and applied as ``EMU_WRENCH`` — over KVP by default, or by
   any ``environment`` callable (``emu.robot.apply_wrench`` in process) — so the true force is
   known and the estimate can be scored.

**Estimator.** The device is 3-DOF, so we solve for the force only: Jᵥᵀ F = τ is 6 equations in
3 unknowns, well conditioned even where the full 6×6 Jᵀ is singular — HOME, where ACTUATOR
starts, has A5 = 0 and there the 6-D ``torques_to_wrench`` loses ~8 N of a 50 N force into the
wrist singularity's null space. ``estimator="wrench"`` uses ``torques_to_wrench`` for comparison.

**What is scored.** The emulator's torque adds I·q̈ (a diagonal inertia) while the axes
accelerate, and q and τ come from two reads that an IPO tick may fall between. Neither is a
force, so the error is scored on *settled* samples (the axes identical before and after the
torque read, the applied wrench unchanged); the error while moving is reported separately.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from pyopenshowvar.kinematics import (
    KR6R900SIXX,
    Load,
    forward,
    gravity_torques,
    jacobian,
    torques_to_wrench,
)
from pyopenshowvar_apps.casestudies.common import (
    CaseResult,
    new_figure,
    output_dir,
    save_figure,
    write_csv,
)
from pyopenshowvar_apps.casestudies.devices import Clock

__all__ = ["HapticDevice", "Wall", "estimate_force", "operator_script", "run_haptic"]

FloatArray = npt.NDArray[np.float64]
MODEL = KR6R900SIXX
G = 9.81
Environment = Callable[[FloatArray], Awaitable[None] | None]


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
        """Integrate ``dt`` s (1 ms semi-implicit Euler substeps: the hand spring is stiff)."""
        n = max(1, math.ceil(dt / 0.001))
        h, f, sub = np.asarray(hand, float), np.asarray(force, float), dt / n
        for _ in range(n):
            total = self.k_hand * (h - self.p) - self.b_hand * self.v + f  # N
            self.v = self.v + total / self.mass * 1000.0 * sub  # N/kg = m/s² → mm/s²
            self.p = np.clip(self.p + self.v * sub, -self.reach, self.reach)
        return self.p.copy()


def operator_script(duration: float) -> Callable[[float], FloatArray]:
    """Where the operator's hand pulls the handle (mm): like Figure 4.19, lift up first, then
    down and forward with a sideways touch — into the wall — hold, and let go."""
    keys = np.array([0.0, 0.1, 0.25, 0.35, 0.45, 0.8, 0.9, 1.0]) * duration
    pts = np.array(
        [[0, 0, 0], [0, 0, 50], [0, 0, 50], [0, 20, -20], [50, 0, 0], [50, 0, 0], [0, 0, 0],
         [0, 0, 0]], dtype=float,
    )  # fmt: skip

    def at(t: float) -> FloatArray:
        return np.array([np.interp(t, keys, pts[:, k]) for k in range(3)])

    return at


def estimate_force(
    q: npt.ArrayLike,
    tau: npt.ArrayLike,
    load: Load | None = None,
    *,
    tool: Any = None,
    estimator: Literal["force", "wrench"] = "force",
    damping: float = 1e-3,
) -> FloatArray:
    """The force (N, base axes) the TCP exerts on the environment from measured torques.

    τ_ext = τ − gravity(q, load); ``"force"`` solves (AᵀA + λ²I) F = Aᵀτ_ext with A = Jᵥᵀ in
    m/rad (Tikhonov-regularised least squares); ``"wrench"`` takes the force part of
    ``torques_to_wrench`` (6-D damped least squares).
    """
    tau_ext = np.asarray(tau, float) - gravity_torques(MODEL, q, load)
    if estimator == "wrench":
        return np.asarray(torques_to_wrench(MODEL, q, tau_ext, tool=tool), float)[:3]
    a = np.asarray(jacobian(MODEL, q, tool=tool), float)[:3].T / 1000.0  # Nm per N
    lhs = a.T @ a + damping**2 * np.eye(3)
    return np.asarray(np.linalg.solve(lhs, a.T @ (MODEL.torque_sign * tau_ext)), float)


async def run_haptic(
    client: Any,
    *,
    duration: float = 8.0,
    wall: Wall | None = None,
    payload_kg: float = 0.0,
    environment: Environment | Literal["kvp"] | None = "kvp",
    out_dir: str | Path | None = None,
    time_scale: float = 1.0,
    gain: float = 0.25,
    k_inc: float = 0.02,
    dead_zone_mm: float = 5.0,
    estimator: Literal["force", "wrench"] = "force",
    period: float = 0.012,
    plots: bool = True,
) -> CaseResult:
    """Run the haptic loop for ``duration`` robot seconds against a running ACTUATOR program.

    ``period`` is the shortest cycle (robot seconds). ``wall`` defaults to a plane 30 mm in front of the start TCP; ``payload_kg`` adds a constant
    held mass (the TCP pushes up with m·g). ``environment`` applies the true wrench: ``"kvp"``
    writes EMU_WRENCH, a callable receives the 6-vector, None applies nothing (a real robot
    touching real things: no ground truth, errors are NaN).
    """
    clock = Clock(time_scale)
    load = Load.from_krl(await client.read_value("$LOAD"))
    q = await client.read_joint_angles()
    x0 = np.asarray(forward(MODEL, q), float)[:3]
    wall = wall if wall is not None else Wall(0, x0[0] + 30.0)
    payload = np.array([0, 0, payload_kg * G, 0, 0, 0], float)

    async def apply(w: FloatArray) -> None:
        if environment == "kvp":
            text = ", ".join(
                f"{n} {v:.4f}" for n, v in zip(("FX", "FY", "FZ", "MX", "MY", "MZ"), w, strict=True)
            )
            await client.write("EMU_WRENCH", "{" + text + "}")
        elif environment is not None:
            maybe = environment(w)
            if maybe is not None:
                await maybe

    device, hand_at = HapticDevice(), operator_script(duration)
    applied = wall.wrench(x0) + payload
    await apply(applied)
    await client.write("MYPOS", "{X 0.0, Y 0.0, Z 0.0}")
    await clock.sleep(0.05)  # let a tick publish the torques of the initial wrench
    rows: list[dict[str, float]] = []
    last_inc = np.zeros(3)
    t_prev = clock.now()
    try:
        while (t := clock.now()) < duration:
            q = await client.read_joint_angles()
            tau = await client.read_joint_torques()
            truth = applied.copy()  # what was applied before this torque read
            x = np.asarray(forward(MODEL, q), float)[:3]
            f_est = estimate_force(q, tau, load, estimator=estimator)
            p = device.step(hand_at(t), -gain * f_est, max(t - t_prev, 0.0))
            t_prev = t
            # direction of motion: handle offset beyond a small dead zone; 0.1 mm resolution so
            # "no input" is an exact zero and the robot really stops
            norm = float(np.linalg.norm(p))
            inc = np.round(k_inc * p * max(0.0, 1 - dead_zone_mm / norm) if norm else p, 1)
            if np.any(inc != last_inc):
                await client.write("MYPOS", f"{{X {inc[0]:.1f}, Y {inc[1]:.1f}, Z {inc[2]:.1f}}}")
                last_inc = inc
            new = wall.wrench(x) + payload
            if np.max(np.abs(new - applied)) > 0.01:
                await apply(new)
                applied = new
            row = {"t": t, **{f"x_{a}": v for a, v in zip("xyz", x, strict=True)}}
            row.update({f"q_A{i + 1}": v for i, v in enumerate(q)})
            row.update({f"tau_A{i + 1}": v for i, v in enumerate(tau)})
            row.update({f"F_est_{a}": v for a, v in zip("xyz", f_est, strict=True)})
            row.update({f"F_true_{a}": v for a, v in zip("xyz", truth[:3], strict=True)})
            row.update({f"handle_{a}": v for a, v in zip("xyz", p, strict=True)})
            rows.append(row)
            # no faster than the IPO cycle: the torques cannot change in between, and a loop
            # spinning on a sped-up in-process emulator would starve its IPO clock
            await clock.sleep(period - (clock.now() - t))
    finally:
        await client.write("MYPOS", "{X 0.0, Y 0.0, Z 0.0}")
        if environment is not None:
            await apply(np.zeros(6))
    return _report(rows, environment is not None, out_dir, plots)


def _report(
    rows: list[dict[str, float]], scored: bool, out_dir: str | Path | None, plots: bool
) -> CaseResult:
    result = CaseResult("haptic force feedback")
    if len(rows) < 5:
        raise RuntimeError(f"only {len(rows)} haptic cycles ran")
    col = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    q = np.stack([col[f"q_A{i}"] for i in range(1, 7)], axis=1)
    est = np.stack([col[f"F_est_{a}"] for a in "xyz"], axis=1)
    true = np.stack([col[f"F_true_{a}"] for a in "xyz"], axis=1)
    # settled: same axes before, at and after this sample, same truth as the sample before
    # (two samples back: the tick that stops the axes publishes the same q with the last
    # deceleration still in its I·q̈ term)
    same = np.zeros(len(q), bool)
    still = np.abs(np.diff(q, axis=0)).max(1) < 1e-6  # still[i]: q[i] == q[i + 1]
    same[2:-1] = still[:-2] & still[1:-1] & still[2:]
    same[2:] &= (np.abs(true[2:] - true[1:-1]).max(1) < 1e-9) & (
        np.abs(true[1:-1] - true[:-2]).max(1) < 1e-9
    )
    err = np.linalg.norm(est - true, axis=1)
    tol = np.maximum(0.05 * np.linalg.norm(true, axis=1), 0.5)
    m = result.metrics
    m["cycle_hz"] = float((len(rows) - 1) / (col["t"][-1] - col["t"][0]))
    m["max_force_N"] = float(np.max(np.linalg.norm(true, axis=1)))
    m["settled_samples"] = float(np.sum(same))
    m["settled_force_max_N"] = (
        float(np.linalg.norm(true[same], axis=1).max()) if same.any() else 0.0
    )
    nan = math.nan
    m["force_err_settled_max_N"] = float(err[same].max()) if scored and same.any() else nan
    m["force_err_settled_rms_N"] = (
        float(np.sqrt(np.mean(err[same] ** 2))) if scored and same.any() else nan
    )
    m["within_tol_settled_frac"] = float(np.mean(err[same] <= tol[same])) if same.any() else nan
    moving = ~same
    m["force_err_moving_rms_N"] = (
        float(np.sqrt(np.mean(err[moving] ** 2))) if scored and moving.any() else nan
    )
    m["force_err_moving_p95_N"] = (
        float(np.percentile(err[moving], 95)) if scored and moving.any() else nan
    )
    result.thesis["within_tol_settled_frac"] = "figure only (no error reported)"
    if out_dir is None:
        return result
    folder = output_dir(out_dir, "haptic")
    result.add_file(write_csv(folder / "haptic.csv", rows))
    if plots:
        t = col["t"]
        fig, axes = new_figure(2, 2, figsize=(11, 8), sharex=True)  # Figure 4.19 a-d
        panels = [
            ("(a) TCP position (mm)", [(f"x_{a}", a.upper()) for a in "xyz"]),
            ("(b) joint angles (deg)", [(f"q_A{i}", f"A{i}") for i in range(1, 7)]),
            ("(c) joint torques (Nm)", [(f"tau_A{i}", f"A{i}") for i in range(1, 7)]),
            ("(d) TCP force (N): estimate, -- true", [(f"F_est_{a}", f"F{a}") for a in "xyz"]),
        ]
        for ax, (title, series) in zip(np.ravel(axes), panels, strict=True):
            for key, label in series:
                ax.plot(t, col[key], label=label)
            ax.set_title(title)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
        for a in "xyz":
            np.ravel(axes)[3].plot(t, col[f"F_true_{a}"], "--", color="grey", linewidth=0.8)
        for ax in np.ravel(axes)[2:]:
            ax.set_xlabel("time (s)")
        result.add_file(save_figure(fig, folder / "fig4_19_haptic.png"))
    return result
