"""Jacobian vs finite differences, damped-least-squares velocity IK, manipulability, statics."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pyopenshowvar.kinematics import (
    KR6R900SIXX,
    Load,
    dls_velocity_ik,
    fk_matrix,
    gravity_torques,
    jacobian,
    manipulability,
    torques_to_wrench,
    wrench_to_torques,
)

M = KR6R900SIXX
TOOL = (0, 0, 244, -90, 0, 180)
HOME = np.array([0.0, -90.0, 90.0, 0.0, 0.0, 0.0])

axis_vectors = st.tuples(*[st.floats(0.0, 1.0)] * 6).map(
    lambda u: M.lower + np.array(u) * (M.upper - M.lower)
)


def _numeric_jacobian(
    q: np.ndarray, tool: npt.ArrayLike | None = None, h: float = 1e-6
) -> np.ndarray:
    t0 = fk_matrix(M, q, tool)
    num = np.zeros((6, 6))
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = np.degrees(h)
        tp, tm = fk_matrix(M, q + dq, tool), fk_matrix(M, q - dq, tool)
        num[:3, i] = (tp[:3, 3] - tm[:3, 3]) / (2 * h)
        w = (tp[:3, :3] - tm[:3, :3]) / (2 * h) @ t0[:3, :3].T  # skew(ω)
        num[3:, i] = (w[2, 1], w[0, 2], w[1, 0])
    return num


@settings(max_examples=60, deadline=None)
@given(axis_vectors, st.booleans())
def test_jacobian_matches_finite_differences(q: np.ndarray, with_tool: bool) -> None:
    tool = TOOL if with_tool else None
    j = jacobian(M, q, tool)
    num = _numeric_jacobian(q, tool)
    assert np.allclose(j[:3], num[:3], atol=1e-5)  # mm/rad
    assert np.allclose(j[3:], num[3:], atol=1e-8)  # rad/rad


def test_jacobian_columns_use_kuka_axis_directions() -> None:
    j = jacobian(M, np.zeros(6))
    assert np.allclose(j[3:, 0], (0, 0, -1))  # A1 turns about -Z
    assert np.allclose(j[3:, 1], (0, 1, 0))  # A2 about +Y
    assert np.allclose(j[3:, 3], (-1, 0, 0))  # A4 about -X
    assert j[1, 0] < 0  # positive A1 moves the flange toward -Y


def test_batched_jacobian_equals_single() -> None:
    rng = np.random.default_rng(3)
    qs = rng.uniform(M.lower, M.upper, (4, 5, 6))
    jb = jacobian(M, qs, TOOL)
    assert jb.shape == (4, 5, 6, 6)
    assert np.allclose(jb[2, 3], jacobian(M, qs[2, 3], TOOL))
    assert np.allclose(manipulability(M, qs)[1, 4], manipulability(M, qs[1, 4]))
    tw = np.array([5.0, 1.0, -2.0, 0.01, 0.0, 0.02])
    assert np.allclose(dls_velocity_ik(M, qs, tw)[3, 1], dls_velocity_ik(M, qs[3, 1], tw))


@settings(max_examples=60, deadline=None)
@given(axis_vectors)
def test_dls_tracks_twist_away_from_singularities(q: np.ndarray) -> None:
    # near a singularity the damping is active by design: such draws are rejected (assume),
    # not silently passed, so Hypothesis keeps searching for regular poses
    assume(np.linalg.svd(_scaled(q), compute_uv=False)[-1] >= 0.06)
    tw = np.array([20.0, -10.0, 5.0, 0.1, -0.2, 0.05])  # mm/s, rad/s
    dq = dls_velocity_ik(M, q, tw)  # deg/s
    assert np.allclose(jacobian(M, q) @ np.radians(dq), tw, atol=1e-9)


def _scaled(q: np.ndarray) -> np.ndarray:
    j = jacobian(M, q)
    j[:3] /= 1000.0
    return j


def test_dls_bounded_at_singularity() -> None:
    assert manipulability(M, HOME) < 1e-12  # A5 = 0: wrist singular
    tw = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    dq = dls_velocity_ik(M, HOME, tw)
    assert np.all(np.isfinite(dq))
    assert np.max(np.abs(dq)) < 2000.0
    # least squares in SI-scaled units: the residual is smaller than doing nothing
    res = jacobian(M, HOME) @ np.radians(dq) - tw
    res[:3] /= 1000.0
    assert np.linalg.norm(res) < 0.5 * np.linalg.norm(tw)


def test_manipulability_positive_in_regular_pose() -> None:
    assert manipulability(M, (10, -80, 100, 20, 30, 40)) > 0.01
    # stretched arm: elbow singular (A3 = phi lines the wrist up with A2-A3)
    assert manipulability(M, (0, -30, M.status_phi, 0, 30, 0)) < 1e-9


# ---------------------------------------------------------------------------------- statics
GRAVITY_TABLE = [
    (HOME, (0, -24.8, -25.5, -0.8, -0.6, 0), (0, -57.2, -57.9, -0.8, -8.3, 0)),
    (np.zeros(6), (0, -108.0, -25.5, -0.8, -0.6, 0), (0, -167.1, -57.9, -0.8, -8.3, 0)),
    ((0, -45, 45, 0, 0, 0), (0, -83.3, -25.5, -0.8, -0.6, 0), (0, -134.6, -57.9, -0.8, -8.3, 0)),
]


@pytest.mark.parametrize(("q", "free", "loaded"), GRAVITY_TABLE)
def test_gravity_table(q: np.ndarray, free: tuple[float, ...], loaded: tuple[float, ...]) -> None:
    assert np.allclose(gravity_torques(M, q), free, atol=0.1)
    assert np.allclose(gravity_torques(M, q, Load(6.0, (0, 0, 50))), loaded, atol=0.1)


def test_gravity_sign_and_batch() -> None:
    qs = np.array([g[0] for g in GRAVITY_TABLE], dtype=float)
    batch = gravity_torques(M, qs, Load(6.0, (0, 0, 50)))
    assert np.allclose(batch[1], gravity_torques(M, qs[1], Load(6.0, (0, 0, 50))))
    assert np.allclose(gravity_torques(M, HOME, sign=-1.0), -gravity_torques(M, HOME))
    # A1 carries no gravity torque in any pose (vertical axis)
    rng = np.random.default_rng(5)
    assert np.allclose(
        gravity_torques(M, rng.uniform(M.lower, M.upper, (20, 6)))[:, 0], 0, atol=1e-9
    )


def test_gravity_equals_jt_of_weight_for_point_load() -> None:
    # a massless robot with a point load at the TCP: τ = Jᵀ F with F the weight on the TCP
    q = np.array([10.0, -80.0, 100.0, 20.0, 30.0, 40.0])
    load = Load(5.0, (0.0, 0.0, 244.0))
    diff = gravity_torques(M, q, load) - gravity_torques(M, q)
    weight_on_env = np.array([0, 0, -5.0 * 9.81, 0, 0, 0])  # the TCP pushes down with the load
    tool = (0, 0, 244, 0, 0, 0)
    assert np.allclose(diff, -wrench_to_torques(M, q, weight_on_env, tool), atol=1e-9)


def test_wrench_to_torques_units() -> None:
    # TCP pushing down with 10 N at HOME: lever arm for A2 is 0.5 m (525 - 25 mm); pushing
    # down means driving A2 positive (positive A2 tips the arm down), the opposite of gravity
    tau = wrench_to_torques(M, HOME, (0, 0, -10.0, 0, 0, 0))
    assert tau[1] == pytest.approx(10.0 * 0.5)
    assert tau[0] == pytest.approx(0.0)
    # a pure moment about base +X; at HOME A4 and A6 turn about -X
    tau = wrench_to_torques(M, HOME, (0, 0, 0, 2.0, 0, 0))
    assert tau[3] == pytest.approx(-2.0)


@settings(max_examples=60, deadline=None)
@given(axis_vectors, st.lists(st.floats(-50, 50), min_size=6, max_size=6))
def test_torques_to_wrench_inverts(q: np.ndarray, f: list[float]) -> None:
    assume(np.linalg.svd(_scaled(q), compute_uv=False)[-1] >= 0.06)  # regularised near them
    wrench = np.array(f)
    tau = wrench_to_torques(M, q, wrench, TOOL)
    assert np.allclose(torques_to_wrench(M, q, tau, tool=TOOL), wrench, atol=1e-7)


def test_torques_to_wrench_bounded_at_singularity() -> None:
    f = torques_to_wrench(M, HOME, (0, 1.0, 0, 1.0, 0, 1.0))
    assert np.all(np.isfinite(f)) and np.max(np.abs(f)) < 1e4


def test_load_validation() -> None:
    with pytest.raises(ValueError):
        Load(-1.0)
    assert Load(2.0).com_mm == (0.0, 0.0, 0.0)
