"""The genetic-algorithm solver of the thesis (§3.2.1, Fig. 3.6): IK learnt from the FK alone.

As the thesis sets it up:

* a chromosome is a set of joint angles (one gene per joint), drawn within the limits;
* cost = Euclidean distance between the target and the chromosome's tip (eq. 3.3), both
  normalised by the workspace (so one target cost fits a youBot and a crane); a chromosome
  outside its joint limits has its cost raised by a considerable amount
  (:data:`PENALTY` + :data:`PENALTY` × the violation in joint ranges);
* 50 individuals per DOF;
* parents by stochastic universal sampling (Baker 1987), fitness-proportionate on 1/cost;
* each pair of parents is crossed over by a single-point crossover with 50 % probability,
  else by a uniform crossover (the paper's "hybrid function that stochastically switches —
  with a 50 % crossover probability — between a single-point and a uniform crossover");
* mutation adds a random ±5 % of the joint's range to a gene with 20 % probability;
* 20 % elitism: the fittest fifth survives unaltered into the next generation *and into the
  next target* ("consecutive input vectors do not differ much"): a new call starts from the
  previous call's elite plus fresh random individuals, one of them θ_a itself (our addition:
  in velocity mode the answer is within one step of it);
* evolution stops when the best cost drops below the target cost (here 0.001, 0.1 % of the
  workspace; the paper's 0.01 is 20 mm on a KR 6 and 21 cm on the crane; in velocity mode a
  tenth of the step, see :class:`~.solver.Solver`) or after the time budget (20 ms wall-clock); position mode returns θ_f (eq. 3.6), velocity mode (θ_f − θ_a)/Δt
  (eq. 3.7, in :class:`~.solver.Solver`).

Everything is vectorised with numpy over the population: one generation is a handful of
array operations and one batched FK (:class:`~.pointfk.PointFK`). bench/universal_solvers.py
compares this with DEAP and PyGAD running the same algorithm.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from ..arms.model import Arm
from ..kinematics.frames import FloatArray
from .solver import Solver

__all__ = ["PENALTY", "GASolver", "sus"]

#: Cost added to a chromosome outside its limits (the workspace scale is 1).
PENALTY = 10.0


def sus(fitness: FloatArray, k: int, rng: np.random.Generator) -> npt.NDArray[np.intp]:
    """Stochastic universal sampling: ``k`` indices drawn proportionally to ``fitness`` with
    one spin of ``k`` equally spaced pointers (minimum spread, no bias)."""
    total = float(np.sum(fitness))
    cum = np.cumsum(fitness)
    step = total / k
    pointers = rng.uniform(0.0, step) + step * np.arange(k)
    return np.minimum(np.searchsorted(cum, pointers, side="right"), len(fitness) - 1)


class GASolver(Solver):
    """The thesis' continuous GA (see the module docstring); options are its parameters."""

    name = "ga"

    def __init__(
        self,
        arm: Arm,
        *,
        per_dof: int = 50,
        elite: float = 0.2,
        crossover: float = 0.5,
        mutation_rate: float = 0.2,
        mutation_size: float = 0.05,
        target_cost: float = 1e-3,
        seed_actual: bool = True,
        max_generations: int | None = None,
        **options: Any,
    ) -> None:
        super().__init__(arm, **options)
        self.size = max(4, per_dof * arm.dof)
        self.n_elite = max(1, round(elite * self.size))
        self.crossover = crossover
        self.mutation_rate = mutation_rate
        self.mutation_size = mutation_size
        self.target_cost = target_cost
        self.seed_actual = seed_actual
        #: A fixed number of generations instead of the budget (reproducible benchmarks).
        self.max_generations = max_generations
        #: The last population, fittest first (its elite seeds the next call).
        self.population: FloatArray | None = None

    def reset(self) -> None:
        self.population = None

    def cost(self, pop: FloatArray, target_n: FloatArray) -> FloatArray:
        """Eq. 3.3 on the normalised workspace, plus the joint-limit penalty."""
        d = np.linalg.norm(self.workspace.normalise(self.fk(pop)) - target_n, axis=-1)
        v = self.violation(pop)
        return np.asarray(d + np.where(v > 0.0, PENALTY * (1.0 + v), 0.0))

    def _solve(
        self, x: FloatArray, q_a: FloatArray, deadline: float
    ) -> tuple[FloatArray, int, float, bool]:
        rng, n = self.rng, self.arm.dof
        target_n = self.workspace.normalise(x)
        fresh = self.size if self.population is None else self.size - self.n_elite
        pop = rng.uniform(self.lower, self.upper, size=(fresh, n))
        if self.population is not None:
            pop = np.concatenate([self.population[: self.n_elite], pop])
        if self.seed_actual:
            pop[-1] = q_a
        goal = self.target_cost
        if self.step_tol is not None:
            goal = min(goal, self.step_tol / self.workspace.scale)
        cost = self.cost(pop, target_n)
        n_children = self.size - self.n_elite
        generations = 0
        while True:
            order = np.argsort(cost)
            pop, cost = pop[order], cost[order]
            if cost[0] <= goal:
                break
            if (self.clock() >= deadline if self.max_generations is None
                    else generations >= self.max_generations):  # fmt: skip
                break
            # an even number of parents, so every one is in a pair
            n_par = n_children + (n_children % 2)
            parents = pop[sus(1.0 / (cost + 1e-9), n_par, rng)]
            rng.shuffle(parents)
            children = self._offspring(parents[0::2], parents[1::2])[:n_children]
            children = self._mutate(children)
            pop = np.concatenate([pop[: self.n_elite], children])
            cost = np.concatenate([cost[: self.n_elite], self.cost(children, target_n)])
            generations += 1
        self.population = pop
        feasible = np.flatnonzero(self.violation(pop) == 0.0)
        best = int(feasible[0]) if len(feasible) else 0
        return pop[best].copy(), generations, float(cost[best]), bool(cost[0] <= goal)

    def _offspring(self, a: FloatArray, b: FloatArray) -> FloatArray:
        """Two children per pair: single-point crossover with probability ``crossover``,
        else uniform crossover."""
        rng = self.rng
        m, n = a.shape
        cut = rng.integers(1, max(n, 2), size=(m, 1))
        single = np.arange(n)[None, :] >= cut
        uniform = rng.random((m, n)) < 0.5
        use_single = rng.random((m, 1)) < self.crossover
        swap = np.where(use_single, single, uniform)
        return np.concatenate([np.where(swap, b, a), np.where(swap, a, b)])

    def _mutate(self, pop: FloatArray) -> FloatArray:
        """±``mutation_size`` of each joint's range, added with probability ``mutation_rate``."""
        rng = self.rng
        hit = rng.random(pop.shape) < self.mutation_rate
        delta = rng.uniform(-1.0, 1.0, size=pop.shape) * self.mutation_size * self.span
        return np.asarray(pop + np.where(hit, delta, 0.0))
