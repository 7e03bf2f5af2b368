"""The particle-swarm solver of the thesis (§3.2.2, Fig. 3.9): IK learnt from the FK alone.

As the thesis sets it up:

* a particle is a set of joint angles within the limits; 10 particles per DOF, initialised
  with random positions and velocities;
* cost = α·a + β·b (eq. 3.12) with α = 0.8, β = 0.2: ``a`` the distance between the target
  and the particle's tip (eq. 3.8) in workspace-normalised units, ``b`` the change from the
  actual configuration θ_a (eq. 3.11), here the root mean square of the per-joint changes in
  joint ranges (so ``a`` and ``b`` are both of order 1 across the workspace);
* velocity update ``v ← w·v + c1·R1·(pbest − s) + c2·R2·(gbest − s)`` (eq. 3.13), position
  ``s ← s + v`` (eq. 3.14), R1 and R2 uniform in [0, 1] per particle and joint; a particle
  that hits a joint limit stops there (its velocity component is zeroed) and |v| is capped
  at :data:`VMAX` of each joint's range per iteration;
* stop when the global best cost drops below 0.01 or after the time budget (20 ms);
  position mode returns the global best (eq. 3.15), velocity mode (θ − θ_a)/Δt (eq. 3.16);
* the same swarm serves successive targets ("the same instance of PSO is continuously
  used"): each call starts a fresh random swarm in which the previous call's best fifth of
  personal bests (re-scored against the new target and θ_a) and θ_a itself take part; a
  swarm carried over whole collapses onto the last target and, as we measured, cannot leave
  a joint-limit corner for a target across the workspace.

**w, c1, c2.** The thesis chose c1 and c2 "through a higher level optimisation process"
without printing them. Ours is a grid search over w and c1 = c2 on random reachable targets of
the thesis' three arms after a fixed number of iterations (bench/universal_pso_tune.py;
docs/universal.md has the table). Its winner by the 90th percentile of the error is w = 0.5
with c1 = c2 = 1.49618: Clerc and Kennedy's learning factors (the standard constriction
choice) with less inertia than their w = 0.7298, which converges too slowly for a 20 ms budget
(median 0.027 % of the workspace and 90th percentile 0.32 % after 50 iterations, against
0.0002 % and 0.061 %).

Because ``b`` is measured from θ_a, a position-mode target far from the arm leaves β·b above
0.01 even at the exact solution: the swarm then uses its whole budget (eq. 3.12's trade-off,
reported in docs/universal.md). ``b`` also makes the swarm prefer, of several solutions, the
one needing the least joint motion (the thesis' reason for it: redundant arms).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..arms.model import Arm
from ..kinematics.frames import FloatArray
from .solver import Solver

__all__ = ["C1", "C2", "VMAX", "PSOSolver", "W"]

#: Inertia weight and learning factors (see the module docstring for how they were chosen).
W = 0.5
C1 = 1.49618
C2 = 1.49618
#: Largest velocity per iteration, in joint ranges.
VMAX = 0.2


class PSOSolver(Solver):
    """The thesis' PSO (see the module docstring); options are its parameters."""

    name = "pso"

    def __init__(
        self,
        arm: Arm,
        *,
        per_dof: int = 10,
        w: float = W,
        c1: float = C1,
        c2: float = C2,
        alpha: float = 0.8,
        beta: float = 0.2,
        target_cost: float = 0.01,
        vmax: float = VMAX,
        carry: float = 0.2,
        seed_actual: bool = True,
        max_iterations: int | None = None,
        **options: Any,
    ) -> None:
        super().__init__(arm, **options)
        self.size = max(2, per_dof * arm.dof)
        self.w, self.c1, self.c2 = w, c1, c2
        self.alpha, self.beta = alpha, beta
        self.target_cost = target_cost
        self.vmax = vmax * self.span
        self.carry = round(carry * self.size)
        self.seed_actual = seed_actual
        #: A fixed number of iterations instead of the budget (reproducible benchmarks).
        self.max_iterations = max_iterations
        self.pbest: FloatArray | None = None

    def reset(self) -> None:
        self.pbest = None

    def cost(
        self, pop: FloatArray, target_n: FloatArray, q_a: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """(α·a + β·b, a) (eqs. 3.8, 3.11, 3.12), normalised as in the module docstring."""
        a = np.linalg.norm(self.workspace.normalise(self.fk(pop)) - target_n, axis=-1)
        b = np.sqrt(np.mean(((pop - q_a) / self.span) ** 2, axis=-1))
        return np.asarray(self.alpha * a + self.beta * b), np.asarray(a)

    def _solve(
        self, x: FloatArray, q_a: FloatArray, deadline: float
    ) -> tuple[FloatArray, int, float, bool]:
        rng, n, size = self.rng, self.arm.dof, self.size
        target_n = self.workspace.normalise(x)
        s = rng.uniform(self.lower, self.upper, size=(size, n))
        v = rng.uniform(-1.0, 1.0, size=(size, n)) * self.vmax
        if self.pbest is not None and self.carry > 0:
            # the previous swarm's best particles carry over (re-scored for the new target)
            keep = self.pbest[np.argsort(self.cost(self.pbest, target_n, q_a)[0])[: self.carry]]
            s[: len(keep)] = keep
            v[: len(keep)] *= 0.1
        if self.seed_actual:
            s[-1], v[-1] = q_a, 0.0
        s = np.clip(s, self.lower, self.upper)
        pbest = s.copy()
        pcost, pdist = self.cost(s, target_n, q_a)
        g = int(np.argmin(pcost))
        iterations = 0
        # velocity mode: stop once the tip is within a tenth of the step (β·b of one step is
        # far below 0.01, so the position-mode criterion would accept θ_a itself)
        step = None if self.step_tol is None else self.step_tol / self.workspace.scale

        def done() -> bool:
            return bool(pcost[g] < self.target_cost if step is None else pdist[g] <= step)

        limit = self.max_iterations
        while not done() and (self.clock() < deadline if limit is None else iterations < limit):
            r1 = rng.random((size, n))
            r2 = rng.random((size, n))
            v = self.w * v + self.c1 * r1 * (pbest - s) + self.c2 * r2 * (pbest[g] - s)
            v = np.clip(v, -self.vmax, self.vmax)
            s = s + v
            wall = (s < self.lower) | (s > self.upper)
            s = np.clip(s, self.lower, self.upper)
            v = np.where(wall, 0.0, v)
            cur, dist = self.cost(s, target_n, q_a)
            better = cur < pcost
            pbest = np.where(better[:, None], s, pbest)
            pcost = np.where(better, cur, pcost)
            pdist = np.where(better, dist, pdist)
            g = int(np.argmin(pcost))
            iterations += 1
        self.pbest = pbest
        return pbest[g].copy(), iterations, float(pcost[g]), done()
