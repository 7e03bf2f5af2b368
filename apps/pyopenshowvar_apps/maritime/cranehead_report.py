"""Outputs of ``kvp crane-head``: the CSV of a run, the sweep's CSV and plots like Figs. 8–12."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..casestudies.common import new_figure, save_figure, write_csv
from .cranehead import CraneHeadRun

__all__ = ["RUN_COLUMNS", "write_run", "write_sweep"]

_XYZ = ("x", "y", "z")
#: the run CSV's columns: every series of :class:`CraneHeadRun` flattened
RUN_COLUMNS = (
    ["t"]
    + [f"eta_{k}" for k in ("x", "y", "z", "phi", "theta", "psi")]
    + [f"eta_hat_{k}" for k in ("x", "y", "z", "phi", "theta", "psi")]
    + [
        f"{name}_{a}"
        for name in ("p_ref_t", "p_cmd_t", "p_c_t", "p_c_n", "p_s_n", "p_d_n")
        for a in _XYZ
    ]
    + [f"{name}_{i}" for name in ("alpha", "alpha_ref", "u") for i in (1, 2, 3)]
    + ["e_c", "e_s", "saturated"]
)


def write_run(run: CraneHeadRun, folder: Path, *, plots: bool = True) -> list[Path]:
    """``crane_head.csv`` (SI units: m, rad, s) and the figures of one run."""
    s = run.series
    cols = [s["t"][:, None], s["eta"], s["eta_hat"], s["p_ref_t"], s["p_cmd_t"], s["p_c_t"],
            s["p_c_n"], s["p_s_n"], s["p_d_n"], s["alpha"], s["alpha_ref"], s["u"],
            s["e_c"][:, None], s["e_s"][:, None], s["saturated"][:, None]]  # fmt: skip
    table = np.hstack(cols)
    files = [write_csv(folder / "crane_head.csv", table.tolist(), RUN_COLUMNS)]
    if plots:
        files += [_fig8(run, folder), _fig9(run, folder), _fig10(run, folder)]
        files += [_fig11(run, folder), _fig12(run, folder)]
    return files


def _fig8(run: CraneHeadRun, folder: Path) -> Path:
    s = run.series
    fig, axes = new_figure(3, 2, figsize=(10, 7), sharex=True)
    labels = ("x (m)", "y (m)", "z (m)", "φ (deg)", "θ (deg)", "ψ (deg)")
    for k in range(6):
        ax = axes[k % 3, k // 3]
        scale = 1.0 if k < 3 else 180.0 / np.pi
        ax.plot(s["t"], s["eta"][:, k] * scale, lw=0.8, label="true")
        ax.plot(s["t"], s["eta_hat"][:, k] * scale, lw=0.6, alpha=0.7, label="IMU")
        ax.set_ylabel(labels[k])
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper right")
    axes[0, 0].set_title(f"Vessel η in {{n}}, H_s = {run.config.hs:g} m (cf. paper Fig. 8)")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    return save_figure(fig, folder / "fig8_vessel_motion.png")


def _three(run: CraneHeadRun, folder: Path, name: str, title: str, lines: dict[str, Any]) -> Path:
    s = run.series
    fig, axes = new_figure(3, 1, figsize=(9, 7), sharex=True)
    for i, ax in enumerate(axes):
        for label, (values, style) in lines.items():
            ax.plot(s["t"], values[:, i], label=label, **style)
        ax.set_ylabel(f"{_XYZ[i]} (m)")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8, loc="upper right")
    axes[0].set_title(title)
    axes[-1].set_xlabel("time (s)")
    return save_figure(fig, folder / name)


def _fig9(run: CraneHeadRun, folder: Path) -> Path:
    s = run.series
    return _three(run, folder, "fig9_tcp_in_t.png", "TCP p_c^t and reference p_ref^t in {t} "
                  "(cf. paper Fig. 9)", {"p_c^t": (s["p_c_t"], {"lw": 1.0}),
                  "p_ref^t": (s["p_ref_t"], {"lw": 0.8, "ls": "--"})})  # fmt: skip


def _fig10(run: CraneHeadRun, folder: Path) -> Path:
    s = run.series
    return _three(run, folder, "fig10_tcp_in_n.png", "TCP in {n}: compensated p_c^n, still "
                  "head p_s^n, set-point p_d^n (cf. paper Fig. 10)",
                  {"p_s^n (uncompensated)": (s["p_s_n"], {"lw": 0.8, "color": "tab:red"}),
                   "p_c^n (compensated)": (s["p_c_n"], {"lw": 1.0, "color": "tab:blue"}),
                   "p_d^n": (s["p_d_n"], {"lw": 0.8, "ls": "--", "color": "k"})})  # fmt: skip


def _fig11(run: CraneHeadRun, folder: Path) -> Path:
    s, m = run.series, run.metrics
    fig, ax = new_figure(figsize=(9, 4))
    ax.plot(s["t"], s["e_s"], lw=0.8, color="tab:red", label="e_s (head still)")
    ax.plot(s["t"], s["e_c"], lw=1.0, color="tab:blue", label="e_c (compensated)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("error (m)")
    ax.set_title(f"Eq. 61: RMS e_c {m['e_c_rms_mm']:.0f} mm vs e_s {m['e_s_rms_mm']:.0f} mm "
                 f"({m['ratio_rms_pct']:.1f} %) (cf. paper Fig. 11)", fontsize=10)  # fmt: skip
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    return save_figure(fig, folder / "fig11_errors.png")


def _fig12(run: CraneHeadRun, folder: Path) -> Path:
    s = run.series
    fig, axes = new_figure(2, 1, figsize=(9, 6), sharex=True)
    for i in range(3):
        axes[0].plot(s["t"], np.degrees(s["alpha"][:, i]), lw=0.9, label=f"α{i + 1}")
        axes[1].plot(s["t"], s["u"][:, i], lw=0.9, label=f"u{i + 1}")
    lo, hi = np.degrees(run.config.tac.alpha_min), np.degrees(run.config.tac.alpha_max)
    for v in (lo, hi):
        axes[0].axhline(v, color="k", ls=":", lw=0.8)
    axes[0].set_ylabel("α (deg)")
    axes[1].set_ylabel("u_α (rad)")
    axes[0].set_title("Joint angles and motor inputs (cf. paper Fig. 12); dotted: joint range")
    for ax in axes:
        ax.legend(fontsize=8, loc="upper right")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    return save_figure(fig, folder / "fig12_alpha_u.png")


def write_sweep(
    rows: list[dict[str, float]], limit: float | None, folder: Path, *, plots: bool = True
) -> list[Path]:
    """``crane_head_sweep.csv`` and its plot: errors and saturation over H_s."""
    files = [write_csv(folder / "crane_head_sweep.csv", rows)]
    if not plots:
        return files
    hs = [r["hs_m"] for r in rows]
    fig, axes = new_figure(2, 1, figsize=(8, 7), sharex=True)
    axes[0].plot(hs, [r["e_s_rms_mm"] for r in rows], "o-", color="tab:red", label="RMS e_s")
    axes[0].plot(hs, [r["e_c_rms_mm"] for r in rows], "o-", color="tab:blue", label="RMS e_c")
    axes[0].plot(hs, [r["e_c_max_mm"] for r in rows], "x--", color="tab:blue", label="max e_c")
    axes[0].set_yscale("log")
    axes[0].set_ylabel("error (mm)")
    axes[1].plot(hs, [r["saturated_pct"] for r in rows], "o-", color="k")
    axes[1].set_ylabel("time outside the workspace (%)")
    axes[1].set_xlabel("significant wave height H_s (m)")
    for ax in axes:
        if limit is not None:
            ax.axvline(limit, color="tab:orange", ls="--", label=f"limits reached: {limit:g} m")
        ax.axvline(3.0, color="tab:gray", ls=":", label="paper: fine up to 3.0 m")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_title("Compensation over the sea state (same seed)")
    files.append(save_figure(fig, folder / "crane_head_sweep.png"))
    return files
