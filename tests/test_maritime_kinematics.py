"""Kinematics of the crane head (Delta TAC) and of the ship crane, against independent sums.

Henriksen et al.: the Delta's FPK∘IPK round trip over the joint range, the upper of the two
sphere intersections, the Jacobian of eq. 32 against finite differences, the workspace of
eq. 33; the ship crane's FK against the paper's own eq. 38 product of Table 3's rows.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyopenshowvar_apps.maritime.crane import STATIONARY, ShipCrane
from pyopenshowvar_apps.maritime.delta import TAC, fpk, ipk, jacobian, workspace

from pyopenshowvar.arms import load_arm

TAC0 = TAC()
LO, HI = TAC0.alpha_min, TAC0.alpha_max
angles = st.lists(st.floats(LO, HI), min_size=3, max_size=3)


def rods(tac: TAC, p: npt.NDArray[np.float64], alpha: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Rod lengths from an independent closed chain: base joint, knee, plate attachment.

    Arm i lies in the plane of {t_i} = {t} turned by ψ_i about x: its joint sits l_k out from
    the centre, the knee l_a further along the arm at angle α, the rod ends l_p out from the
    TCP on the top plate.
    """
    out = []
    for psi, al in zip((5 * math.pi / 6, 3 * math.pi / 2, math.pi / 6), alpha, strict=True):
        inward = np.array([0.0, math.cos(psi), math.sin(psi)])  # y_{t_i} in {t}
        knee = (
            np.array([tac.l_a * math.sin(al), 0, 0]) - (tac.l_k + tac.l_a * math.cos(al)) * inward
        )
        plate = p - tac.l_p * inward
        out.append(np.linalg.norm(plate - knee))
    return np.array(out)


@settings(max_examples=200, deadline=None)
@given(angles)
def test_fpk_closes_the_rods_and_ipk_gives_the_angles_back(alpha: list[float]) -> None:
    p = fpk(TAC0, alpha)
    assert np.all(np.isfinite(p))
    assert rods(TAC0, p, alpha) == pytest.approx([TAC0.l_r] * 3, abs=1e-9)
    # the solution "over the base plate": above every knee, and the other one is below
    assert p[0] > max(TAC0.l_a * math.sin(a) for a in alpha)
    assert ipk(TAC0, p) == pytest.approx(alpha, abs=1e-9)


def test_all_arms_level_is_not_a_singularity_of_fpk() -> None:
    # α = 0 puts the three knees and the frame's origin in one plane (C of eq. 20 singular)
    p = fpk(TAC0, [0.0, 0.0, 0.0])
    expected = math.sqrt(TAC0.l_r**2 - (TAC0.l_k + TAC0.l_a - TAC0.l_p) ** 2)
    assert p == pytest.approx([expected, 0.0, 0.0], abs=1e-12)


def test_ipk_of_unreachable_points_is_nan_and_batches() -> None:
    far = np.array([[30.0, 0.0, 0.0], [7.0, 0.0, 0.0]])
    out = ipk(TAC0, far)
    assert np.isnan(out[0]).all() and np.isfinite(out[1]).all()
    assert list(TAC0.reachable(far)) == [False, True]


def test_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(4)
    for alpha in rng.uniform(LO, HI, (20, 3)):
        p = fpk(TAC0, alpha)
        j = jacobian(TAC0, p, alpha)
        h = 1e-6
        fd = np.stack([(fpk(TAC0, alpha + h * e) - fpk(TAC0, alpha - h * e)) / (2 * h)
                       for e in np.eye(3)], axis=-1)  # fmt: skip
        assert j == pytest.approx(fd, abs=1e-6)


def test_workspace_grid_is_inside_eq_33_and_reachable() -> None:
    ws = workspace(TAC0, 0.5)
    lat = TAC0.l_r + TAC0.l_p - TAC0.l_k
    assert len(ws.points) > 100
    assert ws.points[:, 0].min() >= 0 and ws.points[:, 0].max() <= TAC0.l_a + TAC0.l_r
    assert np.abs(ws.points[:, 1:]).max() <= lat + 1e-9
    assert TAC0.in_range(ipk(TAC0, ws.points)).all()
    x_d, margin = ws.axis_centre
    assert TAC0.reachable([x_d, 0, 0]) and margin > 0
    assert ws.inside_hull([x_d, 0, 0]) and not ws.inside_hull([x_d + 20, 0, 0])


# ------------------------------------------------------------------------------ the crane
def a_matrix(a: float, alpha: float, d: float, theta: float) -> npt.NDArray[np.float64]:
    """Eq. 38 of the paper, typed in: Rot_z,θ Trans_z,d Trans_x,a Rot_x,α."""
    ct, st_, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([[ct, -st_ * ca, st_ * sa, a * ct], [st_, ct * ca, -ct * sa, a * st_],
                     [0, sa, ca, d], [0, 0, 0, 1.0]])  # fmt: skip


def table3(beta: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """T_4^0 of Table 3 with Table 4's lengths (m): L_sx −20.70, L_sz 3, L_0 3, L_1 19.2, L_2 9.6."""
    b0, b1, b2 = np.asarray(beta, dtype=float)
    return (a_matrix(-20.70, math.pi, -3.00, 0.0) @ a_matrix(0.0, math.pi / 2, 3.00, b0)
            @ a_matrix(19.20, 0.0, 0.0, b1) @ a_matrix(9.60, -math.pi / 2, 0.0, b2))  # fmt: skip


def test_ship_crane_fk_is_the_product_of_table_3() -> None:
    arm = load_arm("supply_vessel_crane")
    rng = np.random.default_rng(11)
    qs = rng.uniform(arm.lower, arm.upper, (50, 3))
    got = arm.fk(qs)
    for q, t in zip(qs, got, strict=True):
        ref = table3(np.radians(q))
        assert t[:3, 3] / 1000.0 == pytest.approx(ref[:3, 3], abs=1e-12)
        assert t[:3, :3] == pytest.approx(ref[:3, :3], abs=1e-12)
    assert arm.home_q == pytest.approx(np.degrees(STATIONARY))


def test_stationary_configuration_points_to_starboard_with_the_jib_level() -> None:
    t = ShipCrane().head_frame(STATIONARY)
    # foot 20.7 m aft, 3 m + L0 above CO (z down); boom 45°, jib level, pointing starboard
    assert t[:3, 3] == pytest.approx(
        [-20.70, 19.2 / math.sqrt(2) + 9.6, -6.0 - 19.2 / math.sqrt(2)]
    )
    assert t[:3, 0] == pytest.approx([0, 1, 0], abs=1e-12)  # x_t along the jib: starboard


@settings(max_examples=60, deadline=None)
@given(st.floats(-3.0, 3.0), st.floats(0.1, 1.3), st.floats(-2.5, -0.05))
def test_elbow_ik_of_eq_43_inverts_the_table(b0: float, b1: float, b2: float) -> None:
    crane = ShipCrane()
    o = crane.head_frame([b0, b1, b2])[:3, 3]
    assert crane.ik(o) == pytest.approx([b0, b1, b2], abs=1e-9)
    # the TCP x_d beyond the jib (§8: L_2 replaced by L_2 + x_d) gives the same angles
    tip = crane.head_frame([b0, b1, b2])
    assert crane.ik(tip[:3, 3] + 7.0 * tip[:3, 0], l2_extra=7.0) == pytest.approx(
        [b0, b1, b2], abs=1e-9
    )


def test_crane_ik_out_of_reach_is_an_error() -> None:
    with pytest.raises(ValueError, match="out of the crane's reach"):
        ShipCrane().ik([200.0, 0.0, 0.0])
