"""``kvp universal``, ``kvp universal-sim`` and ``kvp arms bench`` from the command line."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import pytest
from pyopenshowvar_apps.cli import EXIT_USAGE, app
from typer.testing import CliRunner

runner = CliRunner()


def run(*args: str) -> Any:
    return runner.invoke(app, list(args))


def test_universal_runs_a_script_on_a_simulated_arm() -> None:
    res = run("universal", "--arm", "adept_cobra600", "--input", "script", "--duration", "1.5",
              "--solver", "closed-form", "--mode", "velocity")  # fmt: skip
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert lines[0] == ("universal: simulated adept_cobra600 (kinematic), solver closed-form, "
                        "velocity mode, input script")  # fmt: skip
    assert any(
        line.startswith(tuple("0123456789")) and "cycles, loop rate" in line for line in lines
    )
    assert any(line.startswith("solver closed-form: p50") for line in lines)


def test_universal_over_the_protobuf_link_with_the_stand_in() -> None:
    res = run("universal", "--arm", "knuckle_boom_crane", "--sim", "osc", "--input", "script",
              "--script", "hold", "--duration", "1", "--solver", "dls")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "waiting for a simulator on 127.0.0.1:" in res.output
    assert "external simulator over protobuf (knuckle_boom_crane)" in res.output


def test_universal_over_kvp_with_the_embedded_emulator() -> None:
    res = run("--emulate", "universal", "--arm", "kr6_r900_sixx", "--input", "script",
              "--script", "hold", "--duration", "1", "--solver", "closed-form", "--mode", "position")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert res.output.splitlines()[0].startswith("universal: KUKA over KVP 127.0.0.1:")


@pytest.mark.parametrize(
    ("args", "error"),
    [
        (["--input", "mouse"], "--input must be one of"),
        (["--mode", "torque"], "--mode must be position or velocity"),
        (["--solver", "newton"], "--solver must be one of"),
        (["--arm", "nosuch_arm"], "no arm 'nosuch_arm'"),
        (
            ["--arm", "kuka_youbot_arm", "--solver", "closed-form", "--duration", "0.1"],
            "no closed form",
        ),
        (["--arm", "kuka_youbot_arm", "--kvp", "127.0.0.1:7000"], "only KUKA six-axis arms"),
        (["--kvp", "nowhere"], "--kvp must be HOST:PORT"),
        (["--sim", "unity"], "--sim must be"),
        (["--input", "leap", "--leap", "/no/such.csv", "--duration", "0.1"], "--leap /no/such.csv"),
    ],
)
def test_universal_usage_errors_are_one_line(args: list[str], error: str) -> None:
    res = run("universal", *args)
    assert res.exit_code == EXIT_USAGE, res.output
    assert error in res.output and res.output.count("\n") <= 2


def test_a_missing_gamepad_is_a_clear_error() -> None:
    res = run("universal", "--input", "gamepad", "--duration", "0.1")
    # pygame missing (no gamepad extra) or no pad plugged in: one line, exit 2, never a hang
    assert res.exit_code == EXIT_USAGE, res.output
    assert ("pip install 'pyopenshowvar[gamepad]'" in res.output
            or "no gamepad connected" in res.output)  # fmt: skip


def test_arms_bench_json_dump_and_plot(tmp_path: Path) -> None:
    dump, plot = tmp_path / "d.csv", tmp_path / "p.png"
    res = run("arms", "bench", "adept_cobra600", "--solver", "closed-form", "--targets", "27",
              "--json", "--dump", str(dump), "--plot", str(plot))  # fmt: skip
    assert res.exit_code == 0, res.output
    s = json.loads(res.output)
    assert s["arm"] == "adept_cobra600" and s["solver"] == "closed-form" and s["targets"] == 27
    assert 0 < s["reachable"] < 27
    assert set(s["error_mm"]) == {"p50", "p95", "max"} and set(s["time_ms"]) == {"p50", "p99"}
    assert s["error_mm"]["max"] < 1e-6  # the closed form is exact on every reachable target
    rows = list(csv.DictReader(dump.open()))
    assert len(rows) == 27 and {"x_mm", "reachable", "q_J1", "solver_error_mm"} <= set(rows[0])
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_arms_bench_summary_and_errors() -> None:
    res = run("arms", "bench", "knuckle_boom_crane", "--solver", "dls", "--targets", "8",
              "--clock", "cpu")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "reachable" in res.output and "time per target" in res.output
    for args, error in (
        (["--targets", "100"], "a cube"),
        (["--solver", "sa"], "--solver must be one of"),
        (["--clock", "gpu"], "--clock must be"),
    ):
        res = run("arms", "bench", "knuckle_boom_crane", *args)
        assert res.exit_code == EXIT_USAGE and error in res.output, res.output
    res = run("arms", "bench", "lbr_iiwa14_r820", "--solver", "closed-form", "--targets", "8")
    assert res.exit_code == EXIT_USAGE and "no closed form" in res.output
