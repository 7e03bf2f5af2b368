"""Throughput of the kinematics: FK, IK and Jacobian poses per second, single and batched.

Plain script, no asserts: ``python bench/kinematics.py [--batch 10000] [--seconds 1.0]``.
"One pose per call" is what a control loop pays per cycle; "batched" is one numpy call over
``--batch`` poses, what the path planner and the emulator's LIN pre-computation use.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from pyopenshowvar.kinematics import (
    KR6R900SIXX,
    fk_matrix,
    forward,
    inverse,
    jacobian,
    status_turn,
)

M = KR6R900SIXX


def _rate(fn: Callable[[], object], poses_per_call: int, seconds: float) -> float:
    fn()  # warm-up (imports, caches)
    calls = 0
    start = time.perf_counter()
    while True:
        fn()
        calls += 1
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return calls * poses_per_call / elapsed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--batch", type=int, default=10_000)
    ap.add_argument("--seconds", type=float, default=1.0)
    args = ap.parse_args()

    rng = np.random.default_rng(0)
    qs = rng.uniform(M.lower + 5, M.upper - 5, (args.batch, 6))
    qs[:, 4] = np.where(np.abs(qs[:, 4]) < 5, 30.0, qs[:, 4])  # keep off the wrist singularity
    poses = forward(M, qs)
    s, t = status_turn(M, qs)
    q1, p1 = qs[0], poses[0]
    s1, t1 = int(s[0]), int(t[0])  # type: ignore[index]

    rows = [
        ("FK  forward (XYZABC)", lambda: forward(M, q1), lambda: forward(M, qs)),
        ("FK  fk_matrix (4x4)", lambda: fk_matrix(M, q1), lambda: fk_matrix(M, qs)),
        (
            "IK  inverse with S/T",
            lambda: inverse(M, p1, s=s1, t=t1),
            lambda: inverse(M, poses, s=s, t=t),
        ),
        (
            "IK  inverse nearest current",
            lambda: inverse(M, p1, current=q1),
            lambda: inverse(M, poses, current=qs),
        ),
        ("Jacobian", lambda: jacobian(M, q1), lambda: jacobian(M, qs)),
    ]
    print(f"{'':30s} {'one pose/call':>16s} {f'batched ({args.batch})':>20s}")
    for name, single, batched in rows:
        r1 = _rate(single, 1, args.seconds)
        rb = _rate(batched, args.batch, args.seconds)
        print(f"{name:30s} {r1:13,.0f}/s {rb:17,.0f}/s")


if __name__ == "__main__":
    main()
