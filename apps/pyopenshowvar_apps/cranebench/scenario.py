"""What a run asks of the crane: the joint path of its operations and the ship under it.

The thesis generates the OP's input signal "by simply defining the corresponding path for the
crane" and keeps only samples the crane can reach. Here each operation moves one joint by its
angle on a minimum-jerk profile (zero speed and acceleration at both ends, eq. 5.6's boundary
conditions), its duration set by the run category's peak speed (1.875·Δθ/v), with ``hold_s``
of stillness before, between and after; the targets ``x_d`` are the description's forward
kinematics of that path, so every sample is reachable.

The ship: :class:`~pyopenshowvar_apps.maritime.vessel.Motion` of the supply vessel in the
profile's sea, measured by the :class:`~pyopenshowvar_apps.maritime.imu.IMU` (the compensator
reads the measurement, the plant feels the truth). Frames: the crane's base frame {c} is z up,
x forward, y to port; the ship's body frame {b} is x forward, y starboard, z down, so
``R_bc = diag(1, −1, −1)``; the earth frame is NED.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pyopenshowvar.arms import Arm

from .plant import G
from .profiles import ProfileError, Run

__all__ = ["R_BC", "Ship", "joint_path", "ship"]

FloatArray = npt.NDArray[np.float64]
R_BC = np.diag([1.0, -1.0, -1.0])


def _min_jerk(s: FloatArray) -> FloatArray:
    return np.asarray(10 * s**3 - 15 * s**4 + 6 * s**5)


def joint_path(run: Run, arm: Arm, period: float, hold: float) -> tuple[FloatArray, FloatArray]:
    """Sample times (s) and the target joint path θ_t (deg, ``(n, dof)``) of ``run``."""
    names = list(arm.joint_names)
    q = np.array(run.initial_deg, dtype=np.float64)
    if not np.all(arm.within_limits(q)):
        raise ProfileError(f"{run.name}: initial_deg {q.tolist()} is outside {arm.name}'s limits")
    pieces = [np.repeat(q[None], max(1, round(hold / period)), axis=0)]
    for op in run.operations:
        j = names.index(op.joint)
        duration = 1.875 * abs(op.move_deg) / run.speed_deg_s
        n = max(2, round(duration / period))
        s = _min_jerk(np.arange(1, n + 1) / n)
        seg = np.repeat(q[None], n, axis=0)
        seg[:, j] = q[j] + op.move_deg * s
        q = seg[-1].copy()
        if not np.all(arm.within_limits(q)):
            raise ProfileError(f"{run.name}: operation {op.name!r} leaves {arm.name}'s limits")
        pieces += [seg, np.repeat(q[None], max(1, round(hold / period)), axis=0)]
    theta = np.concatenate(pieces)
    return np.arange(len(theta), dtype=np.float64) * period, theta


@dataclass
class Ship:
    """The ship along a run: true and measured poses, and the crane base's effective gravity."""

    eta: FloatArray  # true η (NED, m, rad): (n, 6)
    eta_hat: FloatArray  # measured η̂
    r_b: FloatArray  # crane base in {b} (m)
    g_base: FloatArray  # effective gravity in {c} (m/s²): (n, 3)

    @staticmethod
    def rotation(eta: FloatArray) -> FloatArray:
        from ..maritime.vessel import euler_rotation

        return euler_rotation(eta[..., 3], eta[..., 4], eta[..., 5])

    def earth(self, x_c_mm: FloatArray, eta: FloatArray | None = None) -> FloatArray:
        """Points given in {c} (mm) in the earth frame (mm), per sample: ``(n, 3)``."""
        e = self.eta if eta is None else eta
        local = self.r_b + (R_BC @ (np.asarray(x_c_mm) / 1000.0).T).T
        return np.asarray(1000.0 * (e[:, :3] + np.einsum("nij,nj->ni", self.rotation(e), local)))

    def still(self, x_c_mm: FloatArray) -> FloatArray:
        """Points given in {c} (mm) where they would be in the earth frame on a still ship."""
        return np.asarray(1000.0 * (self.r_b + (R_BC @ (np.asarray(x_c_mm) / 1000.0).T).T))

    def local(self, p_n_mm: FloatArray, k: int, measured: bool = True) -> FloatArray:
        """An earth-frame point (mm) as the crane's base frame {c} sees it at sample ``k``
        by the measured (or true) pose."""
        e = (self.eta_hat if measured else self.eta)[k]
        r = self.rotation(e[None])[0]
        body = r.T @ (np.asarray(p_n_mm) / 1000.0 - e[:3]) - self.r_b
        return np.asarray(1000.0 * (R_BC.T @ body))


def ship(sea: dict[str, Any], t: FloatArray, seed: int) -> Ship:
    """The supply vessel in the profile's ``[sea]`` along the times ``t`` (s)."""
    from ..maritime.imu import IMU
    from ..maritime.vessel import Motion, SeaState, Vessel

    hs, tp, heading = (
        float(sea.get(k, d)) for k, d in (("hs", 2.0), ("tp", 7.0), ("heading", 150.0))
    )
    r_b = np.asarray(sea.get("crane_on_deck_m", [20.0, 5.0, -4.0]), dtype=np.float64)
    seed = seed + int(sea.get("seed", 0))
    motion = Motion.simulate(Vessel(), SeaState(hs, tp, heading=heading), t, seed=seed)
    meas = IMU().measure(motion, seed=seed + 1)
    p = motion.point(r_b)
    dt = float(t[1] - t[0])
    accel = np.gradient(np.gradient(p, dt, axis=0), dt, axis=0)
    g_n = np.array([0.0, 0.0, G]) - accel  # NED: gravity points down (+z)
    rot = motion.rotation()
    g_b = np.einsum("nji,nj->ni", rot, g_n)
    g_c = (R_BC.T @ g_b.T).T
    return Ship(motion.eta, meas.eta, r_b, np.asarray(g_c))
