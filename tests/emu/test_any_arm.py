"""The emulator as any KUKA six-axis arm (``--robot``): identity, FK, limits, plant, refusals.

The flange pose is checked against forward kinematics written here from the URDF joint
origins in the catalogue files (translation, fixed RPY rotation, rotation about z per joint),
not with the toolkit's kinematics, so a wrong derived D-H table or flange would show.
"""

from __future__ import annotations

import asyncio
import math
import time
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import kukavarproxy_emu
import pyopenshowvar.arms as arms_pkg
from kukavarproxy_emu import EmulatorConfig
from kukavarproxy_emu.__main__ import main as emu_main
from kukavarproxy_emu.plant.params import load_params
from kukavarproxy_emu.robots import RobotRefused, resolve_robot
from pyopenshowvar import Client
from pyopenshowvar.arms import arm_for_model_name
from pyopenshowvar.krl import Struct

DATA = Path(arms_pkg.__file__).parent / "data"
PLANT = Path(kukavarproxy_emu.__file__).parent / "plant"


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (
        math.cos(r),
        math.sin(r),
        math.cos(p),
        math.sin(p),
        math.cos(y),
        math.sin(y),
    )
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return np.asarray(rz @ ry @ rx, dtype=np.float64)


def _origin(xyz: list[float], rpy: list[float]) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = _rpy(*rpy)
    t[:3, 3] = np.asarray(xyz) * 1000.0  # the files are in metres
    return t


def urdf_fk(key: str, q_deg: list[float]) -> np.ndarray:
    """Flange pose (mm) from the catalogue file's URDF joint origins: Π origin_i·Rz(q_i)."""
    data = tomllib.loads((DATA / f"{key}.toml").read_text())
    t = np.eye(4)
    for joint, q in zip(data["joint"], q_deg, strict=True):
        assert joint.get("axis", [0, 0, 1]) == [0, 0, 1]
        t = t @ _origin(joint.get("xyz", [0, 0, 0]), joint.get("rpy", [0, 0, 0]))
        rot = np.eye(4)
        rot[:3, :3] = _rpy(0.0, 0.0, math.radians(q))
        t = t @ rot
    flange = _origin(data["flange"].get("xyz", [0, 0, 0]), data["flange"].get("rpy", [0, 0, 0]))
    return np.asarray(t @ flange, dtype=np.float64)


def _abc(a: float, b: float, c: float) -> np.ndarray:
    """KUKA A B C (deg): R = Rz(A)·Ry(B)·Rx(C)."""
    return _rpy(math.radians(c), math.radians(b), math.radians(a))


async def _settle_on(kvp: Client, target: list[float], timeout: float = 8.0) -> Struct:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        axes = await kvp.read_value("$AXIS_ACT")
        assert isinstance(axes, Struct)
        if all(abs(float(axes[f"A{i + 1}"]) - v) < 1e-3 for i, v in enumerate(target)):  # type: ignore[arg-type]
            return axes
        await asyncio.sleep(0.01)
    raise AssertionError(f"the robot did not reach {target}")


def _axis_text(q: list[float]) -> str:
    return "{" + ", ".join(f"A{i + 1} {v}" for i, v in enumerate(q)) + "}"


@pytest.mark.parametrize(
    ("key", "target"),
    [("kr16_r2010_2", [20.0, -70.0, 100.0, 30.0, 40.0, -50.0]),
     ("kr210_r2700_2", [-15.0, -100.0, 80.0, -25.0, 35.0, 60.0])],
)  # fmt: skip
async def test_pos_act_is_the_arms_own_fk_over_kvp(
    emulator_factory: Any, key: str, target: list[float]
) -> None:
    emu = await emulator_factory(arm=key, plant="ideal", speed=50.0, program="follow")
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        model_name = await kvp.read_value("$MODEL_NAME[]")
        assert model_name == tomllib.loads((DATA / f"{key}.toml").read_text())["model_name"]
        home = await kvp.read_value("$POS_ACT")
        assert isinstance(home, Struct)
        expected_home = urdf_fk(key, [0.0, -90.0, 90.0, 0.0, 0.0, 0.0])
        got = [float(home[k]) for k in "XYZ"]  # type: ignore[arg-type]
        np.testing.assert_allclose(got, expected_home[:3, 3], atol=2e-3)
        await kvp.write("MYAXIS", _axis_text(target))
        axes = await _settle_on(kvp, target)
        pos = await kvp.read_value("$POS_ACT")
    assert isinstance(pos, Struct)
    q = [float(axes[f"A{i + 1}"]) for i in range(6)]  # type: ignore[arg-type]
    expected = urdf_fk(key, q)
    xyz = [float(pos[k]) for k in "XYZ"]  # type: ignore[arg-type]
    np.testing.assert_allclose(xyz, expected[:3, 3], atol=2e-3)  # the KRC's text precision
    rot = _abc(*(float(pos[k]) for k in "ABC"))  # type: ignore[arg-type]
    np.testing.assert_allclose(rot, expected[:3, :3], atol=1e-5)


async def test_software_limits_are_the_arms_own(emulator_factory: Any) -> None:
    """A2 = 55°: inside the KR 16's range (-185..65), beyond the KR 6's (-190..45)."""
    target = [0.0, 55.0, 20.0, 0.0, 0.0, 0.0]
    results = {}
    for key in ("kr6_r900_sixx", "kr16_r2010_2"):
        emu = await emulator_factory(arm=key, plant="ideal", speed=50.0, program="follow")
        async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
            upper = await kvp.read_value("$SOFTP_END[2]")
            await kvp.write("MYAXIS", _axis_text(target))
            if key == "kr16_r2010_2":
                await _settle_on(kvp, target)
            else:
                for _ in range(500):  # polled: the stop comes within a few IPO cycles
                    if await kvp.read_value("$STOPMESS"):
                        break
                    await asyncio.sleep(0.01)
            results[key] = (upper, await kvp.read_value("$EMU_MESSAGE[]"))
    assert results["kr6_r900_sixx"][0] == pytest.approx(45.0)
    assert "Software limit switch +A2" in str(results["kr6_r900_sixx"][1])
    assert results["kr16_r2010_2"][0] == pytest.approx(65.0)
    assert results["kr16_r2010_2"][1] == ""


async def test_dynamic_plant_of_a_kr16_holds_and_moves(emulator_factory: Any) -> None:
    """The KR 16's own plant file: gravity torques at home and a PTP without a following
    error; its masses are the documented estimate (the source has no inertials)."""
    emu = await emulator_factory(arm="kr16_r2010_2", speed=50.0, program="none")
    robot = emu.robot
    assert robot.plant is not None and robot.plant.params.name.startswith("KUKA KR 16 R2010-2")
    robot.kernel.ptp([10.0, -80.0, 100.0, 0.0, 30.0, 0.0])
    for _ in range(500):  # polled: about 2 s of simulated motion, 0.04 s at speed 50
        if not (robot.kernel.moving or robot.kernel.queued):
            break
        await asyncio.sleep(0.02)
    assert robot.message == "" and not robot.plant.braked
    torque = emu.store.get("$TORQUE_AXIS_ACT")
    assert isinstance(torque, list)
    # A2 holds the forearm out at about 1 m: tens of Nm on the estimated masses, far from 0
    # and well inside the drive's 1633.6 Nm
    assert 20.0 < abs(float(str(torque[1]))) < 1633.6


def test_plant_files_keep_the_descriptions_inertials_or_say_they_estimate() -> None:
    kr210 = load_params(PLANT / "kr210_r2700_2_dynamics.toml")
    np.testing.assert_allclose(
        kr210.bodies.mass, [363.07, 232.06, 190.33, 42.411794929, 16.991732133, 6.6]
    )
    text = (PLANT / "kr16_r2010_2_dynamics.toml").read_text()
    assert "kr210_r2700_2 scaled" in text
    kr16 = load_params(PLANT / "kr16_r2010_2_dynamics.toml")
    assert np.all(kr16.bodies.mass > 0) and np.all(kr16.bodies.inertia > 0)
    np.testing.assert_allclose(kr16.bodies.max_torque[:3], [1905.3, 1633.6259859, 850.58019869])


@pytest.mark.parametrize("name", ["knuckle_boom_crane", "adept_cobra600", "kuka_youbot_arm"])
def test_non_kuka_arms_are_refused_with_one_clear_line(name: str) -> None:
    with pytest.raises(
        RobotRefused,
        match=f"--robot {name}: .* not a KUKA six-axis arm .*kvp universal --arm {name}",
    ):
        EmulatorConfig(arm=name)


def test_iiwa_and_unknown_and_incomplete_files_are_refused(tmp_path: Path) -> None:
    with pytest.raises(RobotRefused, match="Sunrise cabinet"):
        EmulatorConfig(arm="lbr_iiwa14_r820")
    with pytest.raises(RobotRefused, match="no arm 'kr99'"):
        EmulatorConfig(arm="kr99")
    # a KUKA-layout file without speeds: the controller could not plan
    text = (DATA / "kr16_r2010_2.toml").read_text().replace("max_speed", "# max_speed")
    path = tmp_path / "slow.toml"
    path.write_text(text)
    with pytest.raises(RobotRefused, match="needs max_speed and max_accel of A1"):
        EmulatorConfig(arm=str(path))


def test_an_arm_file_gets_a_generated_plant(tmp_path: Path) -> None:
    path = tmp_path / "my_kr16.toml"
    path.write_text(
        (DATA / "kr16_r2010_2.toml").read_text().replace('model_name = "#KR16R2010-2 C4 FLR"\n', "")
    )
    spec = resolve_robot(str(path))
    assert spec.plant_file is None and spec.model_name == "#KUKAKR16R2010-2"
    params = spec.plant_params()
    assert params.bodies.mass.sum() == pytest.approx(
        load_params(PLANT / "kr16_r2010_2_dynamics.toml").bodies.mass.sum()
    )


def test_model_name_picks_the_catalogue_arm() -> None:
    assert arm_for_model_name('"#KR16R2010-2 C4 FLR"').key == "kr16_r2010_2"  # type: ignore[union-attr]
    assert arm_for_model_name("#KR6R900SIXX C4SR FLR").key == "kr6_r900_sixx"  # type: ignore[union-attr]
    assert arm_for_model_name("#KR1000 TITAN") is None
    assert arm_for_model_name("") is None


def test_cli_refuses_a_crane_with_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        emu_main(["--port", "0", "--robot", "knuckle_boom_crane"])
    assert exc.value.code == 2
    assert (
        capsys.readouterr()
        .err.strip()
        .splitlines()[-1]
        .startswith("kukavarproxy-emu: error: --robot knuckle_boom_crane: ")
    )
