"""Arm files: TOML (D-H tables, chains, the older six-axis schema) with strict keys; URDF."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from pyopenshowvar.arms import ArmFileError, UnknownArmError, arm_from_dict, load_arm
from pyopenshowvar.arms.urdf import load_urdf, to_urdf
from pyopenshowvar.kinematics import KR6R900SIXX, fk_matrix

CRANE = """
name = "crane"
convention = "modified"
[[joint]]
d = 2.62
lower = -180.0
upper = 180.0
[[joint]]
alpha = 90.0
lower = -10.0
upper = 80.0
[[joint]]
a = 7.01
lower = -150.0
upper = 20.0
[[joint]]
type = "fixed"
a = 3.46
"""


def write(tmp_path: Path, text: str, name: str = "arm.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_a_dh_table_in_metres_is_the_crane_of_the_catalogue(tmp_path: Path) -> None:
    arm = load_arm(write(tmp_path, 'length_unit = "m"\n' + CRANE))
    ref = load_arm("knuckle_boom_crane")
    q = np.random.default_rng(0).uniform(ref.lower, ref.upper, size=(20, 3))
    assert np.allclose(arm.fk(q), ref.fk(q), atol=1e-9)
    assert arm.joint_names == ("J1", "J2", "J3") and arm.dof == 3
    assert arm.kuka is None


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (("lower = -10.0", "lowr = -10.0"), "joint 2: unknown key 'lowr' (did you mean 'lower'?)"),
        (('convention = "modified"', 'convention = "modifed"'), "convention must be"),
        (
            ('name = "crane"', 'name = "crane"\nlenght_unit = "m"'),
            "unknown key 'lenght_unit' (did you mean 'length_unit'?)",
        ),
        (("upper = 20.0", 'upper = "20"'), "joint 3: 'upper' must be a finite number"),
        (("upper = 80.0\n", ""), "joint 2: missing 'upper'"),
        (
            ('type = "fixed"', 'type = "fixd"'),
            "joint 4: 'type' must be revolute or prismatic (or fixed)",
        ),
        (("alpha = 90.0", "alpha = 90.0\nxyz = [0, 0, 0]"), "joint 2: unknown key 'xyz'"),
        (("a = 3.46", "a = 3.46\nlower = 0.0"), "joint 4: a fixed row has no 'lower'"),
        (("lower = -150.0", "lower = 30.0"), "joint 3: joint J3: lower limit 30.0 >= upper 20.0"),
    ],
)
def test_a_file_with_a_typo_is_one_clear_error_naming_the_key(
    tmp_path: Path, edit: tuple[str, str], message: str
) -> None:
    text = CRANE.replace(*edit, 1)
    assert text != CRANE
    p = write(tmp_path, text)
    with pytest.raises(ArmFileError) as err:
        load_arm(p)
    assert str(err.value).startswith(f"{p}: ")
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_not_toml_and_unknown_names(tmp_path: Path) -> None:
    with pytest.raises(ArmFileError, match="not valid TOML"):
        load_arm(write(tmp_path, "name = \n"))
    with pytest.raises(UnknownArmError, match="kr210_r2700_2"):
        load_arm("kr99")  # the message lists the catalogue
    with pytest.raises(ArmFileError, match="cannot read"):
        load_arm(tmp_path / "missing.toml")


def test_the_older_six_axis_schema_loads_with_its_closed_form() -> None:
    path = Path(__file__).parents[1] / "pyopenshowvar" / "kinematics" / "kr6r900sixx.toml"
    arm = load_arm(path)
    assert arm.kuka == KR6R900SIXX
    q = np.random.default_rng(1).uniform(arm.lower, arm.upper, size=(50, 6))
    assert np.max(np.abs(arm.fk(q) - fk_matrix(KR6R900SIXX, q))) < 1e-9


def test_chain_with_prismatic_joint_inertials_and_units(tmp_path: Path) -> None:
    text = """
name = "gantry"
convention = "chain"
length_unit = "m"
angle_unit = "rad"
flange = { xyz = [0.0, 0.0, -0.1] }
[[joint]]
type = "prismatic"
axis = [1.0, 0.0, 0.0]
lower = 0.0
upper = 2.0
max_speed = 0.5
inertial = { mass = 10.0, com = [0.0, 0.0, 0.1], inertia = [1.0, 0.0, 0.0, 2.0, 0.0, 3.0] }
[[joint]]
xyz = [0.0, 0.0, 1.0]
lower = -3.14
upper = 3.14
max_speed = 1.0
"""
    arm = load_arm(write(tmp_path, text))
    assert arm.joint_types == ("prismatic", "revolute")
    assert arm.upper[0] == 2000.0 and arm.max_speed[0] == 500.0
    assert arm.max_speed[1] == pytest.approx(math.degrees(1.0))
    j0 = arm.joints[0].inertial
    assert j0 is not None and j0.mass == 10.0 and np.allclose(j0.com, (0, 0, 100))
    assert np.isnan(arm.max_accel).all()
    assert arm.fk((500.0, 90.0))[:3, 3] == pytest.approx((500.0, 0.0, 900.0), abs=1e-9)
    # the Jacobian of a prismatic joint is its axis (per mm), of a revolute one ω
    j = arm.jacobian((500.0, 90.0))
    assert j[:, 0] == pytest.approx((1, 0, 0, 0, 0, 0))
    assert j[3:, 1] == pytest.approx((0, 0, 1))


def test_builtin_entries_must_name_a_model() -> None:
    with pytest.raises(ArmFileError, match="RobotModel"):
        arm_from_dict({"builtin": "NOPE"}, "x.toml")
    with pytest.raises(ArmFileError, match="unknown key 'joint'"):
        arm_from_dict({"builtin": "KR6R900SIXX", "joint": []}, "x.toml")


def test_closed_form_can_be_required_or_refused(tmp_path: Path) -> None:
    with pytest.raises(ArmFileError, match="not a KUKA-layout 6R arm"):
        load_arm(write(tmp_path, "closed_form = true\n" + CRANE))
    kr10 = (Path(load_arm.__code__.co_filename).parent / "data" / "kr10_r1100_2.toml").read_text()
    arm = load_arm(write(tmp_path, "closed_form = false\n" + kr10, "kr10.toml"))
    assert arm.kuka is None and load_arm("kr10_r1100_2").kuka is not None


# ------------------------------------------------------------------------------- URDF

URDF = """<?xml version="1.0"?>
<robot name="two_link">
  <link name="world"/>
  <link name="base_link"><inertial><mass value="5"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="link_1"><inertial><origin xyz="0.1 0 0"/><mass value="2"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <link name="motor"><inertial><origin xyz="0 0 0"/><mass value="2"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <link name="link_2"/>
  <link name="tool0"/>
  <joint name="fix" type="fixed"><parent link="world"/><child link="base_link"/><origin xyz="0 0 0.5"/></joint>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="link_1"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="2" effort="30"/></joint>
  <joint name="m" type="fixed"><parent link="link_1"/><child link="motor"/><origin xyz="0.2 0 0"/></joint>
  <joint name="j2" type="continuous"><parent link="link_1"/><child link="link_2"/>
    <origin xyz="0.4 0 0"/><axis xyz="0 0 1"/></joint>
  <joint name="t" type="fixed"><parent link="link_2"/><child link="tool0"/><origin xyz="0.3 0 0" rpy="0 1.5707963267948966 0"/></joint>
</robot>
"""


def test_urdf_chain_fixed_joints_and_lumped_masses(tmp_path: Path) -> None:
    arm = load_urdf(write(tmp_path, URDF, "two.urdf"))
    assert arm.joint_names == ("j1", "j2") and arm.name == "two_link"
    assert arm.upper[0] == pytest.approx(math.degrees(1.0)) and arm.upper[1] == 180.0
    assert arm.max_speed[0] == pytest.approx(math.degrees(2.0)) and arm.max_effort[0] == 30.0
    assert arm.fk((0.0, 0.0))[:3, 3] == pytest.approx((700.0, 0.0, 500.0))
    assert arm.fk((90.0, 0.0))[:3, 3] == pytest.approx((0.0, 700.0, 500.0), abs=1e-9)
    # link_1 (2 kg at 0.1 m) and the motor (2 kg at 0.2 m) ride together: 4 kg at 0.15 m
    link1 = arm.joints[0].inertial
    assert link1 is not None and link1.mass == 4.0 and link1.com == pytest.approx((150.0, 0.0, 0.0))
    assert link1.inertia is not None
    assert link1.inertia[2, 2] == pytest.approx(0.2 + 2 * 2 * 0.05**2)
    assert arm.base_inertial is not None and arm.base_inertial.mass == 5.0


def test_urdf_errors_are_clear(tmp_path: Path) -> None:
    with pytest.raises(ArmFileError, match="not a usable URDF"):
        load_urdf(write(tmp_path, "<robot", "bad.urdf"))
    with pytest.raises(ArmFileError, match="no link 'nope'"):
        load_urdf(write(tmp_path, URDF, "two.urdf"), tip="nope")


@pytest.mark.parametrize("name", ["kr210_r2700_2", "kuka_youbot_arm", "adept_cobra600"])
def test_to_urdf_round_trip_keeps_kinematics_inertials_and_closed_form(
    tmp_path: Path, name: str
) -> None:
    arm = load_arm(name)
    back = load_urdf(write(tmp_path, to_urdf(arm), f"{name}.urdf"))
    q = np.random.default_rng(4).uniform(arm.lower, arm.upper, size=(30, arm.dof))
    assert np.max(np.abs(back.fk(q) - arm.fk(q))) < 1e-9
    assert np.allclose(back.lower, arm.lower) and np.allclose(back.upper, arm.upper)
    assert (back.kuka is None) == (arm.kuka is None)
    for a, b in zip(arm.joints, back.joints, strict=True):
        assert (a.inertial is None) == (b.inertial is None)
        if a.inertial is not None and b.inertial is not None:
            assert b.inertial.mass == pytest.approx(a.inertial.mass)
            assert np.allclose(b.inertial.com, a.inertial.com, atol=1e-9)


def test_mujoco_loads_the_urdf_of_an_arm_with_inertials() -> None:
    mujoco = pytest.importorskip("mujoco")
    arm = load_arm("kr210_r2700_2")
    model = mujoco.MjModel.from_xml_string(to_urdf(arm))
    assert model.njnt == 6
    # the fixed base merges into MuJoCo's world body; the six moving bodies keep their masses
    masses = [j.inertial.mass for j in arm.joints if j.inertial is not None]
    assert model.body_mass[1:] == pytest.approx(masses, rel=1e-12)


def test_the_catalogue_needs_numpy_only() -> None:
    import subprocess
    import sys

    code = (
        "import sys, pyopenshowvar.arms as a\n"
        "arm = a.load_arm('kr210_r2700_2'); arm.ik(arm.fk(arm.home_q))\n"
        "third = {m.split('.')[0] for m in sys.modules} - set(sys.stdlib_module_names)\n"
        "print(sorted(m for m in third if not m.startswith('_') and m not in ('numpy', 'pyopenshowvar', 'cython_runtime', 'cmeel_pth')))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    assert out.stdout.strip() == "[]", out.stdout
