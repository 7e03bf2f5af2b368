"""Which GA / PSO implementation: ours (vectorised numpy) against DEAP, PyGAD and pyswarms.

The thesis' GA (§3.2.1) and PSO (§3.2.2) must run within 20 ms per target. The same
algorithm is set up in each library, as closely as it allows, on the same cost (our batched
tip FK, so every library evaluates a whole population in one call):

* **GA** — 50 individuals per DOF, stochastic universal sampling, single-point or uniform
  crossover (50 % each), ±5 % mutation with 20 % chance per gene, 20 % elitism. DEAP:
  ``tools.selStochasticUniversalSampling``, ``cxOnePoint``/``cxUniform``, the mutation and the
  elitism written around them (DEAP has no bounded uniform-step mutation), the population
  evaluated through a batched ``map``. PyGAD: ``parent_selection_type="sus"``,
  ``crossover_type="single_point"`` (it has no per-pair switch), ``mutation_type="random"``,
  ``keep_elitism``, ``fitness_batch_size`` = the population, stopped by ``on_generation``.
* **PSO** — 10 particles per DOF, our w, c1, c2 (pso.py), position bounds. pyswarms
  ``GlobalBestPSO`` (no time budget: a fixed iteration count, timed).

Per library: generations (iterations) per 20 ms of CPU time and the median error (% of the
workspace) reached in 20 ms on random reachable targets of the thesis' crane and youBot.

    nice -n 10 .venv/bin/python bench/universal_solvers.py [--targets 20]
"""

from __future__ import annotations

import argparse
import random
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from pyopenshowvar.arms import Arm, load_arm
from pyopenshowvar.universal import make_solver
from pyopenshowvar.universal.pointfk import PointFK
from pyopenshowvar.universal.pso import C1, C2, W
from pyopenshowvar.universal.workspace import workspace_of

BUDGET = 0.020
CLOCK = time.process_time


def _cost_fn(arm: Arm, x: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    fk, box = PointFK(arm), workspace_of(arm)
    tn = box.normalise(x)
    lo, hi, span = arm.lower, arm.upper, arm.upper - arm.lower

    def cost(pop: np.ndarray) -> np.ndarray:
        d = np.linalg.norm(box.normalise(fk(pop)) - tn, axis=-1)
        v = np.sum((np.maximum(lo - pop, 0) + np.maximum(pop - hi, 0)) / span, axis=-1)
        return d + np.where(v > 0, 10 * (1 + v), 0.0)

    return cost


def ours(kind: str, arm: Arm, x: np.ndarray, q0: np.ndarray) -> tuple[np.ndarray, int]:
    s = make_solver(kind, arm, clock=CLOCK, budget=BUDGET, seed=0)
    q = s.position(x, q0)
    return q, s.last.iterations


def deap_ga(arm: Arm, x: np.ndarray, q0: np.ndarray) -> tuple[np.ndarray, int]:
    from deap import base, creator, tools

    if not hasattr(creator, "FitMax"):
        creator.create("FitMax", base.Fitness, weights=(1.0,))
        creator.create("Ind", list, fitness=creator.FitMax)
    cost = _cost_fn(arm, x)
    n, size = arm.dof, 50 * arm.dof
    span = arm.upper - arm.lower
    tb = base.Toolbox()
    tb.register("map", lambda f, inds: [(1.0 / (c + 1e-9),) for c in cost(np.array(inds))])
    pop = [creator.Ind(v) for v in np.random.uniform(arm.lower, arm.upper, (size, n)).tolist()]
    start, gens = CLOCK(), 0
    for ind, fit in zip(pop, tb.map(None, pop), strict=True):
        ind.fitness.values = fit
    while CLOCK() - start < BUDGET:
        elite = tools.selBest(pop, size // 5)
        kids = [
            creator.Ind(k) for k in tools.selStochasticUniversalSampling(pop, size - len(elite))
        ]
        for a, b in zip(kids[::2], kids[1::2], strict=False):
            if random.random() < 0.5:
                tools.cxOnePoint(a, b)
            else:
                tools.cxUniform(a, b, 0.5)
        for k in kids:
            for i in range(n):
                if random.random() < 0.2:
                    k[i] += random.uniform(-0.05, 0.05) * span[i]
            del k.fitness.values
        for ind, fit in zip(kids, tb.map(None, kids), strict=True):
            ind.fitness.values = fit
        pop = [creator.Ind(e) for e in elite] + kids
        for e, src in zip(pop, elite, strict=False):
            e.fitness.values = src.fitness.values
        gens += 1
    return np.array(tools.selBest(pop, 1)[0]), gens


def pygad_ga(arm: Arm, x: np.ndarray, q0: np.ndarray) -> tuple[np.ndarray, int]:
    import pygad

    cost = _cost_fn(arm, x)
    n, size = arm.dof, 50 * arm.dof
    span = arm.upper - arm.lower
    start = CLOCK()

    def stop(ga: Any) -> str | None:
        return "stop" if CLOCK() - start >= BUDGET else None

    ga = pygad.GA(
        num_generations=100_000, num_parents_mating=size - size // 5, sol_per_pop=size,
        num_genes=n, fitness_func=lambda ga, sols, idx: list(-cost(np.array(sols))),
        fitness_batch_size=size, gene_space=[{"low": lo, "high": hi} for lo, hi in
                                             zip(arm.lower, arm.upper, strict=True)],
        parent_selection_type="sus", crossover_type="single_point", crossover_probability=0.5,
        mutation_type="random", mutation_probability=0.2, mutation_by_replacement=False,
        random_mutation_min_val=-0.05 * float(np.max(span)),
        random_mutation_max_val=0.05 * float(np.max(span)), keep_elitism=size // 5,
        on_generation=stop, suppress_warnings=True, random_seed=0,
    )  # fmt: skip
    start = CLOCK()
    ga.run()
    sol, _, _ = ga.best_solution()
    return np.asarray(sol), ga.generations_completed


def pyswarms_pso(arm: Arm, x: np.ndarray, q0: np.ndarray) -> tuple[np.ndarray, int]:
    from pyswarms.single import GlobalBestPSO

    cost = _cost_fn(arm, x)
    opt = GlobalBestPSO(n_particles=10 * arm.dof, dimensions=arm.dof,
                        options={"c1": C1, "c2": C2, "w": W},
                        bounds=(arm.lower.copy(), arm.upper.copy()))  # fmt: skip
    # no time budget in pyswarms: time one short run, then run as many iterations as fit
    t0 = CLOCK()
    opt.optimize(cost, iters=5, verbose=False)
    per = (CLOCK() - t0) / 5
    iters = max(1, int(BUDGET / per) - 5)
    _, pos = opt.optimize(cost, iters=iters, verbose=False)
    return np.asarray(pos), iters + 5


CONTENDERS: dict[str, Callable[[Arm, np.ndarray, np.ndarray], tuple[np.ndarray, int]]] = {
    "GA ours (numpy)": lambda a, x, q: ours("ga", a, x, q),
    "GA DEAP": deap_ga,
    "GA PyGAD": pygad_ga,
    "PSO ours (numpy)": lambda a, x, q: ours("pso", a, x, q),
    "PSO pyswarms": pyswarms_pso,
}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--targets", type=int, default=20)
    args = p.parse_args()
    import logging

    logging.getLogger("pyswarms").setLevel(logging.ERROR)
    print("| implementation | arm | generations or iterations per 20 ms CPU | median error (%) |")
    print("|---|---|---|---|")
    for name in ("knuckle_boom_crane", "kuka_youbot_arm"):
        arm = load_arm(name)
        fk, box = PointFK(arm), workspace_of(arm)
        rng = np.random.default_rng(20260101)  # not the solvers' seed: their first draws
        goals = rng.uniform(arm.lower, arm.upper, (args.targets, arm.dof))
        for label, fn in CONTENDERS.items():
            try:
                errs, gens = [], []
                for g in goals:
                    x = fk(g)
                    q, k = fn(arm, x, arm.home_q)
                    errs.append(100 * np.linalg.norm(fk(q) - x) / box.scale)
                    gens.append(k)
                print(f"| {label} | {name} | {np.median(gens):.0f} | {np.median(errs):.3f} |",
                      flush=True)  # fmt: skip
            except Exception as exc:  # a peer that does not run here is reported, not fatal
                print(f"| {label} | {name} | failed: {type(exc).__name__}: {exc} | |", flush=True)


if __name__ == "__main__":
    main()
