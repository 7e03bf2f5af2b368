"""The thesis' 512-target accuracy test (§3.2.1.1, Fig. 3.8) for arms × solvers: the docs table.

For each arm and each solver that applies to it, ``accuracy_test`` (what ``kvp arms bench``
runs): 8 × 8 × 8 targets spanning the box around the workspace, position mode, one solver
instance for all targets in serpentine order, θ_a = the previous answer. Per run it writes the
JSON summary, the per-target CSV and the Fig. 3.8-style scatter PNG to ``--out`` and prints a
markdown table (reachable, error p50/p95/max in mm and % of the workspace, time p50/p99).

    nice -n 10 .venv/bin/python bench/universal_accuracy.py [--clock wall|cpu] [--targets 512]
        [--arms knuckle_boom_crane adept_cobra600 ...] [--solvers ga pso ...] [--out out/universal]

The machine's load average is recorded with every run: wall-clock times on a shared machine
measure the other jobs too (``--clock cpu`` counts this process's CPU time instead).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "apps"))

from pyopenshowvar_apps.universal.armsbench import plot_report, write_dump

from pyopenshowvar.arms import load_arm
from pyopenshowvar.universal import solver_names
from pyopenshowvar.universal.accuracy import accuracy_test

ARMS = ("knuckle_boom_crane", "adept_cobra600", "kuka_youbot_arm", "kr6_r900_sixx",
        "lbr_iiwa14_r820")  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--arms", nargs="+", default=list(ARMS))
    p.add_argument("--solvers", nargs="+", default=None)
    p.add_argument("--targets", type=int, default=512)
    p.add_argument("--clock", choices=("wall", "cpu"), default="wall")
    p.add_argument("--budget-ms", type=float, default=20.0)
    p.add_argument("--out", type=Path, default=Path("out/universal"))
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    per_axis = round(args.targets ** (1 / 3))
    clock = time.process_time if args.clock == "cpu" else time.perf_counter
    rows = []
    for name in args.arms:
        arm = load_arm(name)
        for solver in solver_names(arm):
            if args.solvers and solver not in args.solvers:
                continue
            started = time.time()
            report = accuracy_test(arm, solver, per_axis=per_axis, budget=args.budget_ms / 1e3,
                                   clock=clock)  # fmt: skip
            s = report.summary()
            stem = args.out / f"{name}_{solver}_{args.clock}"
            stem.with_suffix(".json").write_text(json.dumps(s, indent=2))
            write_dump(report, stem.with_suffix(".csv"))
            plot_report(report, stem.with_suffix(".png"))
            rows.append(s)
            print(f"{name} {solver}: {time.time() - started:.0f} s", json.dumps(s), flush=True)
    print()
    print("| arm | solver | reachable / 512 | error p50 | p95 | max (mm; % of the workspace) "
          "| time p50 / p99 (ms) | load |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for s in rows:
        e, pc, t = s["error_mm"], s["error_pct"], s["time_ms"]
        print(f"| {s['arm']} | {s['solver']} | {s['reachable']} | {e['p50']:.3g} ({pc['p50']:.3g} %) "
              f"| {e['p95']:.3g} ({pc['p95']:.3g} %) | {e['max']:.3g} ({pc['max']:.3g} %) "
              f"| {t['p50']:.1f} / {t['p99']:.1f} | {s['load_average'][0]:.1f} |")  # fmt: skip


if __name__ == "__main__":
    main()
