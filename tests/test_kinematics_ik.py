"""Inverse kinematics: FK∘IK round trips, S/T selection, limits, unreachable poses, batches."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pyopenshowvar.errors import KvpError
from pyopenshowvar.kinematics import (
    KR6R900SIXX,
    UnreachableError,
    fk_matrix,
    forward,
    inverse,
    inverse_all,
    link_frames,
    rotation_angle_deg,
    status_turn,
)

M = KR6R900SIXX
TOOL = (0, 0, 244, -90, 0, 180)
BASE = (300, -100, 50, 20, 5, -10)


def _regular(q: np.ndarray) -> bool:
    """Away from singularities, bit boundaries and limits (so S/T pin one solution)."""
    if np.any(np.abs(q) < 1e-3) or np.any(np.abs(np.abs(q) - 180) < 1e-3):
        return False
    if abs(q[4]) < 3.0 or abs(q[2] - M.status_phi) < 3.0:  # wrist / elbow singularity
        return False
    w = link_frames(M, q)[5, :3, 3]
    return bool(np.hypot(w[0], w[1]) > 30.0)  # shoulder singularity


def _nudge(u: tuple[float, ...]) -> np.ndarray:
    """Map unit floats into the limits, then push values off singularities and bit boundaries
    (moving instead of filtering keeps Hypothesis' boundary-heavy draws useful)."""
    q = M.lower + 1.0 + np.array(u) * (M.upper - M.lower - 2.0)
    q = np.where(np.abs(q) < 0.01, q + 0.37, q)
    if abs(q[4]) < 3.0:
        q[4] += 7.0
    if abs(q[2] - M.status_phi) < 3.0:
        q[2] += 7.0
    return q


axis_vectors = st.tuples(*[st.floats(0.0, 1.0)] * 6).map(_nudge)


def _assert_same_pose(t1: np.ndarray, t2: np.ndarray) -> None:
    assert np.max(np.abs(t1[..., :3, 3] - t2[..., :3, 3])) < 1e-6
    assert np.max(rotation_angle_deg(t1, t2)) < 1e-6


@settings(max_examples=300, deadline=None)
@given(axis_vectors)
def test_fk_ik_round_trip_with_status_turn(q: np.ndarray) -> None:
    assume(_regular(q))
    target = fk_matrix(M, q)
    s, t = status_turn(M, q)
    got = inverse(M, target, s=s, t=t)
    _assert_same_pose(fk_matrix(M, got), target)
    assert status_turn(M, got) == (s, t)
    assert M.within_limits(got)
    # S and T pin down a single solution away from singularities
    assert np.max(np.abs(got - q)) < 1e-6


@settings(max_examples=100, deadline=None)
@given(axis_vectors)
def test_fk_ik_round_trip_with_tool_base_and_xyzabc(q: np.ndarray) -> None:
    assume(_regular(q))
    pose = forward(M, q, tool=TOOL, base=BASE)  # XYZABC, as read from $POS_ACT
    s, t = status_turn(M, q)
    got = inverse(M, pose, s=s, t=t, tool=TOOL, base=BASE)
    _assert_same_pose(fk_matrix(M, got, TOOL, BASE), fk_matrix(M, q, TOOL, BASE))
    assert np.max(np.abs(got - q)) < 1e-6


@settings(max_examples=100, deadline=None)
@given(axis_vectors)
def test_nearest_current_without_status(q: np.ndarray) -> None:
    assume(_regular(q))
    got = inverse(M, fk_matrix(M, q), current=q + 0.5)
    assert np.max(np.abs(got - q)) < 1e-6


@settings(max_examples=100, deadline=None)
@given(axis_vectors)
def test_inverse_all_solutions_are_exact(q: np.ndarray) -> None:
    target = fk_matrix(M, q)
    sols = inverse_all(M, target)
    assert 1 <= len(sols) <= 8
    _assert_same_pose(fk_matrix(M, sols), np.broadcast_to(target, (len(sols), 4, 4)))


@settings(max_examples=100, deadline=None)
@given(axis_vectors)
def test_inverse_all_contains_q_away_from_singularities(q: np.ndarray) -> None:
    # q itself (mod 360) is among them unless a singularity made its free angle arbitrary
    assume(_regular(q))
    sols = inverse_all(M, fk_matrix(M, q))
    wrapped = 180.0 - (180.0 - q) % 360.0
    assert np.min(np.max(np.abs(sols - wrapped), axis=1)) < 1e-6


def test_eight_solutions_with_wrist_flips() -> None:
    sols = inverse_all(M, fk_matrix(M, (10, -80, 100, 20, 30, 40)))
    assert sols.shape == (8, 6)
    st_pairs = {status_turn(M, s)[0] for s in sols}
    assert st_pairs == set(range(8))  # every S: shoulder × elbow × wrist flip


def test_multi_turn_equivalents_and_t_bits() -> None:
    q = np.array([30.0, -60.0, 50.0, 100.0, -40.0, -200.0])  # A6 beyond -180
    target = fk_matrix(M, q)
    s, t = status_turn(M, q)
    assert np.allclose(inverse(M, target, s=s, t=t), q)
    assert np.allclose(inverse(M, target, current=q), q)
    # without status or current the solution nearest HOME is chosen, A6 wrapped to 160
    assert np.allclose(inverse(M, target), (30, -60, 50, -80, 40, -20))
    within = inverse_all(M, target, limits=True)
    assert any(np.allclose(r, q) for r in within)
    assert all(M.within_limits(r) for r in within)
    assert len(within) > len(inverse_all(M, target))


def test_a2_beyond_minus_180_is_reachable() -> None:
    q = np.array([0.0, -185.0, 40.0, 10.0, 30.0, 5.0])  # A2 limit is -190
    s, t = status_turn(M, q)
    assert np.allclose(inverse(M, fk_matrix(M, q), s=s, t=t), q)


def test_home_singular_wrist_keeps_a4_from_current() -> None:
    home = np.array([0.0, -90.0, 90.0, 0.0, 0.0, 0.0])
    assert np.allclose(inverse(M, forward(M, home), s=2, t=2), home)
    cur = np.array([0.0, -90.0, 90.0, 25.0, 0.0, -25.0])
    got = inverse(M, forward(M, home), current=cur)
    assert np.allclose(got, cur)  # only A4 + A6 is defined; A4 comes from current
    _assert_same_pose(fk_matrix(M, got), fk_matrix(M, home))


def test_zero_axis_matches_either_t_bit() -> None:
    # round-off may give A6 = -1e-14; T 2 (A6 bit clear) must still be found
    q = np.array([0.0, -90.0, 90.0, 0.0, 30.0, 0.0])
    got = inverse(M, forward(M, q), s=2, t=2)
    assert np.allclose(got, q, atol=1e-9)


def test_unreachable_raises_with_message() -> None:
    with pytest.raises(UnreachableError, match="out of reach") as exc:
        inverse(M, (2000.0, 0.0, 400.0, 0.0, 90.0, 0.0))
    assert isinstance(exc.value, KvpError)
    assert isinstance(exc.value, ValueError)
    assert "mm beyond" in str(exc.value)
    assert inverse_all(M, (2000.0, 0.0, 400.0, 0.0, 90.0, 0.0)).shape == (0, 6)


def test_no_solution_inside_limits_names_the_limits() -> None:
    # Reachable only with A1 = 180 (behind the robot, overhead) and the requested S asks for it
    pose = forward(M, (0, -90, 90, 0, 30, 0))
    with pytest.raises(UnreachableError, match=r"S 3 .*A1 180 > 170"):
        inverse(M, pose, s=3)
    # Directly behind the robot: A1 would have to be ±180, outside ±170
    with pytest.raises(UnreachableError, match="software limits"):
        inverse(M, (-500.0, 0.0, 600.0, 0.0, 0.0, 0.0), s=0)


def test_batched_inverse_equals_single() -> None:
    rng = np.random.default_rng(7)
    qs = rng.uniform(M.lower + 10, M.upper - 10, (64, 6))
    qs[:, 4] = np.where(np.abs(qs[:, 4]) < 5, 20.0, qs[:, 4])
    poses = forward(M, qs)
    s, t = status_turn(M, qs)
    batch = inverse(M, poses, s=s, t=t)
    assert batch.shape == (64, 6)
    for i in range(0, 64, 7):
        single = inverse(M, poses[i], s=int(s[i]), t=int(t[i]))  # type: ignore[index]
        assert np.allclose(batch[i], single, atol=1e-9)
    assert np.allclose(fk_matrix(M, batch), fk_matrix(M, qs), atol=1e-6)
    all_batch = inverse_all(M, poses.reshape(8, 8, 6))
    assert all_batch.shape == (8, 8, 8, 6)


def test_batched_errors_nan_or_raise() -> None:
    poses = np.array([forward(M, (0, -90, 90, 0, 30, 0)), [3000.0, 0, 0, 0, 0, 0]])
    out = inverse(M, poses, errors="nan")
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1]))
    with pytest.raises(UnreachableError, match=r"pose \(1,\) of 2"):
        inverse(M, poses)
