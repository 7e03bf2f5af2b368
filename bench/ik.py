"""IK benchmark with the protocol of the TRAC-IK benchmark, on every catalogue arm, side by
side with ikpy and pinocchio's CLIK (the ``bench`` extra; a missing peer is skipped).

Protocol (Beeson & Ames, TRAC-IK, Humanoids 2015): per arm, N random joint configurations
drawn uniformly inside the joint limits; their flange poses are the targets (so every target
is reachable); full-pose IK to 1e-5 (each twist component: metres, radians), seeded from the
mid-range pose, 5 ms timeout per query. A query counts as solved when the answer is inside
the limits, reaches the target within the tolerance (checked with our FK for every solver)
and came within the timeout. Published anchor: TRAC-IK 99.6–100 % in 0.2–0.5 ms (C++), KDL
21–97 %.

Solvers:

* ours, closed form (KUKA six-axis arms): one batched call;
* ours, numeric, batched: one call for all N targets (budget N × 5 ms);
* ours, numeric, one query per call: what a control loop pays;
* pinocchio CLIK: the damped-pseudo-inverse loop of pinocchio's documentation (step 1,
  damping 1e-12), joint limits clamped, restarted from a random configuration after 30
  steps without convergence (as TRAC-IK's "KDL-RR"), until solved or 5 ms;
* ikpy: ``Chain.inverse_kinematics_frame`` (its scipy optimiser), seeded the same way; it
  cannot be interrupted, so a query over 5 ms counts as failed. ikpy takes tenths of a second
  per query, so it runs ``--n-ikpy`` queries per arm (default 100), not N.

``--clock cpu`` measures (and times out) with this process's CPU time instead of wall time,
for a machine shared with other jobs.

    .venv/bin/python bench/ik.py [--quick] [--n 10000] [--n-ikpy 100] [--clock wall|cpu]
        [--arms kr10_r1100_2 lbr_iiwa14_r820 ...] [--json PATH]
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import Row, base_parser, machine_info, print_rows, write_json

from pyopenshowvar.arms import Arm, catalogue, load_arm, solve
from pyopenshowvar.arms.spatial import rotation_log
from pyopenshowvar.arms.urdf import to_urdf

TOL = 1e-5
TIMEOUT = 0.005
Result = dict[str, float]


def check(
    arm: Arm, q: npt.NDArray[np.float64], targets: npt.NDArray[np.float64]
) -> npt.NDArray[np.bool_]:
    """Solved = inside the limits and within TOL of the target (our FK, for every solver)."""
    ok = np.all(np.isfinite(q), axis=-1)
    q = np.nan_to_num(q)
    t = arm.fk(q)
    pos = np.max(np.abs(t[..., :3, 3] - targets[..., :3, 3]), axis=-1) <= TOL * 1000.0
    rot = np.max(
        np.abs(rotation_log(targets[..., :3, :3] @ np.swapaxes(t[..., :3, :3], -1, -2))), axis=-1
    )
    return np.asarray(ok & pos & (rot <= TOL) & arm.within_limits(q, tol=1e-6))


def units(arm: Arm) -> npt.NDArray[np.float64]:
    """Our units (deg, mm) per peer unit (rad, m)."""
    return np.where(arm.revolute, math.degrees(1.0), 1000.0)


def ours_closed(arm: Arm, targets: Any, clock: Callable[[], float]) -> Result:
    t0 = clock()
    res = solve(arm, targets, arm.mid, method="closed")
    dt = clock() - t0
    return {
        "rate": float(np.mean(check(arm, res.q, targets) & res.ok)),
        "ms": dt / len(targets) * 1e3,
    }


def ours_batched(arm: Arm, targets: Any, clock: Callable[[], float], seed: int) -> Result:
    t0 = clock()
    res = solve(arm, targets, arm.mid, method="numeric", tol=TOL, timeout=TIMEOUT, clock=clock,
                rng=np.random.default_rng(seed))  # fmt: skip
    dt = clock() - t0
    return {
        "rate": float(np.mean(check(arm, res.q, targets) & res.ok)),
        "ms": dt / len(targets) * 1e3,
    }


def ours_single(arm: Arm, targets: Any, clock: Callable[[], float], seed: int) -> Result:
    rng = np.random.default_rng(seed)
    solved, total = 0, 0.0
    for target in targets:
        t0 = clock()
        res = solve(
            arm, target, arm.mid, method="numeric", tol=TOL, timeout=TIMEOUT, clock=clock, rng=rng
        )
        dt = clock() - t0
        total += dt
        solved += bool(res.ok) and bool(check(arm, res.q, target)) and dt <= TIMEOUT * 1.05
    return {"rate": solved / len(targets), "ms": total / len(targets) * 1e3}


def pinocchio_clik(arm: Arm, targets: Any, clock: Callable[[], float], seed: int) -> Result | None:
    try:
        import pinocchio as pin
    except ImportError:
        return None
    model = pin.buildModelFromXML(to_urdf(arm))
    data = model.createData()
    frame = model.getFrameId("flange")
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    scale = units(arm)
    mid = arm.mid / scale
    rng = np.random.default_rng(seed)
    solved, total = 0, 0.0
    for target in targets:
        goal = pin.SE3(target[:3, :3], target[:3, 3] / 1000.0)
        q = mid.copy()
        t0 = clock()
        steps = 0
        done = False
        while clock() - t0 < TIMEOUT:
            pin.framesForwardKinematics(model, data, q)
            err = pin.log6(data.oMf[frame].actInv(goal)).vector  # in the flange frame
            if np.max(np.abs(err)) < TOL * 0.5:  # local frame: leave room for the world check
                done = True
                break
            jac = pin.computeFrameJacobian(model, data, q, frame, pin.LOCAL)
            v = jac.T @ np.linalg.solve(jac @ jac.T + 1e-12 * np.eye(6), err)
            q = np.clip(pin.integrate(model, q, v), lo, hi)
            steps += 1
            if steps >= 30:
                q, steps = rng.uniform(lo, hi), 0
        dt = clock() - t0
        total += dt
        solved += done and bool(check(arm, q * scale, target))
    return {"rate": solved / len(targets), "ms": total / len(targets) * 1e3}


def ikpy_solve(arm: Arm, targets: Any, clock: Callable[[], float]) -> Result | None:
    try:
        import ikpy.chain
    except ImportError:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "arm.urdf"
        path.write_text(to_urdf(arm))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            chain = ikpy.chain.Chain.from_urdf_file(
                str(path),
                base_elements=["base_link"],
                active_links_mask=[False, *[True] * arm.dof, False],
            )
    scale = units(arm)
    init = np.concatenate([[0.0], arm.mid / scale, [0.0]])
    solved, total, any_time = 0, 0.0, 0
    for target in targets:
        frame = target.copy()
        frame[:3, 3] /= 1000.0
        t0 = clock()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = chain.inverse_kinematics_frame(
                frame, initial_position=init, orientation_mode="all"
            )
        dt = clock() - t0
        total += dt
        good = bool(check(arm, np.asarray(sol[1:-1]) * scale, target))
        any_time += good
        solved += good and dt <= TIMEOUT
    n = len(targets)
    return {"rate": solved / n, "ms": total / n * 1e3, "rate_any_time": any_time / n}


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--n", type=int, default=10_000, help="random configurations per arm")
    ap.add_argument("--n-ikpy", type=int, default=100, help="queries per arm for ikpy (slow)")
    ap.add_argument(
        "--n-single", type=int, default=None, help="queries per arm, one per call (default: --n)"
    )
    ap.add_argument("--clock", choices=("wall", "cpu"), default="wall")
    ap.add_argument("--arms", nargs="*", default=None, help="catalogue names (default: all)")
    ap.add_argument("--seed", type=int, default=2015)
    args = ap.parse_args()
    n = 20 if args.quick else args.n
    n_single = min(n, 5 if args.quick else (args.n_single or n))
    n_ikpy = 2 if args.quick else args.n_ikpy
    clock: Callable[[], float] = time.process_time if args.clock == "cpu" else time.perf_counter
    names = args.arms or catalogue()

    rows: list[Row] = []
    table: dict[str, dict[str, Result | None]] = {}
    for name in names:
        arm = load_arm(name)
        rng = np.random.default_rng(args.seed)
        q = rng.uniform(arm.lower, arm.upper, size=(n, arm.dof))
        targets = arm.fk(q)
        res: dict[str, Result | None] = {}
        if arm.kuka is not None:
            res["closed"] = ours_closed(arm, targets, clock)
        res["batched"] = ours_batched(arm, targets, clock, args.seed)
        res["single"] = ours_single(arm, targets[:n_single], clock, args.seed)
        res["pinocchio"] = pinocchio_clik(arm, targets[:n_single], clock, args.seed)
        res["ikpy"] = ikpy_solve(arm, targets[:n_ikpy], clock)
        table[name] = res
        pin_r, ikpy_r = res["pinocchio"], res["ikpy"]
        if "closed" in res and res["closed"] is not None:
            c = res["closed"]
            rows.append(
                Row(
                    f"{name}: solved, closed form",
                    c["rate"] * 100,
                    "%",
                    target=("ours", ">=", 100.0),
                )
            )
            rows.append(Row(f"{name}: time per query, closed form (batched)", c["ms"], "ms"))
        b, s = res["batched"], res["single"]
        assert b is not None and s is not None
        rows.append(Row(f"{name}: solved, numeric batched", b["rate"] * 100, "%",
                        peer=None if pin_r is None else pin_r["rate"] * 100, peer_name="pinocchio CLIK",
                        target=("ours", ">=", 99.9)))  # fmt: skip
        rows.append(Row(f"{name}: time per query, numeric batched", b["ms"], "ms",
                        peer=None if pin_r is None else pin_r["ms"], peer_name="pinocchio CLIK",
                        target=("ours", "<=", 1.0)))  # fmt: skip
        rows.append(Row(f"{name}: solved, numeric one query per call", s["rate"] * 100, "%",
                        peer=None if ikpy_r is None else ikpy_r["rate"] * 100, peer_name="ikpy (≤ 5 ms)"))  # fmt: skip
        rows.append(Row(f"{name}: time per query, numeric one query per call", s["ms"], "ms",
                        peer=None if ikpy_r is None else ikpy_r["ms"], peer_name="ikpy"))  # fmt: skip
        print_rows(f"IK, {arm.name} ({arm.dof} axes)", rows[-6 if "closed" in res else -4 :])

    print(
        "\n| arm | axes | closed form | ours numeric, batched | ours numeric, one per call | pinocchio CLIK | ikpy (≤ 5 ms / any time) |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, res in table.items():

        def cell(r: Result | None) -> str:
            return "–" if r is None else f"{r['rate'] * 100:.2f} %, {r['ms']:.3f} ms"

        ik = res["ikpy"]
        ik_cell = (
            "–"
            if ik is None
            else f"{ik['rate'] * 100:.0f} % / {ik['rate_any_time'] * 100:.0f} %, {ik['ms']:.0f} ms"
        )
        print(f"| {name} | {load_arm(name).dof} | {cell(res.get('closed'))} | {cell(res['batched'])} | "
              f"{cell(res['single'])} | {cell(res['pinocchio'])} | {ik_cell} |")  # fmt: skip
    info = machine_info()
    print(f"\nN = {n} per arm (one per call and pinocchio: {n_single}, ikpy: {n_ikpy}); clock: {args.clock}; "
          f"machine: {info['cpu']}, {info['cores']} cores, load {info['load']}")  # fmt: skip
    write_json(args.json, "ik", rows, {"machine": info, "n": n, "n_single": n_single, "n_ikpy": n_ikpy,
                                        "clock": args.clock})  # fmt: skip


if __name__ == "__main__":
    main()
