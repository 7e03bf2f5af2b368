"""Robot model: built-in KR 6 values, the shipped TOML file, TOML/JSON round trips, limits."""

from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

from pyopenshowvar.kinematics import KR6R900SIXX, RobotModel, forward, inverse

M = KR6R900SIXX
SHIPPED = Path(str(files("pyopenshowvar.kinematics").joinpath("kr6r900sixx.toml")))


def test_shipped_toml_round_trips_to_builtin() -> None:
    loaded = RobotModel.from_file(SHIPPED)
    assert loaded == M
    assert hash(loaded) == hash(M)
    assert np.array_equal(forward(loaded, M.home), forward(M, M.home))


def test_reference_values() -> None:
    assert list(M.sign) == [-1, 1, 1, -1, 1, -1]
    assert list(M.offset) == [0, 0, -90, 0, 0, 180]
    assert list(M.lower) == [-170, -190, -120, -185, -120, -350]
    assert list(M.upper) == [170, 45, 156, 185, 120, 350]
    assert list(M.max_speed) == [360, 300, 360, 381, 388, 615]
    assert M.lower.shape == (6,)
    assert M.link_mass.sum() == pytest.approx(38.244)
    with pytest.raises(ValueError):
        M.lower[0] = 0.0  # read-only arrays


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_round_trip_other_robot(tmp_path: Path, suffix: str) -> None:
    d = M.to_dict()
    d["name"] = "site-narrowed KR 6"
    d["axis"][0]["lower"], d["axis"][0]["upper"] = -155.0, 168.0  # [KCT] site limits
    d["flange"] = [0.0, 0.0, 10.0, 0.0, 0.0, 0.0]  # an adapter plate
    d["torque_sign"] = -1.0
    other = RobotModel.from_dict(d)
    path = tmp_path / f"robot{suffix}"
    path.write_text(other.to_toml() if suffix == ".toml" else other.to_json())
    back = RobotModel.from_file(path)
    assert back == other and back != M
    assert back.lower[0] == -155.0
    # the flange plate moves the flange 10 mm along its z (forward at HOME)
    assert forward(back, M.home)[0] == pytest.approx(535.0)
    q = np.array([10.0, -80.0, 100.0, 20.0, 30.0, 40.0])
    assert np.allclose(inverse(back, forward(back, q), s=2, t=2), q)


def test_minimal_file_defaults(tmp_path: Path) -> None:
    axes = [
        {
            "a": r[0],
            "alpha": r[1],
            "d": r[2],
            "theta": r[3],
            "sign": int(r[4]),
            "lower": -100,
            "upper": 100,
            "max_speed": 100,
            "max_accel": 500,
        }
        for r in M.dh
    ]
    path = tmp_path / "bare.json"
    path.write_text(json.dumps({"axis": axes}))
    bare = RobotModel.from_file(path)
    assert (
        bare.name == "robot" and np.all(bare.link_mass == 0) and np.all(np.isinf(bare.max_torque))
    )
    assert np.allclose(forward(bare, (0, -90, 90, 0, 0, 0)), (525, 0, 890, 0, 90, 0))


def test_bad_files_raise_value_error(tmp_path: Path) -> None:
    p = tmp_path / "bad.toml"
    p.write_text("name = \n")
    with pytest.raises(ValueError, match="not a valid model file"):
        RobotModel.from_file(p)
    d = M.to_dict()
    d["axis"] = d["axis"][:5]
    with pytest.raises(ValueError, match="6"):
        RobotModel.from_dict(d)
    d = M.to_dict()
    d["axis"][2]["sign"] = 2
    with pytest.raises(ValueError, match="sign"):
        RobotModel.from_dict(d)
    d = M.to_dict()
    del d["axis"][1]["upper"]
    with pytest.raises(ValueError, match="upper"):
        RobotModel.from_dict(d)


def test_limits() -> None:
    assert M.within_limits(M.home)
    assert not M.within_limits((0, -195, 90, 0, 0, 0))
    assert M.limit_violations((0, -195, 90, 0, 130, 0)) == ["A2 -195 < -190", "A5 130 > 120"]
    assert M.limit_violations(M.home) == []
    mask = M.limit_mask(np.array([M.home, (0, 50, 0, 0, 0, 0)]))
    assert list(mask) == [True, False]
