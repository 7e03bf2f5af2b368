"""FK of every catalogue arm against an independent computation from its source chain.

The chains below are typed in from the sources (URDF joint origins, axes and tool0 frames;
the thesis' and the toolbox's D-H tables) and multiplied out here with our own Rodrigues
and rpy code, not the library's: ``arms.fk`` must agree to 1e-9 mm at random poses.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from pyopenshowvar.arms import catalogue, load_arm
from pyopenshowvar.kinematics import KR6R900SIXX, fk_matrix

PI = math.pi
H = PI / 2

# (xyz m, rpy rad, axis) per joint, then the tool0 (flange) frame (xyz, rpy), KUKA style
# URDFs of kroshu/kuka_robot_descriptions; the KR 6 from its older URDF style (axes ±x/±y/±z).
Chain = tuple[
    list[tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]],
    tuple[tuple[float, ...], tuple[float, ...]],
]


def kuka_new_style(d1: float, a1: float, a2: float, a3: float, d4: float, d6: float) -> Chain:
    z = (0.0, 0.0, 1.0)
    joints = [
        ((0.0, 0.0, 0.0), (-PI, 0.0, 0.0), z),
        ((a1, 0.0, -d1), (H, 0.0, 0.0), z),
        ((a2, 0.0, 0.0), (0.0, 0.0, -H), z),
        ((a3, 0.0, 0.0), (H, 0.0, 0.0), z),
        ((0.0, 0.0, -d4), (-H, 0.0, 0.0), z),
        ((0.0, 0.0, 0.0), (H, 0.0, 0.0), z),
    ]
    return joints, ((0.0, 0.0, -d6), (0.0, PI, 0.0))


URDF_CHAINS: dict[str, Chain] = {
    "kr10_r1100_2": kuka_new_style(0.4, 0.025, 0.56, 0.025, 0.515, 0.09),
    "kr16_r2010_2": kuka_new_style(0.52, 0.16, 0.98, 0.15, 0.86, 0.153),
    "kr210_r2700_2": kuka_new_style(0.645, 0.33, 1.15, 0.115, 1.22, 0.215),
    "kr560_r3100_2": kuka_new_style(0.86, 0.5, 1.55, 0.18, 1.0345, 0.305),
    "kr6_r900_sixx": (
        [
            ((0.0, 0.0, 0.4), (0.0, 0.0, 0.0), (0.0, 0.0, -1.0)),
            ((0.025, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
            ((0.455, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
            ((0.0, 0.0, 0.035), (0.0, 0.0, 0.0), (-1.0, 0.0, 0.0)),
            ((0.42, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
            ((0.08, 0.0, 0.0), (0.0, 0.0, 0.0), (-1.0, 0.0, 0.0)),
        ],
        ((0.0, 0.0, 0.0), (0.0, H, 0.0)),
    ),
    "lbr_iiwa14_r820": (
        [
            ((0.0, 0.0, 0.1575), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
            ((0.0, 0.0, 0.2025), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
            ((0.0, 0.0, 0.2045), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
            ((0.0, 0.0, 0.2155), (0.0, 0.0, 0.0), (0.0, -1.0, 0.0)),
            ((0.0, 0.0, 0.1845), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
            ((0.0, 0.0, 0.2155), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
            ((0.0, 0.0, 0.081), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
        ],
        ((0.0, 0.0, 0.071), (0.0, 0.0, 0.0)),
    ),
    "kuka_youbot_arm": (
        [
            ((0.024, 0.0, 0.096), (0.0, 0.0, math.radians(170)), (0.0, 0.0, -1.0)),
            ((0.033, 0.0, 0.019), (0.0, math.radians(-65), 0.0), (0.0, 1.0, 0.0)),
            ((0.0, 0.0, 0.155), (0.0, math.radians(146), 0.0), (0.0, 1.0, 0.0)),
            ((0.0, 0.0, 0.135), (0.0, math.radians(-102.5), 0.0), (0.0, 1.0, 0.0)),
            ((-0.002, 0.0, 0.130), (0.0, 0.0, math.radians(167.5)), (0.0, 0.0, -1.0)),
        ],
        ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    ),
}


def rpy_matrix(r: float, p: float, y: float) -> npt.NDArray[np.float64]:
    def rx(a: float) -> npt.NDArray[np.float64]:
        return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])

    def ry(a: float) -> npt.NDArray[np.float64]:
        return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])

    def rz(a: float) -> npt.NDArray[np.float64]:
        return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])

    return rz(y) @ ry(p) @ rx(r)


def hom(r: npt.NDArray[np.float64], p: npt.ArrayLike) -> npt.NDArray[np.float64]:
    t = np.eye(4)
    t[:3, :3] = r
    t[:3, 3] = p
    return t


def axis_angle(u: tuple[float, ...], angle: float) -> npt.NDArray[np.float64]:
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def urdf_fk(chain: Chain, q_deg: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Flange frame in mm: Π origin·rot(axis, q), then tool0."""
    joints, (txyz, trpy) = chain
    t = np.eye(4)
    for (xyz, rpy, axis), q in zip(joints, np.radians(np.asarray(q_deg)), strict=True):
        t = t @ hom(rpy_matrix(*rpy), np.array(xyz) * 1000) @ hom(axis_angle(axis, q), [0, 0, 0])
    return t @ hom(rpy_matrix(*trpy), np.array(txyz) * 1000)


def dh_standard(a: float, alpha: float, d: float, theta: float) -> npt.NDArray[np.float64]:
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0, sa, ca, d],
            [0, 0, 0, 1],
        ]
    )


def dh_modified(alpha: float, a: float, d: float, theta: float) -> npt.NDArray[np.float64]:
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st, 0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0, 0, 0, 1],
        ]
    )


def crane_fk(q: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Thesis Table 3.3 (modified D-H), L1 = 2.62 m, L2 = 7.01 m, L3 = 3.46 m (mm here)."""
    t1, t2, t3 = np.radians(np.asarray(q))
    return (
        dh_modified(0, 0, 2620, t1)
        @ dh_modified(H, 0, 0, t2)
        @ dh_modified(0, 7010, 0, t3)
        @ dh_modified(0, 3460, 0, 0)
    )


def cobra_fk(q: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Corke's standard D-H of the Cobra 600: d1 387, a1 325, a2 275 / alpha2 180°, d3 = q3."""
    q1, q2, d3, q4 = np.asarray(q, dtype=np.float64)
    return (
        dh_standard(325, 0, 387, math.radians(q1))
        @ dh_standard(275, PI, 0, math.radians(q2))
        @ dh_standard(0, 0, d3, 0)
        @ dh_standard(0, 0, 0, math.radians(q4))
    )


def ship_crane_fk(q: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Henriksen et al.'s Table 3 (standard D-H, first row fixed), Table 4's lengths in mm."""
    b0, b1, b2 = np.radians(np.asarray(q))
    return (
        dh_standard(-20700, PI, -3000, 0.0)
        @ dh_standard(0, H, 3000, b0)
        @ dh_standard(19200, 0, 0, b1)
        @ dh_standard(9600, -H, 0, b2)
    )


def reference_fk(name: str, q: npt.ArrayLike) -> npt.NDArray[np.float64]:
    if name == "knuckle_boom_crane":
        return crane_fk(q)
    if name == "supply_vessel_crane":
        return ship_crane_fk(q)
    if name == "adept_cobra600":
        return cobra_fk(q)
    return urdf_fk(URDF_CHAINS[name], q)


def test_every_catalogue_arm_has_an_independent_reference() -> None:
    assert set(catalogue()) == {
        *URDF_CHAINS,
        "knuckle_boom_crane",
        "supply_vessel_crane",
        "adept_cobra600",
    }


@pytest.mark.parametrize("name", catalogue())
def test_fk_matches_the_source_chain(name: str) -> None:
    arm = load_arm(name)
    rng = np.random.default_rng(sum(map(ord, name)))
    qs = rng.uniform(arm.lower, arm.upper, size=(40, arm.dof))
    got = arm.fk(qs)  # batched
    for q, t in zip(qs, got, strict=True):
        ref = reference_fk(name, q)
        assert np.max(np.abs(t[:3, 3] - ref[:3, 3])) < 1e-9, (name, q)
        assert np.max(np.abs(t[:3, :3] - ref[:3, :3])) < 1e-12, (name, q)
    # one configuration alone gives the same frame as in the batch
    assert np.array_equal(arm.fk(qs[0]), got[0])


def test_kr6_keeps_its_model_and_figures() -> None:
    arm = load_arm("kr6_r900_sixx")
    assert arm.kuka is KR6R900SIXX
    assert arm.model_name == "#KR6R900SIXX C4SR FLR"
    qs = np.random.default_rng(3).uniform(arm.lower, arm.upper, size=(500, 6))
    assert np.max(np.abs(arm.fk(qs) - fk_matrix(KR6R900SIXX, qs))) < 1e-9
    assert np.allclose(arm.fk_pose((0, -90, 90, 0, 0, 0)), (525, 0, 890, 0, 90, 0), atol=1e-9)


@pytest.mark.parametrize(
    ("name", "lengths"),
    [
        # a1, d1, a2, a3 (offset of A4 above A3), d4 (A3 to wrist), d6 (wrist to flange), mm
        ("kr6_r900_sixx", (25, 400, 455, 35, 420, 80)),
        ("kr10_r1100_2", (25, 400, 560, 25, 515, 90)),
        ("kr16_r2010_2", (160, 520, 980, 150, 860, 153)),
        ("kr210_r2700_2", (330, 645, 1150, 115, 1220, 215)),
        # the OPW parameter file of the same repository: a1 .5, a2 -.18, c1 .86, c2 1.55, c3 1.0345, c4 .305
        ("kr560_r3100_2", (500, 860, 1550, 180, 1034.5, 305)),
    ],
)
def test_closed_form_tables_of_the_kuka_family(name: str, lengths: tuple[float, ...]) -> None:
    model = load_arm(name).kuka
    assert model is not None
    a, d = model.a, model.d
    got = (a[0], d[0], a[1], a[2], d[3], d[5])
    assert got == pytest.approx(lengths, abs=1e-9)
    assert list(model.sign) == [-1, 1, 1, -1, 1, -1]
    assert np.array_equal(model.flange, np.eye(4))


@pytest.mark.parametrize(
    "name",
    [
        "knuckle_boom_crane",
        "supply_vessel_crane",
        "adept_cobra600",
        "kuka_youbot_arm",
        "lbr_iiwa14_r820",
    ],
)
def test_arms_outside_the_kuka_family_have_no_closed_form(name: str) -> None:
    assert load_arm(name).kuka is None


def test_jacobian_matches_finite_differences() -> None:
    for name in ("lbr_iiwa14_r820", "adept_cobra600", "kuka_youbot_arm"):
        arm = load_arm(name)
        q = arm.mid + 0.1 * (arm.upper - arm.lower) * np.linspace(-1, 1, arm.dof)
        j = arm.jacobian(q)
        unit = np.where(arm.revolute, math.degrees(1.0), 1.0)  # J is per rad / per mm
        for k in range(arm.dof):
            dq = np.zeros(arm.dof)
            dq[k] = 1e-6 * unit[k]
            t1, t0 = arm.fk(q + dq), arm.fk(q - dq)
            lin = (t1[:3, 3] - t0[:3, 3]) / 2e-6
            dr = (t1[:3, :3] - t0[:3, :3]) / 2e-6 @ arm.fk(q)[:3, :3].T
            ang = np.array([dr[2, 1], dr[0, 2], dr[1, 0]])
            assert np.allclose(j[:3, k], lin, atol=1e-4), (name, k)
            assert np.allclose(j[3:, k], ang, atol=1e-7), (name, k)
