"""Kinematics benchmark: FK, IK and Jacobian poses/s, one pose per call and batched, vs
roboticstoolbox-python (Peter Corke's Robotics Toolbox, PyPI) on the same KR 6 R900 sixx.

The peer gets the same standard D-H chain (``rtb.DHRobot`` of ``RevoluteDH`` links with the
model's a, α, d, offset and ``flip`` for the axes whose sign is −1; metres and radians, its
native units). The answers are checked on the benchmark's poses: FK positions agree within
1e-6 mm and rotations within 1e-9; the Jacobians agree (mm/rad); for IK both solutions must
reproduce the target pose (the peer's numeric ``ikine_LM`` may converge to another branch).

"One pose per call" is what a control loop pays per cycle; "batched" is one call over
``--batch`` poses (ours: one numpy call; the peer: ``fkine``/``jacob0``/``ikine_LM`` per pose,
which is how it is used for a trajectory — its ``fkine`` takes an (N, 6) array too, used here).

    .venv/bin/python bench/kinematics.py [--quick] [--batch 10000] [--seconds 1.0] [--repeat 3]
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import Row, base_parser, median, print_rows, write_json

from pyopenshowvar.kinematics import (
    KR6R900SIXX,
    fk_matrix,
    forward,
    inverse,
    jacobian,
    status_turn,
)

M = KR6R900SIXX
#: The peer's LM stopping tolerance: its default (1e-6) leaves ~0.01–1 mm of error; 1e-10
#: gives < 1e-6 mm (no slower: it converges quadratically near the end).
IK_TOL = 1e-10


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


def peer_robot() -> Any:
    """The KR 6 R900 sixx in roboticstoolbox (None if it is not installed)."""
    try:
        import roboticstoolbox as rtb
    except ImportError:
        return None
    links = [
        rtb.RevoluteDH(
            a=row[0] / 1000.0,
            alpha=np.radians(row[1]),
            d=row[2] / 1000.0,
            offset=np.radians(row[3]),
            flip=bool(row[4] < 0),
            qlim=np.radians([lo, hi]),
        )
        for row, lo, hi in zip(M.dh, M.lower, M.upper, strict=True)
    ]
    return rtb.DHRobot(links, name="KR6R900sixx")


def run(quick: bool, repeat: int, batch: int, seconds: float) -> tuple[list[Row], dict[str, Any]]:
    rng = np.random.default_rng(0)
    qs = rng.uniform(M.lower + 5, M.upper - 5, (batch, 6))
    qs[:, 4] = np.where(np.abs(qs[:, 4]) < 5, 30.0, qs[:, 4])  # keep off the wrist singularity
    poses = forward(M, qs)
    mats = fk_matrix(M, qs)
    s, t = status_turn(M, qs)
    q1, p1 = qs[0], poses[0]
    s1, t1 = int(s[0]), int(t[0])  # type: ignore[index]
    extra: dict[str, Any] = {"batch": batch}

    robot = peer_robot()
    peer_single: dict[str, Callable[[], object]] = {}
    peer_batched: dict[str, tuple[Callable[[], object], int]] = {}
    if robot is not None:
        qr = np.radians(qs)
        q1r = qr[0]
        agreement, targets = _agreement(robot, qs, poses, s, t, mats)
        extra["agreement"] = agreement
        n_ik = min(batch, 200)
        T1 = targets[0]
        q0 = np.radians(M.home)
        peer_single = {
            "fk": lambda: robot.fkine(q1r),
            "ik": lambda: robot.ikine_LM(T1, q0=q0, tol=IK_TOL),
            "jac": lambda: robot.jacob0(q1r),
        }
        n_pb = min(batch, 1000)  # per-pose peer calls: time a slice, report poses/s
        peer_batched = {
            "fk": (lambda: robot.fkine(qr), batch),
            "ik": (
                lambda: [robot.ikine_LM(T, q0=q0, tol=IK_TOL) for T in targets[: min(n_ik, 100)]],
                min(n_ik, 100),
            ),
            "jac": (lambda: [robot.jacob0(q) for q in qr[:n_pb]], n_pb),
        }
        extra["peer"] = f"roboticstoolbox-python {rtb_version()}"

    ours_single = {
        "fk": lambda: fk_matrix(M, q1),
        "ik": lambda: inverse(M, p1, s=s1, t=t1),
        "jac": lambda: jacobian(M, q1),
    }
    ours_batched = {
        "fk": lambda: fk_matrix(M, qs),
        "ik": lambda: inverse(M, poses, s=s, t=t),
        "jac": lambda: jacobian(M, qs),
    }
    rows = _rows(
        ours_single, ours_batched, peer_single, peer_batched, repeat, batch, seconds, robot
    )
    return rows, extra


def _rows(
    ours_single: dict[str, Callable[[], object]],
    ours_batched: dict[str, Callable[[], object]],
    peer_single: dict[str, Callable[[], object]],
    peer_batched: dict[str, tuple[Callable[[], object], int]],
    repeat: int,
    batch: int,
    seconds: float,
    robot: Any,
) -> list[Row]:
    """Poses per second of each operation, one pose per call and batched, ours and the peer's."""
    labels = {"fk": "FK (4×4 pose)", "ik": "IK (closed form, given S/T)", "jac": "Jacobian (6×6)"}
    rows: list[Row] = []
    for key in ("fk", "ik", "jac"):
        for mode in ("single", "batched"):
            ours_r, peer_r = [], []
            for _ in range(repeat):
                if mode == "single":
                    ours_r.append(_rate(ours_single[key], 1, seconds))
                    if key in peer_single:
                        peer_r.append(_rate(peer_single[key], 1, seconds))
                else:
                    ours_r.append(_rate(ours_batched[key], batch, seconds))
                    if key in peer_batched:
                        fn, n = peer_batched[key]
                        peer_r.append(_rate(fn, n, seconds))
            what = "one pose per call" if mode == "single" else f"batched ({batch})"
            rows.append(
                Row(
                    f"{labels[key]}, {what}",
                    median(ours_r),
                    "poses/s",
                    peer=median(peer_r) if peer_r else None,
                    peer_name="roboticstoolbox",
                    runs=ours_r,
                    note=""
                    if robot is not None
                    else "roboticstoolbox-python not installed: peer skipped",
                )
            )
    return rows


def _agreement(
    robot: Any, qs: np.ndarray, poses: np.ndarray, s: Any, t: Any, mats: np.ndarray
) -> tuple[dict[str, Any], list[Any]]:
    """How far ours and the peer agree on the benchmark's poses (FK, Jacobian, IK: each
    solution's FK must reproduce the target, branches may differ), and the peer's IK targets."""
    from spatialmath import SE3

    batch = len(qs)
    qr = np.radians(qs)
    # --- agreement on the benchmark's poses
    T_peer = robot.fkine(qr)  # SE3 with `batch` values
    A = np.asarray(T_peer.A)
    pos_err = float(np.max(np.abs(A[:, :3, 3] * 1000.0 - mats[:, :3, 3])))
    rot_err = float(np.max(np.abs(A[:, :3, :3] - mats[:, :3, :3])))
    n_j = min(batch, 500)
    J_ours = jacobian(M, qs[:n_j])
    J_peer = np.stack([robot.jacob0(q) for q in qr[:n_j]])
    J_peer[:, :3, :] *= 1000.0  # m/rad -> mm/rad
    jac_err = float(np.max(np.abs(J_ours - J_peer)))
    # IK: each solution's FK must reproduce the target (branches may differ)
    n_ik = min(batch, 200)
    ours_ik = inverse(M, poses[:n_ik], s=s[:n_ik], t=t[:n_ik])
    ours_ik_err = float(np.max(np.abs(fk_matrix(M, ours_ik)[:, :3, 3] - mats[:n_ik, :3, 3])))
    targets = [SE3(m[:3, 3] / 1000.0) * SE3.Rt(m[:3, :3]) for m in mats[:n_ik]]
    sols = [robot.ikine_LM(T, q0=np.radians(M.home), tol=IK_TOL) for T in targets]
    ok = [sol.success for sol in sols]
    peer_pos = np.stack([robot.fkine(sol.q).A for sol in sols])
    peer_ik_err = float(np.max(np.abs(peer_pos[ok][:, :3, 3] * 1000.0 - mats[:n_ik][ok][:, :3, 3])))
    peer_ik_rot = float(np.max(np.abs(peer_pos[ok][:, :3, :3] - mats[:n_ik][ok][:, :3, :3])))
    ours_ik_rot = float(np.max(np.abs(fk_matrix(M, ours_ik)[:, :3, :3] - mats[:n_ik, :3, :3])))
    agreement = {
        "fk_position_max_diff_mm": pos_err,
        "fk_rotation_max_diff": rot_err,
        "jacobian_max_diff_mm_per_rad": jac_err,
        "ik_ours_max_position_error_mm": ours_ik_err,
        "ik_ours_max_rotation_error": ours_ik_rot,
        "ik_peer_max_position_error_mm": peer_ik_err,
        "ik_peer_max_rotation_error": peer_ik_rot,
        "ik_peer_success": f"{sum(ok)}/{n_ik}",
        "ik_peer_same_branch": int(
            sum(
                np.allclose(np.degrees(sol.q), q, atol=1e-3)
                for sol, q in zip(sols, qs[:n_ik], strict=True)
            )
        ),
    }
    return agreement, targets


def rtb_version() -> str:
    from importlib.metadata import version

    return version("roboticstoolbox-python")


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--batch", type=int, default=None)
    ap.add_argument("--seconds", type=float, default=None)
    args = ap.parse_args()
    repeat = args.repeat or (1 if args.quick else 3)
    batch = args.batch or (50 if args.quick else 10_000)
    seconds = args.seconds or (0.02 if args.quick else 1.0)
    rows, extra = run(args.quick, repeat, batch, seconds)
    print_rows(f"Kinematics (median of {repeat} runs)", rows)
    for key, value in extra.get("agreement", {}).items():
        print(f"  agreement: {key} = {value}")
    write_json(args.json, "kinematics", rows, extra)


if __name__ == "__main__":
    main()
