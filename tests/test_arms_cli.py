"""``kvp arms list`` / ``kvp arms show``: the catalogue, a file, JSON, and errors (exit 2)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pyopenshowvar_apps.cli import EXIT_USAGE, app
from typer.testing import CliRunner

from pyopenshowvar.arms import catalogue

runner = CliRunner()


def run(*args: str) -> Any:
    return runner.invoke(app, list(args))


def test_list_shows_every_entry_with_axes_ik_and_source() -> None:
    res = run("arms", "list")
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert lines[0].split() == ["NAME", "AXES", "FAMILY", "IK", "SOURCE"]
    rows = {line.split()[0]: line for line in lines[1:]}
    assert set(rows) == set(catalogue())
    assert " 7 " in rows["lbr_iiwa14_r820"] and "numeric" in rows["lbr_iiwa14_r820"]
    assert (
        "closed form" in rows["kr560_r3100_2"]
        and "kroshu/kuka_robot_descriptions" in rows["kr560_r3100_2"]
    )
    assert " 3 " in rows["knuckle_boom_crane"]


def test_list_json() -> None:
    res = run("arms", "list", "--json")
    assert res.exit_code == 0
    data = {row["name"]: row for row in json.loads(res.output)}
    assert data["kuka_youbot_arm"]["dof"] == 5
    assert data["kr210_r2700_2"]["licence"].startswith("Apache-2.0")


def test_show_a_catalogue_arm() -> None:
    res = run("arms", "show", "kr16_r2010_2")
    assert res.exit_code == 0, res.output
    out = res.output
    assert "KUKA KR 16 R2010-2" in out and "closed form" in out
    assert "flange@home  X Y Z A B C = 1173 0 1650 0 90 0" in out
    a2 = next(line for line in out.splitlines() if line.startswith("A2 "))
    assert a2.split()[2:4] == ["-185", "65"]  # limits in degrees
    assert "commit       04e1135b6434a830618f6ef59b0d3625da2cee5b" in out


def test_show_json_and_a_file(tmp_path: Path) -> None:
    res = run("arms", "show", "knuckle_boom_crane", "--json")
    data = json.loads(res.output)
    assert data["dof"] == 3 and data["closed_form_ik"] is False
    assert [j["name"] for j in data["joints"]] == ["slew", "boom", "jib"]
    p = tmp_path / "arm.toml"
    p.write_text(
        'name = "one"\nconvention = "standard"\n[[joint]]\na = 100.0\nlower = -90\nupper = 90\n'
    )
    res = run("arms", "show", str(p))
    assert res.exit_code == 0 and "one" in res.output and "J1" in res.output


def test_unknown_arm_and_bad_file_exit_2(tmp_path: Path) -> None:
    res = run("arms", "show", "kr99")
    assert res.exit_code == EXIT_USAGE
    assert "no arm 'kr99'" in res.output
    p = tmp_path / "bad.toml"
    p.write_text('name = "x"\nconvention = "standard"\n[[joint]]\nlenght = 1\n')
    res = run("arms", "show", str(p))
    assert res.exit_code == EXIT_USAGE
    assert "unknown key 'lenght'" in res.output
