"""Outputs of ``kvp underwater-plan``: the postures and the transitions as CSV, a 3D figure."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..casestudies.common import new_figure, save_figure, write_csv
from .underwater import Plan
from .uw_scenario import link_points

__all__ = ["write_plans"]


def _variant(plan: Plan) -> str:
    return "drag" if plan.drag else "no_drag"


def write_plans(plans: list[Plan], folder: Path, *, plots: bool = True) -> list[Path]:
    """``underwater_path.csv`` (one row per planned posture), ``underwater_transitions.csv``
    (every sampled joint vector between postures: what the clearance and eq. 8 are taken
    over) and ``underwater_plan.png``. Lengths in mm, angles in degrees, areas in mm²."""
    dof = len(plans[0].points[0].q)
    qs = [f"q{i + 1}" for i in range(dof)]
    rows: list[list[Any]] = []
    trans: list[list[Any]] = []
    for plan in plans:
        v = _variant(plan)
        for k, p in enumerate(plan.points):
            rows.append([v, k, *p.cube, *plan.scenario.mm(p.cube), *p.tip, *p.q, p.e1, p.e2,
                         p.e3, p.clearance, p.area, p.candidates, p.rank, p.regenerations])  # fmt: skip
            for j, q in enumerate(p.transition):
                trans.append([v, k, j, *q])
    header = ["variant", "index", "cube_x", "cube_y", "cube_z", "target_x", "target_y",
              "target_z", "tip_x", "tip_y", "tip_z", *qs, "e1", "e2", "e3", "clearance",
              "area", "candidates", "rank", "regenerations"]  # fmt: skip
    files = [
        write_csv(folder / "underwater_path.csv", rows, header),
        write_csv(
            folder / "underwater_transitions.csv", trans, ["variant", "index", "sample", *qs]
        ),
    ]
    if plots:
        files.append(_figure(plans, folder))
    return files


def _box(ax: Any, lo: np.ndarray, hi: np.ndarray) -> None:
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # type: ignore[import-untyped]

    x, y, z = np.array([lo, hi]).T
    corners = np.array([[x[i], y[j], z[k]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    faces = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]]
    ax.add_collection3d(Poly3DCollection([corners[f] for f in faces], alpha=0.35,
                                         facecolor="tab:red", edgecolor="darkred"))  # fmt: skip


def _figure(plans: list[Plan], folder: Path) -> Path:
    fig, _ = new_figure(1, len(plans), figsize=(7 * len(plans), 6.5))
    fig.clf()
    for n, plan in enumerate(plans):
        sc = plan.scenario
        arm = sc.load_arm()
        ax = fig.add_subplot(1, len(plans), n + 1, projection="3d")
        lo, hi = sc.boxes_mm()
        for b in range(len(lo)):
            _box(ax, lo[b], hi[b])
        tips = np.array([p.tip for p in plan.points])
        ax.plot(*tips.T, color="tab:blue", lw=2.0, label="tip path")
        every = max(1, len(plan.points) // 8)
        for k in [*range(0, len(plan.points), every), len(plan.points) - 1]:
            pts = link_points(arm, plan.points[k].q, sc.base)
            ax.plot(*pts.T, color="0.35", lw=1.2, marker="o", ms=2)
        ax.scatter(*sc.mm(sc.start), color="tab:green", s=40, label="start")
        ax.scatter(*sc.mm(sc.goal), color="k", marker="*", s=80, label="goal")
        m = plan.metrics()
        ax.set_title(f"{'with' if plan.drag else 'without'} the drag term e3: "
                     f"∫A {m['drag_area_integral_m2']:.2f} m², clearance "
                     f"{m['min_clearance_mm']:.1f} mm", fontsize=9)  # fmt: skip
        ax.set_xlabel("X (mm)")
        ax.set_ylabel("Y (mm)")
        ax.set_zlabel("Z (mm)")
        ax.set_box_aspect((1, 1, 1))
        ax.legend(fontsize=7, loc="upper left")
    fig.suptitle("Path and postures (cf. Ishibashi et al., Figs. 10 and 11); flow along Z")
    return save_figure(fig, folder / "underwater_plan.png")
