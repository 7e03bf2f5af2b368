"""Forward kinematics, frames and S/T bits against the reference poses (kr6r900sixx.md §1.5)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pyopenshowvar.kinematics import (
    ABC_SINGULAR_COS,
    KR6R900SIXX,
    abc_from_matrix,
    fk_matrix,
    forward,
    frame_to_matrix,
    inv_transform,
    matrix_from_abc,
    matrix_to_frame,
    rotation_angle_deg,
    status_turn,
)

M = KR6R900SIXX

# (axes, XYZABC, S, T); angles compared mod 360 (the flange-down pose reads A 180, C 180).
GOLDEN = [
    ((0, -90, 90, 0, 0, 0), (525, 0, 890, 0, 90, 0), 2, 2),
    ((0, 0, 0, 0, 0, 0), (980, 0, 435, 0, 90, 0), 0, 0),
    ((0, -90, 90, 0, 90, 0), (445, 0, 810, 180, 0, 180), 2, 2),
    ((0, -150, 60, 0, 0, 0), (-404.042, 0, 1127.5, 0, 0, 0), 3, 2),
    (
        (10, -80, 100, 20, 30, 40),
        (551.972229, -111.219452, 678.311584, -130.933029, 14.3722048, -139.600388),
        2,
        2,
    ),
]


def _angle_diff(a: npt.ArrayLike, b: npt.ArrayLike) -> np.ndarray:
    return np.asarray(np.abs((np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0))


@pytest.mark.parametrize(("q", "pose", "s", "t"), GOLDEN)
def test_golden_poses(q: tuple[float, ...], pose: tuple[float, ...], s: int, t: int) -> None:
    got = forward(M, q)
    assert np.allclose(got[:3], pose[:3], atol=1e-3)
    assert np.all(_angle_diff(got[3:], pose[3:]) < 1e-3)
    assert status_turn(M, q) == (s, t)


def test_home_exact_text_values() -> None:
    x, y, z, a, b, c = forward(M, (0, -90, 90, 0, 0, 0))
    assert (x, y, z, a, b, c) == pytest.approx((525, 0, 890, 0, 90, 0), abs=1e-9)
    # no -0.0: a KRC never prints "A -0.0"
    assert np.signbit(a) == np.signbit(c) == False  # noqa: E712


def test_batched_equals_single() -> None:
    qs = np.array([g[0] for g in GOLDEN], dtype=float)
    batch = forward(M, qs)
    assert batch.shape == (len(GOLDEN), 6)
    for i, q in enumerate(qs):
        assert np.array_equal(batch[i], forward(M, q))
    s, t = status_turn(M, qs)
    assert list(s) == [g[2] for g in GOLDEN]  # type: ignore[arg-type]
    assert list(t) == [g[3] for g in GOLDEN]  # type: ignore[arg-type]
    assert fk_matrix(M, qs.reshape(5, 1, 6)).shape == (5, 1, 4, 4)


def test_turn_bits_even_tiny_negative() -> None:
    # reference §2.1: A1 45, A2 -119.55, A3 106, A4 +4.5e-6, A5 27, A6 -4.45e-6 -> T 34
    q = (45, -119.551010, 106, 4.48259061e-06, 27.0000057, -4.45310388e-06)
    s, t = status_turn(M, q)
    assert t == 34
    assert s == 2


def test_status_bits_a5_and_a3_threshold() -> None:
    assert status_turn(M, (0, -90, 90, 0, -30, 0)) == (6, 2 | 16)
    phi = np.degrees(np.arctan2(35, 420))
    assert M.status_phi == pytest.approx(phi)
    assert status_turn(M, (0, -90, phi + 1e-9, 0, 10, 0))[0] & 2
    assert not status_turn(M, (0, -90, phi - 1e-6, 0, 10, 0))[0] & 2


def test_a1_sign_matches_capture() -> None:
    # [FIW]: A1 45 pairs with X 840.229, Y -840.229 (negative Y for positive A1)
    x, y = forward(M, (45, -119.551010, 106, 0, 27, 0))[:2]
    assert y < 0 < x


def test_tool_moves_tcp_along_flange_z() -> None:
    tool = (0, 0, 244, -90, 0, 180)  # captured $TOOL of a KR 6
    for q in [(0, -90, 90, 0, 0, 0), (10, -80, 100, 20, 30, 40)]:
        flange = fk_matrix(M, q)
        tcp = fk_matrix(M, q, tool=tool)
        assert np.allclose(tcp[:3, 3], flange[:3, 3] + 244 * flange[:3, 2], atol=1e-9)
        assert np.allclose(tcp[:3, :3], flange[:3, :3] @ matrix_from_abc(-90, 0, 180))
    # at HOME the flange z points forward: TCP at X 525 + 244
    assert forward(M, (0, -90, 90, 0, 0, 0), tool=tool)[:3] == pytest.approx((769, 0, 890))


def test_base_frame_is_inverted() -> None:
    base = (100, 200, 50, 30, 0, 0)
    q = (10, -80, 100, 20, 30, 40)
    tcp = fk_matrix(M, q, base=base)
    assert np.allclose(frame_to_matrix(*base) @ tcp, fk_matrix(M, q), atol=1e-9)
    # tool and base given as 4x4 behave like their XYZABC forms
    assert np.allclose(fk_matrix(M, q, base=frame_to_matrix(*base)), tcp)


def test_inv_transform() -> None:
    t = frame_to_matrix(1, 2, 3, 10, 20, 30)
    assert np.allclose(inv_transform(t) @ t, np.eye(4), atol=1e-12)


def test_abc_convention_is_zyx_intrinsic() -> None:
    a, b, c = 30.0, 20.0, 10.0

    def rz(x: float) -> np.ndarray:
        r = np.radians(x)
        return np.array([[np.cos(r), -np.sin(r), 0], [np.sin(r), np.cos(r), 0], [0, 0, 1]])

    def ry(x: float) -> np.ndarray:
        r = np.radians(x)
        return np.array([[np.cos(r), 0, np.sin(r)], [0, 1, 0], [-np.sin(r), 0, np.cos(r)]])

    def rx(x: float) -> np.ndarray:
        r = np.radians(x)
        return np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])

    assert np.allclose(matrix_from_abc(a, b, c), rz(a) @ ry(b) @ rx(c))


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-179.9, 179.9),
    st.floats(-89.9, 89.9),
    st.floats(-179.9, 179.9),
)
def test_abc_round_trip(a: float, b: float, c: float) -> None:
    got = np.array([float(v) for v in abc_from_matrix(matrix_from_abc(a, b, c))])
    assert np.all(_angle_diff(got, (a, b, c)) < 1e-9)


@settings(max_examples=100, deadline=None)
@given(st.floats(-179.0, 179.0), st.floats(-179.0, 179.0), st.sampled_from([90.0, -90.0]))
def test_abc_gimbal_lock_controller_rule(a: float, c: float, b: float) -> None:
    r = matrix_from_abc(a, b, c)
    ga, gb, gc = (float(v) for v in abc_from_matrix(r))
    assert ga == 0.0
    assert gb == pytest.approx(b)
    assert rotation_angle_deg(matrix_from_abc(ga, gb, gc), r) < 1e-9
    # +90: C carries C - A; -90: C carries A + C
    expect = c - a if b > 0 else a + c
    assert _angle_diff(gc, expect) < 1e-9


def test_gimbal_threshold_matches_capture() -> None:
    # [KRA]: B 89.9999466 with rotation Rz(+0.68°) about the vertical -> A 0.0, C -0.680795908
    r = matrix_from_abc(0.680795908, 89.9999466, 0.0)
    assert np.cos(np.radians(89.9999466)) < ABC_SINGULAR_COS
    a, b, c = (float(v) for v in abc_from_matrix(r))
    assert a == 0.0
    assert b == pytest.approx(89.9999466, abs=1e-7)
    assert c == pytest.approx(-0.680795908, abs=1e-6)
    # just outside the band the ordinary formula is used
    r = matrix_from_abc(10.0, 89.99, 5.0)
    assert np.allclose([float(v) for v in abc_from_matrix(r)], (10.0, 89.99, 5.0))


def test_matrix_frame_round_trip_batched() -> None:
    rng = np.random.default_rng(1)
    poses = np.column_stack(
        [
            rng.uniform(-900, 900, (50, 3)),
            rng.uniform(-170, 170, 50),
            rng.uniform(-80, 80, 50),
            rng.uniform(-170, 170, 50),
        ]
    )
    back = matrix_to_frame(frame_to_matrix(*poses.T))
    assert np.allclose(back, poses, atol=1e-9)
    assert np.array_equal(matrix_to_frame(frame_to_matrix(*poses[3])), back[3])


_EXACT = st.sampled_from([-180.0, -90.0, 0.0, 90.0, 180.0])


@settings(max_examples=150, deadline=None)
@given(
    st.one_of(_EXACT, st.floats(-180.0, 180.0)),
    st.one_of(_EXACT, st.floats(-90.0, 90.0)),
    st.one_of(_EXACT, st.floats(-180.0, 180.0)),
)
def test_abc_is_in_the_documented_range(a: float, b: float, c: float) -> None:
    """docs/kinematics.md: A, C in (-180°, 180°], B in [-90°, 90°] — never A -180.0."""
    r = matrix_from_abc(a, b, c)
    ga, gb, gc = (float(v) for v in abc_from_matrix(r))
    assert -180.0 < ga <= 180.0 and -180.0 < gc <= 180.0 and -90.0 <= gb <= 90.0
    assert rotation_angle_deg(matrix_from_abc(ga, gb, gc), r) < 1e-6


@settings(max_examples=100, deadline=None)
@given(
    st.lists(
        st.sampled_from([-180.0, -90.0, 0.0, 90.0, 180.0]) | st.floats(-170, 170),
        min_size=6,
        max_size=6,
    )
)
def test_forward_pose_angles_in_range(q: list[float]) -> None:
    a, b, c = forward(M, q)[3:]
    assert -180.0 < a <= 180.0 and -180.0 < c <= 180.0 and -90.0 <= b <= 90.0


def test_flange_down_is_a_plus_180() -> None:
    # atan2(-0.0, -1) = -180: the pose the issue reported now reads A 180
    assert tuple(forward(M, (0, -90, 90, 0, 90, 0))[3:]) == (180.0, 0.0, 180.0)


# --- the single-pose FK of the simulated robot's readings -------------------------------------
_angle = st.floats(-190.0, 190.0, allow_nan=False) | st.sampled_from([0.0, -0.0, 180.0, -180.0])
_frame = st.none() | st.tuples(
    *(st.floats(-300.0, 300.0) for _ in range(3)), *(st.floats(-180.0, 180.0) for _ in range(3))
)


@settings(max_examples=150, deadline=None)
@given(st.lists(_angle, min_size=6, max_size=6), _frame, _frame)
def test_single_pose_fk_matches_the_batched_fk(
    q: list[float], tool: tuple[float, ...] | None, base: tuple[float, ...] | None
) -> None:
    from pyopenshowvar.kinematics.single import SinglePoseFK

    fk = SinglePoseFK(M)
    tool_m = None if tool is None else frame_to_matrix(*tool)
    base_m = None if base is None else frame_to_matrix(*base)
    fk.set_frames(tool_m, base_m)
    got = np.array(fk.frame(q))
    want = forward(M, q, tool_m, base_m)
    assert np.allclose(got[:3], want[:3], atol=1e-9)
    # the same rotation (A and C swap meaning only at the B = ±90° singularity)
    assert rotation_angle_deg(matrix_from_abc(*got[3:]), matrix_from_abc(*want[3:])) < 1e-7
    assert all(-180.0 < v <= 180.0 for v in got[3:])
    assert fk.status_turn(q) == status_turn(M, q)
    fk.set_frames(None, None)
    assert fk.frame([0, -90, 90, 0, 0, 0]) == (525.0, 0.0, 890.0, 0.0, 90.0, 0.0)
