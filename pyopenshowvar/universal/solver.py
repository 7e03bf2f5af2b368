"""The solver interface of the universal control architecture (thesis §2.2.2, eqs. 2.9, 2.10).

Every mapping method implements the same two functions, for any arm, within its joint limits:

* ``position(x_ds, q_a) -> θ_d`` — eq. 2.9, the joint angles that put the tip at the scaled
  desired position ``x_ds`` (mm, the arm's base frame), starting from the actual angles;
* ``velocity(q_a, ẋ_ds, Δt) -> θ̇_d`` — eq. 2.10, the joint velocities that move the tip at
  ``ẋ_ds`` (mm/s) for the next ``Δt`` seconds.

Units are the toolkit's: degrees and mm for joints (prismatic), deg/s and mm/s for speeds.
:class:`Solver` supplies what all methods share: the tip's batched forward kinematics, the
workspace box the target is normalised by, the wall-clock time budget, the velocity mode of
the thesis' optimisers (eqs. 3.5, 3.7: solve for ``x_t = x_a + ẋ_ds·Δt`` and divide the joint
change by ``Δt``), the limits, and :attr:`Solver.last`, what the last call achieved.
A solver keeps state between calls (the GA's elite, the swarm): one instance per arm, used
for successive targets, as the thesis does; :meth:`Solver.reset` forgets it.
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from ..arms.model import Arm
from ..kinematics.frames import FloatArray
from .pointfk import PointFK
from .workspace import Workspace, workspace_of

__all__ = [
    "BUDGET",
    "NoClosedFormError",
    "SolveInfo",
    "Solver",
]

#: The thesis' time limit per solve: "when the overall population evolution time exceeds
#: 20 ms" (GA, §3.2.1) and "exceeds 20 ms" (PSO, §3.2.2); wall-clock seconds.
BUDGET = 0.020


class NoClosedFormError(ValueError):
    """The arm has no closed-form solution this toolkit knows (use dls, ga or pso)."""


@dataclass(frozen=True)
class SolveInfo:
    """What one call achieved: the tip's remaining distance to its target by the solver's own
    forward kinematics (mm), wall-clock time (s), iterations (steps or generations), the
    method's final cost and whether it stopped on its own criterion (not on the budget)."""

    error_mm: float = math.nan
    time_s: float = 0.0
    iterations: int = 0
    cost: float = math.nan
    converged: bool = False


class Solver(ABC):
    """Base of the mapping methods (see the module docstring)."""

    name: ClassVar[str] = ""

    def __init__(
        self,
        arm: Arm,
        *,
        budget: float = BUDGET,
        tool: npt.ArrayLike | None = None,
        workspace: Workspace | None = None,
        seed: int | None = None,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        if not (budget > 0.0 and math.isfinite(budget)):
            raise ValueError(f"budget must be > 0 s, got {budget}")
        self.arm = arm
        self.budget = budget
        self.clock = clock
        self.fk = PointFK(arm, tool)
        self.workspace = workspace or workspace_of(arm, tool)
        self.rng = np.random.default_rng(seed)
        self.lower = np.array(arm.lower)
        self.upper = np.array(arm.upper)
        self.span = self.upper - self.lower
        speed = np.array(arm.max_speed)
        self.max_speed = np.where(np.isfinite(speed), speed, np.inf)
        self.last = SolveInfo()
        #: In velocity mode, the distance (mm) at which an optimiser may stop: a tenth of the
        #: step ẋ·Δt (None in position mode, where each method's target cost applies).
        self.step_tol: float | None = None

    # ------------------------------------------------------------------ the two mappings
    def position(self, x_ds: npt.ArrayLike, q_a: npt.ArrayLike) -> FloatArray:
        """Eq. 2.9: joint angles θ_d (within the limits) for the tip at ``x_ds`` (mm)."""
        x, q = self._target(x_ds), self._config(q_a)
        start = self.clock()
        out, iterations, cost, converged = self._solve(x, q, start + self.budget)
        out = np.clip(out, self.lower, self.upper)
        error = float(np.linalg.norm(self.fk(out) - x))
        self.last = SolveInfo(error, self.clock() - start, iterations, cost, converged)
        return out

    def velocity(self, q_a: npt.ArrayLike, xdot_ds: npt.ArrayLike, dt: float) -> FloatArray:
        """Eq. 2.10: joint velocities θ̇_d for the tip moving at ``xdot_ds`` (mm/s) over the
        next ``dt`` seconds (solves for x_t = x_a + ẋ_ds·Δt, eq. 3.5, and returns
        (θ_f − θ_a)/Δt, eq. 3.7). Joints that would leave their limits within ``dt`` are
        held at them; a speed above an axis' maximum scales the whole vector down."""
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f"dt must be > 0 s, got {dt}")
        q = self._config(q_a)
        xdot = self._target(xdot_ds)
        if not np.any(xdot):
            # released: stop exactly (a stochastic solver would otherwise jitter around θ_a)
            self.last = SolveInfo(0.0, 0.0, 0, 0.0, True)
            return np.zeros(self.arm.dof)
        # an optimiser's position-mode target cost (0.1 % of the workspace) is larger than
        # one step ẋ·Δt: θ_a itself would meet it and the arm would never move, so in
        # velocity mode it stops at a tenth of the step instead
        self.step_tol = 0.1 * float(np.linalg.norm(xdot)) * dt
        try:
            theta_f = self.position(self.fk(q) + xdot * dt, q)
        finally:
            self.step_tol = None
        return self.limit_rate(q, (theta_f - q) / dt, dt)

    def limit_rate(self, q_a: FloatArray, qdot: FloatArray, dt: float) -> FloatArray:
        """``qdot`` with the whole vector scaled into the speed limits, then each joint
        stopped at its position limit within ``dt``."""
        qdot = np.nan_to_num(np.asarray(qdot, dtype=np.float64))
        ratio = np.max(np.abs(qdot) / self.max_speed)
        if ratio > 1.0:
            qdot = qdot / ratio
        nxt = np.clip(q_a + qdot * dt, self.lower, self.upper)
        return np.asarray((nxt - np.clip(q_a, self.lower, self.upper)) / dt)

    def reset(self) -> None:  # noqa: B027 - optional hook: stateless solvers keep nothing
        """Forget the state carried between calls (population, swarm)."""

    # ------------------------------------------------------------------------- helpers
    @abstractmethod
    def _solve(
        self, x: FloatArray, q_a: FloatArray, deadline: float
    ) -> tuple[FloatArray, int, float, bool]:
        """θ for target ``x`` from ``q_a`` before ``deadline`` (on :attr:`clock`):
        (θ, iterations, final cost, converged)."""

    def _target(self, x: npt.ArrayLike) -> FloatArray:
        xa = np.asarray(x, dtype=np.float64)
        if xa.shape != (3,) or not np.all(np.isfinite(xa)):
            raise ValueError(f"a target is a finite X Y Z (mm); got {xa!r}")
        return xa

    def _config(self, q: npt.ArrayLike) -> FloatArray:
        qa = np.asarray(q, dtype=np.float64)
        if qa.shape != (self.arm.dof,) or not np.all(np.isfinite(qa)):
            raise ValueError(f"{self.arm.name}: θ_a must be {self.arm.dof} finite values")
        return qa

    def violation(self, q: FloatArray) -> FloatArray:
        """Per configuration: how far outside the limits, in joint ranges (0 inside)."""
        below = np.maximum(self.lower - q, 0.0)
        above = np.maximum(q - self.upper, 0.0)
        return np.asarray(np.sum((below + above) / self.span, axis=-1))
