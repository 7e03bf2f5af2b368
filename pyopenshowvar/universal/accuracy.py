"""The thesis' accuracy test (§3.2.1.1, Fig. 3.8): 512 targets in the box around the workspace.

:func:`accuracy_test` solves ``per_axis``³ equally spaced targets spanning the box that
encloses the arm's workspace (:func:`~.workspace.grid_targets`, faces included, 8 × 8 × 8 =
512 in the thesis) in position mode, one after the other with the same solver instance and
θ_a = the previous answer (as an operator's successive inputs; the GA's elite and the swarm
carry over), starting from the arm's home. Per target it records the error by the arm's own
forward kinematics (:meth:`Arm.fk`, not the solver's), the solver's own error, the time, and
whether the target is reachable at all by an exact check (:func:`reachable`).

**Reachable, exactly.** For arms with a closed form that covers position targets (the 3R crane,
the SCARA: :mod:`.closed`) every solution inside the limits is enumerated, so "no solution"
is a proof. For the others (KUKA six-axis arms — their closed form needs an orientation —,
the youBot, the iiwa) it is the arms package's batched numeric IK, position-only, to 0.01 mm,
with 64 random restarts per target and 0.1 s of CPU time each (shared by the batch, so the hard
targets get what the easy ones leave): a target it does not solve is counted unreachable
(near-certain, not a proof; :func:`reach_method` names the method per arm). The answer is
cached per arm and grid.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from ..arms.ik import solve as ik_solve
from ..arms.model import Arm
from ..kinematics.frames import FloatArray
from .closed import closed_form_for
from .factory import make_solver
from .solver import BUDGET
from .workspace import Workspace, grid_targets, workspace_of

__all__ = ["AccuracyReport", "accuracy_test", "reach_method", "reachable"]

#: Position tolerance of the numeric reachability check (m, i.e. 0.01 mm).
REACH_TOL = 1e-5


def reach_method(arm: Arm) -> str:
    """How :func:`reachable` decides for ``arm``."""
    cf = closed_form_for(arm)
    if cf is not None and cf.kind in ("3r", "scara"):
        return f"closed form ({cf.kind}, every solution inside the limits)"
    return "numeric IK, position-only, 64 restarts, 0.1 s CPU per target"


_REACH_CACHE: dict[tuple[int, bytes], npt.NDArray[np.bool_]] = {}


def reachable(arm: Arm, targets: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """Per target ``(k, 3)`` (mm): whether the tip can be put there within the limits."""
    x = np.atleast_2d(np.asarray(targets, dtype=np.float64))
    key = (id(arm), x.tobytes())
    if key not in _REACH_CACHE:
        _REACH_CACHE.clear()  # one grid at a time: bounded memory
        _REACH_CACHE[key] = _reachable(arm, x)
    return _REACH_CACHE[key].copy()


def _reachable(arm: Arm, x: FloatArray) -> npt.NDArray[np.bool_]:
    cf = closed_form_for(arm)
    if cf is not None and cf.kind in ("3r", "scara"):
        return np.asarray(np.all(np.isfinite(cf.best(x, arm.home_q)), axis=1))
    res = ik_solve(
        arm, x, arm.home_q, tol=REACH_TOL, timeout=0.1, restarts=64,
        rng=np.random.default_rng(7), clock=time.process_time,
    )  # fmt: skip
    return np.asarray(res.ok)


@dataclass
class AccuracyReport:
    """Per-target results of one run (arrays in target order) and the run's settings."""

    arm: Arm
    solver: str
    workspace: Workspace
    targets: FloatArray
    reachable: npt.NDArray[np.bool_]
    q: FloatArray
    error_mm: FloatArray
    solver_error_mm: FloatArray
    time_s: FloatArray
    budget_s: float
    clock: str
    reach_method: str
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def error_pct(self) -> FloatArray:
        """Errors in per cent of the workspace box's largest side (the thesis' Fig. 3.8)."""
        return np.asarray(100.0 * self.error_mm / self.workspace.scale)

    def summary(self) -> dict[str, Any]:
        """The JSON of ``kvp arms bench --json``."""
        r = self.reachable

        def pct(
            values: FloatArray, qs: tuple[float, ...], names: tuple[str, ...]
        ) -> dict[str, Any]:
            if not len(values):
                return {n: None for n in names}
            return {
                n: round(float(np.percentile(values, q)), 4) for n, q in zip(names, qs, strict=True)
            }

        stats = ((50.0, 95.0, 100.0), ("p50", "p95", "max"))
        return {
            "arm": self.arm.key or self.arm.name,
            "solver": self.solver,
            "targets": len(self.targets),
            "reachable": int(np.sum(r)),
            "error_mm": pct(self.error_mm[r], *stats),
            "error_pct": pct(self.error_pct[r], *stats),
            "unreachable_error_mm": pct(self.error_mm[~r], *stats),
            "time_ms": pct(1e3 * self.time_s, (50.0, 99.0), ("p50", "p99")),
            "budget_ms": round(1e3 * self.budget_s, 3),
            "clock": self.clock,
            "workspace_mm": {
                "lower": [round(float(v), 3) for v in self.workspace.lower],
                "upper": [round(float(v), 3) for v in self.workspace.upper],
                "scale": round(self.workspace.scale, 3),
            },
            "reach_check": self.reach_method,
            **self.extra,
        }

    def rows(self) -> list[list[Any]]:
        """The CSV of ``--dump``: one row per target (see :data:`DUMP_HEADER`)."""
        out = []
        for i in range(len(self.targets)):
            out.append(
                [i, *(round(float(v), 4) for v in self.targets[i]), int(self.reachable[i]),
                 *(round(float(v), 6) for v in self.q[i]), round(float(self.error_mm[i]), 6),
                 round(float(self.solver_error_mm[i]), 6), round(float(self.error_pct[i]), 6),
                 round(1e3 * float(self.time_s[i]), 4)]
            )  # fmt: skip
        return out

    def dump_header(self) -> list[str]:
        joints = [f"q_{name}" for name in self.arm.joint_names]
        return ["index", "x_mm", "y_mm", "z_mm", "reachable", *joints, "error_mm",
                "solver_error_mm", "error_pct", "time_ms"]  # fmt: skip


def accuracy_test(
    arm: Arm,
    solver: str,
    *,
    per_axis: int = 8,
    budget: float = BUDGET,
    seed: int = 0,
    clock: Callable[[], float] = time.perf_counter,
    progress: Callable[[int, int], None] | None = None,
    **options: Any,
) -> AccuracyReport:
    """Run the test (see the module docstring); ``options`` go to the solver."""
    box = workspace_of(arm)
    targets = grid_targets(box, per_axis)
    reach = reachable(arm, targets)
    s = make_solver(solver, arm, budget=budget, seed=seed, clock=clock, **options)
    n = len(targets)
    qs = np.zeros((n, arm.dof))
    own, times = np.zeros(n), np.zeros(n)
    q = np.array(arm.home_q)
    for i, x in enumerate(targets):
        q = s.position(x, q)
        qs[i], own[i], times[i] = q, s.last.error_mm, s.last.time_s
        if progress is not None:
            progress(i + 1, n)
    err = np.linalg.norm(arm.fk(qs)[:, :3, 3] - targets, axis=1)
    name = "cpu" if clock is time.process_time else "wall"
    return AccuracyReport(
        arm, s.name, box, targets, reach, qs, err, own, times, budget, name, reach_method(arm),
        extra={"load_average": [round(v, 2) for v in _loadavg()]},
    )  # fmt: skip


def _loadavg() -> tuple[float, ...]:
    try:
        import os

        return tuple(os.getloadavg())
    except OSError:  # pragma: no cover - not on every platform
        return (math.nan,) * 3
