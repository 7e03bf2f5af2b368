"""CSV files and the Figure-4.15-like plots of the line-following case study (:mod:`.linefollow`).

Samples are the executed path (the physical TCP when the run had ground truth of it, else
``$POS_ACT``) with their XY and Z deviations; the plots show the camera image with the detected
centreline (pixels), the true, detected and executed paths on the table (base XY, mm) and the
deviation over time.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pyopenshowvar_apps.casestudies.common import CaseResult, new_figure, save_figure, write_csv

if TYPE_CHECKING:  # pragma: no cover - typing only
    from pyopenshowvar_apps.casestudies.linefollow_vision import Detection

__all__ = ["figures", "write_outputs"]


def write_outputs(
    result: CaseResult,
    out: Path,
    xyz: np.ndarray,
    t: np.ndarray,
    pts: np.ndarray,
    on: np.ndarray,
    err_xy: np.ndarray,
    err_z: np.ndarray,
) -> None:
    """CSV of the samples and of the path."""
    rows: list[list[Any]] = [
        [f"{ti:.4f}", f"{p[0]:.3f}", f"{p[1]:.3f}", f"{p[2]:.3f}", int(o), f"{e:.4f}", f"{ez:.4f}"]
        for ti, p, o, e, ez in zip(t, pts, on, err_xy, err_z, strict=True)
    ]
    result.add_file(
        write_csv(
            out / "linefollow_samples.csv",
            rows,
            ["t_s", "x_mm", "y_mm", "z_mm", "on_line", "error_xy_mm", "error_z_mm"],
        )
    )
    result.add_file(
        write_csv(
            out / "linefollow_path.csv",
            [[i, *(f"{v:.3f}" for v in p)] for i, p in enumerate(xyz, 1)],
            ["row", "x_mm", "y_mm", "z_mm"],
        )
    )


def figures(
    result: CaseResult,
    out: Path,
    det: Detection,
    detected: np.ndarray,
    reference: np.ndarray,
    t: np.ndarray,
    pts: np.ndarray,
    on: np.ndarray,
    err_xy: np.ndarray,
    err_z: np.ndarray,
) -> None:
    """The three Figure-4.15-like plots."""
    fig, ax = new_figure()
    ax.imshow(det.gray, cmap="gray", vmin=0, vmax=1)
    ax.contour(det.mask, levels=[0.5], colors="tab:blue", linewidths=0.6)
    ax.plot(
        det.path_px[:, 0], det.path_px[:, 1], color="tab:red", lw=1.2, label="detected centreline"
    )
    ax.plot(*det.path_px[0], "go", label="start")
    ax.plot(*det.path_px[-1], "rs", label="end")
    ax.set_xlabel("image x (pixels)")
    ax.set_ylabel("image y (pixels)")
    ax.set_title("Detected line and its centreline (camera image)")
    ax.legend(loc="lower right", fontsize=8)
    result.add_file(save_figure(fig, out / "linefollow_detection.png"))

    fig, ax = new_figure()
    ax.plot(
        reference[:, 1],
        reference[:, 0],
        color="black",
        lw=3,
        alpha=0.3,
        label="true centreline" if reference is not detected else "detected",
    )
    if reference is not detected:
        ax.plot(detected[:, 1], detected[:, 0], color="tab:blue", lw=1, ls="--", label="detected")
    ax.plot(pts[on, 1], pts[on, 0], color="tab:red", lw=1, label="executed")
    ax.set_xlabel("Y in $BASE (mm)")
    ax.set_ylabel("X in $BASE (mm)")
    ax.set_aspect("equal")
    ax.invert_xaxis()  # seen from above with the robot at the bottom: +Y to the left
    ax.set_title("True, detected and executed path (table, robot base)")
    ax.legend(fontsize=8)
    result.add_file(save_figure(fig, out / "linefollow_path.png"))

    fig, ax = new_figure()
    ax.plot(t[on] - t[on][0], err_xy[on], label="XY deviation")
    ax.plot(t[on] - t[on][0], err_z[on], label="Z deviation")
    ax.set_xlabel("time on the line (s)")
    what = "true centreline" if reference is not detected else "detected path"
    ax.set_ylabel(f"deviation from the {what} (mm)")
    ax.set_title(f"Tracking error: max {err_xy[on].max():.3f} mm")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    result.add_file(save_figure(fig, out / "linefollow_error.png"))
