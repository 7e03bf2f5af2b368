"""Outputs of the heave experiment: CSV files, the thesis' Figure 4.24 and a platform-motion plot."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..casestudies.common import new_figure, save_figure, write_csv
from .experiment import AXES, GroundTruth, HeaveResult

__all__ = ["write_outputs"]


def write_outputs(
    result: HeaveResult, server: Any, phases: dict[str, float], folder: Path, *, plots: bool = True
) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    s = result.series
    t0 = phases["t0"]
    header = ["t", "compensation", *(f"world_{a}" for a in AXES), *(f"setpoint_{a}" for a in AXES),
              *(f"error_{a}" for a in AXES)]  # fmt: skip
    rows = np.column_stack([s["t"], s["comp"], s["world"], s["x_s"], s["err"]])
    if "truth" in s:
        header += list(GroundTruth.COLUMNS[4:])
        rows = np.column_stack([rows, s["truth"][:, 4:]])
    result.files.append(write_csv(folder / "heave_world.csv", rows.tolist(), header))
    control = list(server.rows)
    for r in control:
        r["t"] -= t0
    result.files.append(write_csv(folder / "heave_control.csv", control))
    plat = list(server.platform_rows)
    for r in plat:
        r["t"] -= t0
    result.files.append(write_csv(folder / "platform_measured.csv", plat))
    if plots:
        result.files.append(_fig_4_24(result, phases, folder))
        result.files.append(_platform_plot(result, plat, control, folder))


def _shade(ax: Any, phases: dict[str, float]) -> None:
    t0 = phases["t0"]
    ax.axvspan(phases["off_start"] - t0, phases["switch"] - t0, color="tab:red", alpha=0.12,
               label="no compensation")  # fmt: skip


def _fig_4_24(result: HeaveResult, phases: dict[str, float], folder: Path) -> Path:
    s = result.series
    # the experiment only: not the robot's way to its start pose, nor the parking afterwards
    keep = (s["t"] >= 0.0) & (s["t"] <= phases["end"] - phases["t0"])
    t = s["t"][keep]
    fig, axes = new_figure(3, 1, figsize=(9, 8), sharex=True)
    for i, (ax, a) in enumerate(zip(axes, AXES, strict=True)):
        _shade(ax, phases)
        ax.plot(t, s["world"][keep, i], lw=1.0, label="end-effector (world)")
        ax.plot(t, s["x_s"][keep, i], lw=0.8, ls="--", color="k", label="set-point x_s")
        att = result.metrics.get(f"attenuation_rms_{a}", float("nan"))
        ax.set_ylabel(f"{a.upper()} (mm)")
        ax.set_title(f"{a.upper()}: RMS attenuation {att:.1f} %", fontsize=9, loc="right")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="upper left", fontsize=8)
    axes[0].set_title("End-effector world position (thesis Figure 4.24)", loc="left")
    axes[-1].set_xlabel("time (s)")
    return save_figure(fig, folder / "fig4_24_end_effector.png")


def _platform_plot(
    result: HeaveResult, plat: list[dict[str, float]], control: list[dict[str, float]], folder: Path
) -> Path:
    s = result.series
    fig, axes = new_figure(4, 1, figsize=(9, 10), sharex=True)
    tp = np.array([r["t"] for r in plat])
    tc = np.array([r["t"] for r in control])
    attitude = result.info.get("attitude", "")
    labels = [("heave", "heave z (mm)", "est_z"), ("roll", "roll φ (deg)", "est_phi"),
              ("pitch", "pitch θ (deg)", "est_theta")]  # fmt: skip
    for k, (ax, (key, label, est)) in enumerate(zip(axes, labels, strict=False)):
        if "truth" in s:
            ax.plot(s["t"], s["truth"][:, 7 + k], lw=1.2, label="true (simulator)")
        ax.plot(tp, [r[key] for r in plat], lw=0.8, label="PLC (Modbus)")
        ax.plot(tc, [r[est] for r in control], lw=0.8, alpha=0.8,
                label="server estimate" + (f" ({attitude})" if k else ""))  # fmt: skip
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="upper left", fontsize=8)
    axes[0].set_title("Platform motion: eq. 4.13 waves through the PLC's motors")
    for j in range(3):
        axes[3].plot(tp, [r[f"beta{j + 1}"] for r in plat], lw=0.9, label=f"β{j + 1}")
    axes[3].set_ylabel("joint β (deg)")
    axes[3].legend(loc="upper left", fontsize=8)
    axes[3].grid(True, alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    return save_figure(fig, folder / "platform_motion.png")
