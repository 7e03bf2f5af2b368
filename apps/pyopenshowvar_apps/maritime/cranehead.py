"""The crane-head simulation of Henriksen et al. §8–10: the TAC compensating a vessel's motion.

One run (:func:`simulate`): the supply vessel moves in a sea of significant wave height H_s
(:mod:`.vessel`); the motion sensor (:mod:`.imu`) reports η̂, ν̂; the crane stands in the
stationary configuration of eq. 60; the controller computes, from the **measured** motion,

* p_ref^t = R_n^t (p_d^n − o_t^n) (eqs. 49–50), checked against the workspace (a point out
  of reach is moved back towards the set-point until reachable: "saturation", §6);
* v_ref^t, its time derivative (eqs. 52–54, with ν's body-frame rates rotated explicitly);
* α_ref = IPK(p_ref^t) (eq. 51), α̇_ref = J⁻¹ v_ref^t (eq. 56);
* per arm a PID (eq. 57: K_p 10, K_i 60, K_d 1) driving a DC motor α/u = K_DC/(T_DC s + 1)
  (eq. 58: K_DC 1, T_DC 0.2 s), sampled at ``dt`` with the motor integrated exactly.

The TCP p_c^t = FPK(α) is then placed in the world with the **true** motion and compared with
the set-point: e_c = ‖p_d^n − p_c^n‖, and e_s = ‖p_d^n − p_s^n‖ for the head held still (eq. 61).
The set-point p_d^t = [x_d, 0, 0] is the on-axis centre of the workspace (§8).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from .crane import STATIONARY, ShipCrane
from .delta import TAC, Workspace, fpk, ipk, jacobian, workspace
from .imu import IMU
from .vessel import Motion, SeaState, Vessel, euler_rotation, sea_state_code

__all__ = ["CraneHeadConfig", "CraneHeadRun", "simulate", "sweep"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class CraneHeadConfig:
    """Everything a run depends on; the defaults are the paper's (Table 4) and ours (sea, IMU)."""

    hs: float = 3.0
    tp: float | None = None
    heading: float = 150.0
    spectrum: str = "jonswap"
    duration: float = 300.0  # s, recorded
    warmup: float = 30.0  # s simulated before the record (the PID settles), not recorded
    dt: float = 0.02  # s, control period
    seed: int = 1
    imu_scale: float = 1.0  # 0: a perfect sensor
    compensate: bool = True
    kp: float = 10.0
    ki: float = 60.0
    kd: float = 1.0
    k_dc: float = 1.0
    t_dc: float = 0.2
    tac: TAC = field(default_factory=TAC)
    vessel: Vessel = field(default_factory=Vessel)
    grid: float = 0.2  # m, workspace grid step h

    def sea(self) -> SeaState:
        return SeaState(self.hs, self.tp, spectrum=self.spectrum, heading=self.heading)  # type: ignore[arg-type]


@dataclass
class CraneHeadRun:
    """One run: the series (arrays over time) and the headline metrics."""

    config: CraneHeadConfig
    series: dict[str, FloatArray]
    metrics: dict[str, float]
    info: dict[str, Any]


def _skew(w: FloatArray) -> FloatArray:
    z = np.zeros(len(w))
    return np.stack(
        [z, -w[:, 2], w[:, 1], w[:, 2], z, -w[:, 0], -w[:, 1], w[:, 0], z], axis=-1
    ).reshape(-1, 3, 3)


def _saturate(
    tac: TAC, p: FloatArray, centre: FloatArray
) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Points moved back along the line to ``centre`` until reachable (bisection); the mask
    of the points that had to move."""
    out = tac.reachable(p)
    if out.all():
        return p, np.zeros(len(p), dtype=bool)
    bad = ~out
    lo = np.zeros(int(bad.sum()))  # fraction of the way back that is known reachable... from 1
    hi = np.ones(int(bad.sum()))
    d = p[bad] - centre
    for _ in range(30):  # 1e-9 of the excursion
        mid = (lo + hi) / 2.0
        ok = tac.reachable(centre + mid[:, None] * d)
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
    q = p.copy()
    q[bad] = centre + lo[:, None] * d
    return q, bad


def simulate(cfg: CraneHeadConfig, ws: Workspace | None = None) -> CraneHeadRun:
    """One run of the compensation (or of the head held still, ``compensate=False``)."""
    tac = cfg.tac
    ws = ws or workspace(tac, cfg.grid)
    x_d, margin = ws.axis_centre
    p_d_t = np.array([x_d, 0.0, 0.0])
    alpha_d = ipk(tac, p_d_t)
    crane = ShipCrane()
    t_tb = crane.head_frame(STATIONARY)
    r_tb, o_tb = t_tb[:3, :3], t_tb[:3, 3]
    p_d_n = o_tb + r_tb @ p_d_t  # the TCP with the vessel at rest (o_b^n = 0, R_b^n = I)

    n_warm = round(cfg.warmup / cfg.dt)
    n = round(cfg.duration / cfg.dt) + 1
    t = (np.arange(n_warm + n) - n_warm) * cfg.dt
    motion = Motion.simulate(cfg.vessel, cfg.sea(), t, seed=cfg.seed)
    meas = IMU().scaled(cfg.imu_scale).measure(motion, seed=cfg.seed + 1000)

    # ---- references from the measured motion (eqs. 49-56), all time steps at once
    r_hat = euler_rotation(meas.eta[:, 3], meas.eta[:, 4], meas.eta[:, 5])
    o_t_n = meas.eta[:, :3] + r_hat @ o_tb  # eq. 49
    p_ref_n = p_d_n - o_t_n
    r_nt = np.einsum("ji,tkj->tik", r_tb, r_hat)  # R_n^t = R_tbᵀ R̂ᵀ
    p_ref = np.einsum("tij,tj->ti", r_nt, p_ref_n)  # eq. 50
    v_b, w_b = meas.nu[:, :3], meas.nu[:, 3:]
    s_w = _skew(w_b)
    dp_ref_n = -np.einsum("tij,tj->ti", r_hat @ s_w, np.broadcast_to(o_tb, (len(t), 3)))
    dp_ref_n -= np.einsum("tij,tj->ti", r_hat, v_b)
    r_hat_t = r_hat.transpose(0, 2, 1)
    v_ref = -np.einsum("ij,tjk,tkl,tl->ti", r_tb.T, s_w, r_hat_t, p_ref_n)
    v_ref += np.einsum("tij,tj->ti", r_nt, dp_ref_n)  # eqs. 52-54
    p_cmd, saturated = _saturate(tac, p_ref, p_d_t)
    v_ref[saturated] = 0.0
    alpha_ref = ipk(tac, p_cmd)  # eq. 51
    dalpha_ref = np.linalg.solve(jacobian(tac, p_cmd, alpha_ref), v_ref[..., None])[..., 0]

    # ---- PID (eq. 57) and DC motors (eq. 58): per arm a linear discrete system
    if cfg.compensate:
        alpha, u = _pid_motor(cfg, alpha_ref, dalpha_ref, alpha_d)
    else:
        alpha = np.broadcast_to(alpha_d, alpha_ref.shape).copy()
        u = alpha / cfg.k_dc

    # ---- the TCP in the world with the true motion (eq. 61)
    keep = slice(n_warm, None)
    r_true = motion.rotation()[keep]
    o_true = motion.eta[keep, :3]
    p_c_t = fpk(tac, alpha[keep])
    p_c_n = o_true + np.einsum("tij,tj->ti", r_true, o_tb + p_c_t @ r_tb.T)
    p_s_n = o_true + r_true @ (o_tb + r_tb @ p_d_t)
    e_c = np.linalg.norm(p_d_n - p_c_n, axis=1)
    e_s = np.linalg.norm(p_d_n - p_s_n, axis=1)
    series = {
        "t": t[keep], "eta": motion.eta[keep], "eta_hat": meas.eta[keep],
        "p_ref_t": p_ref[keep], "p_cmd_t": p_cmd[keep], "p_c_t": p_c_t,
        "p_c_n": p_c_n, "p_s_n": p_s_n, "p_d_n": np.broadcast_to(p_d_n, p_c_n.shape),
        "alpha": alpha[keep], "alpha_ref": alpha_ref[keep], "u": u[keep],
        "e_c": e_c, "e_s": e_s, "saturated": saturated[keep].astype(np.float64),
    }  # fmt: skip
    metrics = _metrics(series, tac)
    info = {"x_d_m": x_d, "workspace_margin_m": margin, "workspace_volume_m3": ws.volume,
            "alpha_d_deg": np.degrees(alpha_d).tolist(), "head_in_b_m": o_tb.tolist(),
            "sea_state": sea_state_code(cfg.hs), "tp_s": cfg.sea().peak_period}  # fmt: skip
    return CraneHeadRun(cfg, series, metrics, info)


def _pid_motor(
    cfg: CraneHeadConfig, alpha_ref: FloatArray, dalpha_ref: FloatArray, alpha_d: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """α and u of the three arms under eq. 57 on the motors of eq. 58, sampled at ``dt``.

    The D term acts on α̇, which eq. 58 ties to u at the same instant (α̇ = (K u − α)/T), so
    u = K_p α̃ + K_i ∫α̃ + K_d (α̇_ref − (K u − α)/T) is solved for u, as a continuous-time
    simulation resolves that algebraic loop (feeding back the last sample's speed instead
    gives u_k ≈ −(K_d K/T) u_{k−1} = −5 u_{k−1}: unstable at any sampling period). With
    the motor integrated exactly over a sample (zero-order hold), state x = [α, ∫α̃] and
    inputs [α_ref, α̇_ref], each arm is one linear discrete system. It starts at rest where
    it holds α_d (α = α_d, α̇ = 0, u = α_d / K_DC, the integrator at α_d / (K_DC K_i)), so its
    output is that rest plus the zero-state response to the inputs' departure from it,
    filtered as transfer functions (scipy.signal.ss2tf, lfilter).
    """
    from scipy.signal import lfilter, ss2tf

    kp, ki, kd, k, tm, dt = cfg.kp, cfg.ki, cfg.kd, cfg.k_dc, cfg.t_dc, cfg.dt
    g = 1.0 / (1.0 + kd * k / tm)
    a_m = math.exp(-dt / tm)
    # u = c_u·x + d_u·[α_ref, α̇_ref]
    c_u = g * np.array([-kp + kd / tm, ki])
    d_u = g * np.array([kp, kd])
    b_m = (1.0 - a_m) * k
    a = np.array([[a_m + b_m * c_u[0], b_m * c_u[1]], [-dt, 1.0]])
    b = np.array([[b_m * d_u[0], b_m * d_u[1]], [dt, 0.0]])
    c = np.array([[1.0, 0.0], c_u])
    d = np.array([[0.0, 0.0], d_u])
    inputs = (alpha_ref - alpha_d, dalpha_ref)
    alpha = np.broadcast_to(alpha_d, alpha_ref.shape).copy()
    u = alpha / k
    for j, x in enumerate(inputs):
        num, den = ss2tf(a, b, c, d, input=j)
        alpha += lfilter(num[0], den, x, axis=0)
        u += lfilter(num[1], den, x, axis=0)
    return alpha, u


def _rms(x: FloatArray) -> float:
    return float(np.sqrt(np.mean(x * x)))


def _metrics(s: dict[str, FloatArray], tac: TAC) -> dict[str, float]:
    e_c, e_s = s["e_c"], s["e_s"]
    alpha = np.degrees(s["alpha"])
    rms_c, rms_s = _rms(e_c) * 1000.0, _rms(e_s) * 1000.0
    return {
        "e_c_rms_mm": rms_c,
        "e_c_max_mm": float(e_c.max()) * 1000.0,
        "e_s_rms_mm": rms_s,
        "e_s_max_mm": float(e_s.max()) * 1000.0,
        "ratio_rms_pct": 100.0 * rms_c / rms_s if rms_s > 0 else math.nan,
        "ratio_max_pct": 100.0 * float(e_c.max() / e_s.max()) if e_s.max() > 0 else math.nan,
        "saturated_pct": 100.0 * float(np.mean(s["saturated"])),
        "alpha_min_deg": float(alpha.min()),
        "alpha_max_deg": float(alpha.max()),
        "u_max_abs": float(np.abs(s["u"]).max()),
    }


def sweep(
    base: CraneHeadConfig, heights: list[float]
) -> tuple[list[dict[str, float]], float | None]:
    """Runs over H_s; rows of metrics, and the smallest H_s whose references left the
    workspace (None if none did)."""
    ws = workspace(base.tac, base.grid)
    rows: list[dict[str, float]] = []
    limit: float | None = None
    for hs in heights:
        run = simulate(replace(base, hs=hs), ws)
        row = {"hs_m": hs, "sea_state": float(sea_state_code(hs)), **run.metrics}
        rows.append(row)
        if limit is None and run.metrics["saturated_pct"] > 0.0:
            limit = hs
    return rows, limit
