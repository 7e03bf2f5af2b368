"""``kvp demo``: every case study on an embedded emulator, one table that fits 80 columns."""

from __future__ import annotations

import math
from typing import Any

import pytest
from pyopenshowvar_apps.casestudies import teleop_cli
from pyopenshowvar_apps.casestudies.common import CaseResult, summary_table, verdict
from pyopenshowvar_apps.cli import app
from pyopenshowvar_apps.common import Opts
from rich.console import Console
from typer.testing import CliRunner


def test_verdicts_say_worse_and_never_leave_an_off_row_blank() -> None:
    assert verdict(0.5, "< 5") == "better" and verdict(7.0, "< 5") == "worse"
    assert verdict(30.0, "> 20") == "better" and verdict(3.0, "> 20") == "worse"
    assert verdict(4.0, "≈ 4.27") == "similar"  # within 25 %
    assert verdict(15.0, "≈ 4.27", lower_is_better=True) == "worse"
    assert verdict(2.0, "≈ 4.27", lower_is_better=True) == "better"
    assert verdict(15.0, "≈ 4.27") == "differs"  # off, and no direction to call it by
    assert verdict(1.0, "plots only") == "" and verdict(math.nan, "< 5") == ""


def test_summary_table_fits_80_columns_without_cutting() -> None:
    results = [
        CaseResult("teleop", {"access_mean_ms": 15.04, "force_err_settled_max_N": math.nan}),
        CaseResult("haptic", {"a_rather_long_metric_name_that_wraps_mm": 0.123456}),
    ]
    results[0].thesis["access_mean_ms"] = "≈ 4.27"
    console = Console(width=80, record=True, color_system=None)
    console.print(summary_table(results))
    text = console.export_text()
    assert max(len(line) for line in text.splitlines()) <= 80
    assert "…" not in text and "nan" not in text and "n/a" in text
    assert "worse" in text  # 15 ms against 4.27 ms: off by more than the tolerance


def test_demo_quick_linefollow_prints_table(tmp_path) -> None:
    res = CliRunner().invoke(
        app, ["demo", "--quick", "--only", "linefollow", "--out", str(tmp_path), "--seed", "3"]
    )
    assert res.exit_code == 0, res.output
    out = res.output
    assert "dynamic plant" in out and "'kvp' latency" in out and "seed 3" in out
    # by default the physical robot is not the nominal model: a calibration error, seeded
    assert "calibration error seed 3" in out
    assert "NOT" in out and "representative" in out  # --quick says so
    assert "ours vs thesis" in out and "max_error_mm" in out and "< 5" in out
    assert "better" in out and "nan" not in out
    table = [line for line in out.splitlines() if line[:1] in "┏┃┡│└"]
    assert table and max(len(line) for line in table) <= 80
    lines = out.strip().splitlines()
    header = max(i for i, line in enumerate(lines) if line.startswith("files written under"))
    listed = [line.strip() for line in lines[header + 1 :]]
    assert "linefollow/linefollow_path.png" in listed, listed
    assert "linefollow/linefollow_detection.png" in listed
    for name in listed:  # the last lines are the files written, all there, no nested folders
        assert (tmp_path / name).stat().st_size > 0
        assert name.count("linefollow") == 2  # linefollow/linefollow_*.*, not deeper


@pytest.mark.parametrize(
    "args",
    [
        ["demo", "--calibration-error", "x"],
        ["demo", "--calibration-error", "-1"],
        ["linefollow", "--calibration-error", "x"],
        ["teleop", "--calibration-error", "1.5"],
        ["haptic", "--calibration-error", "nope"],
    ],
)
def test_calibration_error_option_is_validated(args: list[str]) -> None:
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2 and "is not a seed" in res.output, res.output


def test_case_study_commands_build_the_robot_they_were_asked_for() -> None:
    """``kvp haptic --emulate --calibration-error 7``: the embedded robot is the one seed 7
    draws (not the nominal one); ``off`` and no option: the nominal robot."""
    seen: list[Any] = []

    async def probe(kvp: Any, emu: Any) -> CaseResult:
        await kvp.read("$PRO_NAME1[]")
        seen.append(emu.emulator.robot.plant.calibration_seed)
        return CaseResult("probe")

    Opts.reset("127.0.0.1", 7000, 1.0, emulate=True)
    try:
        for option in ("7", "off", None):
            teleop_cli._run("actuator", False, probe, calibration=option)
    finally:
        Opts.reset("127.0.0.1", 7000, 2.0, emulate=False)
    assert seen == [7, None, None]


def test_seed_also_draws_the_heave_sea(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    """``kvp demo --seed 5``: the heave section's sea (and its rig's noise) is drawn with 5
    too, not a fixed 19 (the section itself runs 15 s of real time: only its inputs here)."""
    import pyopenshowvar_apps.heave.demo as heave_demo
    from pyopenshowvar_apps.demo import Conditions, _heave

    asked: list[int] = []

    def record(out: Any, speed: float, quick: bool, *, plant: str, seed: int) -> CaseResult:
        asked.append(seed)
        return CaseResult("heave")

    monkeypatch.setattr(heave_demo, "demo_case", record)
    _heave(tmp_path, Conditions("dynamic", 5, 1.0, True))
    assert asked == [5]
