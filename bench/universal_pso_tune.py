"""PSO's inertia weight and learning factors by a higher-level search (thesis §3.2.2).

The thesis chose c1 and c2 "through a higher level optimisation process" and does not print
them. This is ours: a grid over w and c1 = c2 (the swarm's own pull and the pull of the best
balanced, as usual), scored on the thesis' three arms by the median and 90th-percentile error
(per cent of the workspace) after a fixed number of iterations (not a time budget, so the
load of a shared machine cannot change the ranking), on sequences of random reachable
targets solved with one swarm and θ_a = the previous answer, as in the accuracy test.

    nice -n 10 .venv/bin/python bench/universal_pso_tune.py [--iterations 50] [--targets 60]
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np

from pyopenshowvar.arms import load_arm
from pyopenshowvar.universal import make_solver

ARMS = ("knuckle_boom_crane", "adept_cobra600", "kuka_youbot_arm")
WS = (0.4, 0.5, 0.6, 0.7298, 0.9)
CS = (0.5, 1.0, 1.49618, 2.0)


def score(w: float, c: float, iterations: int, targets: int, seeds: int) -> tuple[float, float]:
    errs = []
    for name in ARMS:
        arm = load_arm(name)
        for seed in range(seeds):
            s = make_solver("pso", arm, w=w, c1=c, c2=c, seed=seed, budget=60.0,
                            max_iterations=iterations)  # fmt: skip
            rng = np.random.default_rng(1000 + seed)
            q = arm.home_q.copy()
            for goal in rng.uniform(arm.lower, arm.upper, (targets, arm.dof)):
                x = s.fk(goal)
                q = s.position(x, q)
                errs.append(100 * np.linalg.norm(arm.fk(q)[:3, 3] - x) / s.workspace.scale)
    e = np.array(errs)
    return float(np.median(e)), float(np.percentile(e, 90))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--iterations", type=int, default=50)
    p.add_argument("--targets", type=int, default=60)
    p.add_argument("--seeds", type=int, default=2)
    args = p.parse_args()
    rows = []
    for w, c in itertools.product(WS, CS):
        med, p90 = score(w, c, args.iterations, args.targets, args.seeds)
        rows.append((med, p90, w, c))
        print(f"w {w:<7} c1 = c2 {c:<8} error median {med:.4f} %  p90 {p90:.4f} %", flush=True)
    print("\n| w | c1 = c2 | median error (%) | 90th percentile (%) |\n|---|---|---|---|")
    for med, p90, w, c in sorted(rows):
        print(f"| {w} | {c} | {med:.4f} | {p90:.4f} |")


if __name__ == "__main__":
    main()
