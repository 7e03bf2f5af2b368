"""Outputs of ``kvp crane-bench``: per-step CSVs and plots like the thesis' Figs. 5.5–5.12.

Per run and solver, ``<prefix>_<solver>.csv`` holds the calm flight sample by sample (targets,
calculated and actual positions, joint angles, torques, valve commands, rod forces, solve
times) and, with the heave test, ``<prefix>_<solver>_heave.csv`` the earth-frame target and
the tip without and with compensation. Plots are drawn for the first (most probable) run.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..casestudies.common import new_figure, save_figure, write_csv
from .bench import Trace
from .suite import SuiteResult

__all__ = ["HEAVE_COLUMNS", "RUN_COLUMNS", "write_outputs"]

_XYZ = ("x", "y", "z")
_J = ("slew", "boom", "jib")
RUN_COLUMNS = (
    ["t"]
    + [f"{n}_{a}" for n in ("x_d", "x_t", "x_c", "x_a") for a in _XYZ]
    + [f"{n}_{j}" for n in ("theta_t", "theta_c", "theta_a", "tau", "spool") for j in _J]
    + ["rod_force_boom", "rod_force_jib", "solve_ms"]
)
HEAVE_COLUMNS = ["t"] + [f"{n}_{a}" for n in ("target_n", "off_n", "on_n") for a in _XYZ]


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")


def write_outputs(result: SuiteResult, folder: Path, *, plots: bool = True) -> list[Path]:
    """Write the CSVs (and PNGs) of ``result`` into ``folder``; return the paths."""
    files: list[Path] = []
    single = len(result.runs) == 1
    for index, res in enumerate(result.runs):
        prefix = "crane_bench" if single else f"run{index + 1}"
        for name, traces in res.traces.items():
            calm = traces["calm"]
            table = np.hstack([calm.t[:, None], calm.x_d, calm.x_t, calm.x_c, calm.x_a,
                               calm.theta_t, calm.theta_c, calm.theta_a, calm.tau, calm.spool,
                               calm.rod_force, calm.solve_ms[:, None]])  # fmt: skip
            files.append(
                write_csv(folder / f"{prefix}_{_slug(name)}.csv", table.tolist(), RUN_COLUMNS)
            )
            if "on" in traces:
                off, on = traces["off"], traces["on"]
                assert off.earth_target is not None and off.earth_actual is not None
                assert on.earth_actual is not None
                heave = np.hstack(
                    [off.t[:, None], off.earth_target, off.earth_actual, on.earth_actual]
                )
                files.append(write_csv(folder / f"{prefix}_{_slug(name)}_heave.csv",
                                       heave.tolist(), HEAVE_COLUMNS))  # fmt: skip
            if plots and index == 0:
                files += _figures(name, traces, folder)
    return files


def _figures(name: str, traces: dict[str, Trace], folder: Path) -> list[Path]:
    calm, slug = traces["calm"], _slug(name)
    out = []
    fig, axes = new_figure(3, 1, figsize=(9, 7), sharex=True)
    for i, ax in enumerate(axes):
        ax.plot(calm.t, calm.x_a[:, i] / 1000, lw=1.2, label="actual")
        ax.plot(calm.t, calm.x_d[:, i] / 1000, lw=0.9, ls="--", color="k", label="desired")
        ax.plot(calm.t, calm.x_c[:, i] / 1000, lw=0.8, alpha=0.8, label="calculated")
        ax.set_ylabel(f"{_XYZ[i].upper()} (m)")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8, loc="best")
    axes[0].set_title(f"Tracking of X, Y, Z with {name} (cf. thesis Figs. 5.5/5.6)")
    axes[-1].set_xlabel("time (s)")
    out.append(save_figure(fig, folder / f"fig5_5_tracking_{slug}.png"))

    fig, ax = new_figure(figsize=(9, 4))
    ax.plot(
        calm.t, np.linalg.norm(calm.x_t - calm.x_c, axis=1), lw=1.0, label="eq. 5.2 |x_t − x_c|"
    )
    ax.plot(calm.t, np.linalg.norm(calm.x_d - calm.x_a, axis=1), lw=0.8, label="|x_d − x_actual|")
    ax.set_ylabel("position error (mm)")
    ax.set_xlabel("time (s)")
    ax.set_title(f"Position error with {name} (cf. thesis Figs. 5.7/5.8)")
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    out.append(save_figure(fig, folder / f"fig5_7_error_{slug}.png"))

    fig, axes = new_figure(3, 1, figsize=(9, 7), sharex=True)
    for i, ax in enumerate(axes):
        ax.plot(calm.t, calm.tau[:, i] / 1000, lw=1.0)
        ax.set_ylabel(f"τ {_J[i]} (kN·m)")
        ax.grid(True, alpha=0.3)
    axes[0].set_title(f"Joint torques with {name} (cf. thesis Figs. 5.9/5.10)")
    axes[-1].set_xlabel("time (s)")
    out.append(save_figure(fig, folder / f"fig5_9_torque_{slug}.png"))

    if "on" in traces:
        off, on = traces["off"], traces["on"]
        assert off.earth_target is not None and off.earth_actual is not None
        assert on.earth_actual is not None
        fig, axes = new_figure(3, 2, figsize=(11, 7), sharex=True)
        for col, (trace, label) in enumerate(((off, "(a) without"), (on, "(b) with"))):
            assert trace.earth_actual is not None
            for i in range(3):
                ax = axes[i, col]
                ax.plot(trace.t, trace.earth_actual[:, i] / 1000, lw=1.0, label="actual")
                ax.plot(trace.t, off.earth_target[:, i] / 1000, lw=0.9, ls="--", color="k",
                        label="target")  # fmt: skip
                ax.set_ylabel(f"{'NED'[i]} (m)")
                ax.grid(True, alpha=0.3)
            axes[0, col].set_title(f"{label} heave compensation, {name}", fontsize=10)
            axes[-1, col].set_xlabel("time (s)")
        axes[0, 0].legend(fontsize=8)
        out.append(save_figure(fig, folder / f"fig5_11_heave_{slug}.png"))
    return out
