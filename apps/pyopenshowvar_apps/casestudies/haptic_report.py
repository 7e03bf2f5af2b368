"""Scoring, CSV and Figure 4.19 of the haptic case study (:mod:`.haptic`).

A row is one reading of the loop. Its true force comes from outside the app (the simulated
contact, the applied EMU_WRENCH). Two kinds of samples are scored:

* **settled** — the arm stood still long enough for the rest average to be settled (the force
  the app renders then); its error is what a static force measurement is worth;
* **moving** — every other row with a fresh per-cycle estimate (a consistent group whose
  cycle start was known), i.e. the dynamics-compensated estimate while the arm moves.

Rows with neither (an inconsistent group while moving) hold the previous rendered force and
are not scored; their share is ``1 − consistent_frac``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from pyopenshowvar_apps.casestudies.common import (
    CaseResult,
    new_figure,
    output_dir,
    save_figure,
    write_csv,
)

__all__ = ["report"]

#: What the thesis reports for this case study (Figure 4.19: plots, no error figures).
THESIS = {"force_err_settled_max_N": "plots only", "force_err_moving_rms_N": "plots only"}


def _stack(col: dict[str, np.ndarray], key: str) -> np.ndarray:
    return np.stack([col[f"{key}_{a}"] for a in "xyz"], axis=1)


def report(
    rows: list[dict[str, float]],
    info: dict[str, float],
    *,
    scored: bool,
    out_dir: str | Path | None,
    plots: bool,
) -> CaseResult:
    """Metrics (and files when ``out_dir`` is given) of one haptic run."""
    result = CaseResult("haptic force feedback")
    if len(rows) < 5:
        raise RuntimeError(f"only {len(rows)} haptic cycles ran")
    col = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    true, fresh, settled = _stack(col, "F_true"), _stack(col, "F_est"), _stack(col, "F_settled")
    is_settled = np.all(np.isfinite(settled), axis=1)
    is_moving = np.all(np.isfinite(fresh), axis=1) & ~is_settled
    err_settled = np.linalg.norm(settled - true, axis=1)[is_settled]
    err_moving = np.linalg.norm(fresh - true, axis=1)[is_moving]
    t = col["t"]
    m = result.metrics
    m["cycle_hz"] = float((len(rows) - 1) / (t[-1] - t[0])) if t[-1] > t[0] else math.nan
    m["consistent_frac"] = float(info.get("consistent_frac", math.nan))
    m["max_force_N"] = float(np.nanmax(np.linalg.norm(true, axis=1))) if scored else math.nan
    m["settled_samples"] = float(is_settled.sum())
    m["moving_samples"] = float(is_moving.sum())
    ok = scored and err_settled.size > 0
    m["settled_force_max_N"] = (
        float(np.linalg.norm(true[is_settled], axis=1).max()) if ok else math.nan
    )
    m["force_err_settled_max_N"] = float(err_settled.max()) if ok else math.nan
    m["force_err_settled_rms_N"] = float(np.sqrt(np.mean(err_settled**2))) if ok else math.nan
    ok = scored and err_moving.size > 0
    m["force_err_moving_rms_N"] = float(np.sqrt(np.mean(err_moving**2))) if ok else math.nan
    m["force_err_moving_p95_N"] = float(np.percentile(err_moving, 95)) if ok else math.nan
    result.thesis.update(THESIS)
    if out_dir is None:
        return result
    folder = output_dir(out_dir)
    result.add_file(write_csv(folder / "haptic.csv", rows))
    cal = folder / "haptic_calibration.json"
    cal.write_text(json.dumps(info, indent=2, sort_keys=True), encoding="utf-8")
    result.add_file(cal)
    if plots:
        result.add_file(_figure(folder, col, true, fresh, settled, is_settled))
    return result


def _figure(
    folder: Path,
    col: dict[str, np.ndarray],
    true: np.ndarray,
    fresh: np.ndarray,
    settled: np.ndarray,
    is_settled: np.ndarray,
) -> Path:
    """Figure 4.19 (a)–(d): TCP motion, joint angles, joint torques, force estimate vs truth."""
    t = col["t"]
    fig, axes = new_figure(2, 2, figsize=(12, 8), sharex=True)
    a, b, c, d = np.ravel(axes)
    for k in "xyz":  # (a) relative to the start, so the axis spans the motion, not the reach
        a.plot(t, col[f"dx_{k}"], label=k.upper())
    a.set_ylabel("TCP displacement from the start (mm)")
    a.set_title("(a) TCP motion")
    for i in range(1, 7):
        b.plot(t, col[f"q_A{i}"], label=f"A{i}")
        c.plot(t, col[f"tau_A{i}"], label=f"A{i}")
    b.set_ylabel("joint angle (deg)")
    b.set_title("(b) joint angles")
    c.set_ylabel("motor torque (Nm)")
    c.set_title("(c) joint torques ($TORQUE_AXIS_ACT)")
    colours = ("tab:blue", "tab:orange", "tab:green")
    for i, (k, colour) in enumerate(zip("xyz", colours, strict=True)):
        d.plot(t, fresh[:, i], ".", color=colour, markersize=2, alpha=0.5, label=f"F{k} estimate")
        shown = np.where(is_settled, settled[:, i], np.nan)
        d.plot(t, shown, "-", color=colour, linewidth=2.5, label=f"F{k} settled")
        d.plot(t, true[:, i], "--", color="black", linewidth=1.2, label="true" if i == 0 else None)
    d.set_ylabel("TCP force (N)")
    d.set_title("(d) force on the environment: estimate vs true")
    for ax in (a, b, c, d):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best", ncol=2 if ax is d else 1)
    for ax in (c, d):
        ax.set_xlabel("time (s)")
    fig.suptitle("Haptic force feedback (thesis Figure 4.19)")
    return save_figure(fig, folder / "fig4_19_haptic.png")
