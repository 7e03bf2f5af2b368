"""IK round trips on every catalogue arm (hypothesis), limits, redundancy, position-only targets.

Timeouts here are generous (the solver returns as soon as a target is solved), so the tests
hold on a loaded machine; speed is measured by bench/ik.py, not here.
"""

from __future__ import annotations

import math
import time

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyopenshowvar.arms import catalogue, load_arm, solve
from pyopenshowvar.arms.spatial import rotation_log
from pyopenshowvar.kinematics import UnreachableError, inverse_all

TOL = 1e-5  # metres and radians per twist component, as in the TRAC-IK benchmark

fractions = st.lists(st.floats(0.0, 1.0), min_size=7, max_size=7)


def config(arm_name: str, f: list[float]) -> npt.NDArray[np.float64]:
    arm = load_arm(arm_name)
    frac = np.array(f[: arm.dof])
    return np.asarray(arm.lower + frac * (arm.upper - arm.lower))


def assert_reaches(
    arm_name: str, q: npt.NDArray[np.float64], target: npt.NDArray[np.float64]
) -> None:
    arm = load_arm(arm_name)
    assert np.all(arm.within_limits(q))
    t = arm.fk(q)
    assert np.max(np.abs(t[..., :3, 3] - target[..., :3, 3])) <= TOL * 1000
    rot = rotation_log(target[..., :3, :3] @ np.swapaxes(t[..., :3, :3], -1, -2))
    assert np.max(np.abs(rot)) <= TOL


@pytest.mark.parametrize("name", catalogue())
@settings(max_examples=12, deadline=None)
@given(f=fractions)
def test_full_pose_round_trip_within_limits(name: str, f: list[float]) -> None:
    arm = load_arm(name)
    q_true = config(name, f)
    target = arm.fk(q_true)
    q = arm.ik(target, seed=arm.mid, timeout=2.0, rng=np.random.default_rng(0))
    assert_reaches(name, q, target)


@pytest.mark.parametrize("name", [n for n in catalogue() if load_arm(n).kuka is not None])
def test_numeric_solver_also_solves_the_kuka_arms(name: str) -> None:
    arm = load_arm(name)
    qs = np.random.default_rng(5).uniform(arm.lower, arm.upper, size=(40, 6))
    targets = arm.fk(qs)
    res = solve(arm, targets, arm.mid, method="numeric", timeout=1.0, rng=np.random.default_rng(1))
    assert res.method == "numeric"
    assert res.ok.all()
    assert_reaches(name, res.q, targets)


@pytest.mark.parametrize("name", [n for n in catalogue() if load_arm(n).kuka is not None])
def test_closed_form_solves_every_reachable_pose_nearest_the_seed(name: str) -> None:
    arm = load_arm(name)
    rng = np.random.default_rng(9)
    qs = rng.uniform(arm.lower, arm.upper, size=(300, 6))
    targets = arm.fk(qs)
    res = solve(arm, targets, qs)  # seeded with the true configuration
    assert res.method == "closed-form"
    assert res.ok.all()
    assert np.max(np.abs(res.q - qs)) < 1e-6  # the nearest solution to the seed is the seed
    # from the mid-range seed: every pose solved, and no solution inside the limits is nearer
    res = solve(arm, targets[:20], arm.mid)
    assert res.ok.all()
    assert arm.kuka is not None
    for target, q in zip(targets[:20], res.q, strict=True):
        alts = inverse_all(arm.kuka, target, limits=True)
        assert np.sum((q - arm.mid) ** 2) <= np.min(np.sum((alts - arm.mid) ** 2, axis=1)) + 1e-6


@pytest.mark.parametrize(
    "name", ["knuckle_boom_crane", "kuka_youbot_arm", "lbr_iiwa14_r820", "kr16_r2010_2"]
)
def test_position_only_targets(name: str) -> None:
    arm = load_arm(name)
    qs = np.random.default_rng(2).uniform(arm.lower, arm.upper, size=(25, arm.dof))
    points = arm.fk(qs)[:, :3, 3]
    res = solve(arm, points, arm.mid, timeout=1.0, rng=np.random.default_rng(3))
    assert res.method == "numeric"  # position-only: never the closed form
    assert res.ok.all() and arm.within_limits(res.q).all()
    assert np.max(np.abs(arm.fk(res.q)[:, :3, 3] - points)) <= TOL * 1000
    assert np.all(res.rot_err == 0.0)


def test_crane_reaches_a_point_of_its_table() -> None:
    crane = load_arm("knuckle_boom_crane")
    # boom at 30°, jib folded 60° down from the boom: tip from the thesis' lengths by hand
    b, j = math.radians(30), math.radians(-30)
    x = 7010 * math.cos(b) + 3460 * math.cos(j)
    z = 2620 + 7010 * math.sin(b) + 3460 * math.sin(j)
    assert crane.fk((0, 30, -60))[:3, 3] == pytest.approx((x, 0, z), abs=1e-9)
    q = crane.ik((0, x, z), seed=(0, 30, -60), timeout=1.0)  # the same point turned 90°
    assert crane.fk(q)[:3, 3] == pytest.approx((0, x, z), abs=1e-2)
    assert q[0] == pytest.approx(90, abs=1e-3)


def test_redundancy_follows_the_seed_and_the_preferred_posture() -> None:
    arm = load_arm("lbr_iiwa14_r820")
    rng = np.random.default_rng(11)
    q0 = rng.uniform(arm.lower * 0.6, arm.upper * 0.6, size=(20, 7))
    targets = arm.fk(q0)
    near = q0 + rng.normal(0, 3, size=q0.shape)
    plain = solve(arm, targets, near, timeout=1.0, rng=np.random.default_rng(1))
    assert plain.ok.all()
    # from a seed 3° off, the solution stays by the seed (not some other arm angle)
    assert np.max(np.abs(plain.q - q0)) < 15
    # a preferred posture pulls the solution towards it through the null space
    pref = np.zeros(7)
    pulled = solve(arm, targets, near, preferred=pref, timeout=1.0, rng=np.random.default_rng(1))
    assert pulled.ok.all()
    assert_reaches("lbr_iiwa14_r820", pulled.q, targets)
    d_plain = np.linalg.norm(plain.q - pref, axis=1)
    d_pulled = np.linalg.norm(pulled.q - pref, axis=1)
    assert np.mean(d_pulled) < np.mean(d_plain)
    assert np.all(d_pulled <= d_plain + 1e-6)


def test_unreachable_target_is_a_clear_error_within_the_timeout() -> None:
    arm = load_arm("kuka_youbot_arm")
    far = np.eye(4)
    far[:3, 3] = (5000.0, 0.0, 0.0)
    t0 = time.perf_counter()
    with pytest.raises(UnreachableError, match="KUKA youBot arm"):
        arm.ik(far, timeout=0.05)
    assert time.perf_counter() - t0 < 1.0
    res = arm.solve_ik(np.stack([far, arm.fk(arm.home_q)]), timeout=0.05)
    assert res.ok.tolist() == [False, True]
    assert np.isnan(res.value("nan")[0]).all()
    kr = load_arm("kr210_r2700_2")
    with pytest.raises(UnreachableError):
        kr.ik(far * 10)  # the closed form knows at once


def test_batch_with_tiny_timeout_returns_promptly() -> None:
    arm = load_arm("lbr_iiwa14_r820")
    far = np.broadcast_to(np.eye(4), (200, 4, 4)).copy()
    far[:, 0, 3] = 3000.0
    t0 = time.perf_counter()
    res = solve(arm, far, timeout=1e-4)
    assert not res.ok.any()
    assert time.perf_counter() - t0 < 1.0


def test_tool_frames_are_undone() -> None:
    arm = load_arm("kr10_r1100_2")
    tool = (0.0, 0.0, 200.0, 0.0, 0.0, 0.0)
    q_true = np.array([10.0, -80.0, 100.0, 20.0, 30.0, 40.0])
    target = arm.fk(q_true, tool=tool)
    for method in ("closed", "numeric"):
        q = arm.ik(target, seed=q_true + 2.0, tool=tool, method=method, timeout=1.0)  # type: ignore[arg-type]
        assert np.allclose(arm.fk(q, tool=tool), target, atol=1e-2)


def test_bad_targets_and_timeouts_are_refused() -> None:
    arm = load_arm("kr6_r900_sixx")
    with pytest.raises(ValueError, match="target"):
        arm.ik(np.zeros(5))
    with pytest.raises(ValueError, match="timeout"):
        arm.ik(np.eye(4), timeout=0)
    with pytest.raises(ValueError, match="closed form"):
        load_arm("lbr_iiwa14_r820").ik(np.eye(4), method="closed")
