"""The crane-head simulation: the PID/motor law, compensation on vs off on a calm and a rough
sea, the workspace limit, and ``kvp crane-head`` whose figures are recomputed from its CSV."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from pyopenshowvar_apps.cli import app
from pyopenshowvar_apps.maritime.cranehead import CraneHeadConfig, _pid_motor, simulate
from typer.testing import CliRunner

runner = CliRunner()
SHORT = CraneHeadConfig(duration=60.0, warmup=10.0)


def test_pid_and_motors_follow_eqs_57_58_sample_by_sample() -> None:
    """The filtered closed loop equals the control law stepped one sample at a time: u from
    eq. 57 with α̇ of eq. 58 at the same instant, the motor integrated exactly over dt."""
    cfg = CraneHeadConfig(dt=0.01)
    rng = np.random.default_rng(1)
    n = 3000
    t = np.arange(n) * cfg.dt
    ref = (
        0.3
        + 0.2 * np.sin(0.7 * t)[:, None] * rng.uniform(0.5, 1.5, 3)
        + 0.01 * rng.normal(size=(n, 3))
    )
    dref = 0.14 * np.cos(0.7 * t)[:, None] * np.ones(3)
    alpha_d = np.array([0.3, 0.25, 0.35])
    alpha, u = _pid_motor(cfg, ref, dref, alpha_d)
    # the loop, typed in: K_d multiplies α̇_ref − α̇ with α̇ = (K u − α)/T
    kp, ki, kd, k, tm, dt = cfg.kp, cfg.ki, cfg.kd, cfg.k_dc, cfg.t_dc, cfg.dt
    a = math.exp(-dt / tm)
    x, integ = alpha_d.copy(), alpha_d / (k * ki)
    xs, us, laws = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    for i in range(n):
        e = ref[i] - x
        ui = (kp * e + ki * integ + kd * (dref[i] + x / tm)) / (1.0 + kd * k / tm)
        rate = (k * ui - x) / tm
        xs[i], us[i], laws[i] = x, ui, kp * e + ki * integ + kd * (dref[i] - rate)
        integ = integ + e * dt
        x = a * x + (1 - a) * k * ui
    assert np.abs(laws - us).max() < 1e-12  # u is eq. 57 with α̇ of eq. 58
    assert np.abs(alpha - xs).max() < 1e-9
    assert np.abs(u - us).max() < 1e-9


@pytest.mark.parametrize("hs", [0.5, 3.0])
def test_compensation_on_and_off_on_a_calm_and_a_rough_sea(hs: float) -> None:
    on = simulate(replace(SHORT, hs=hs))
    off = simulate(replace(SHORT, hs=hs, compensate=False))
    ideal = simulate(replace(SHORT, hs=hs, imu_scale=0.0))
    # the head held still: its error is the uncompensated one
    assert off.metrics["e_c_rms_mm"] == pytest.approx(off.metrics["e_s_rms_mm"])
    assert on.metrics["e_s_rms_mm"] == pytest.approx(off.metrics["e_s_rms_mm"])
    # with a perfect sensor compensation always helps
    assert ideal.metrics["e_c_rms_mm"] < 0.05 * ideal.metrics["e_s_rms_mm"]
    if hs >= 3.0:  # rough: the head takes out > 90 % of the motion despite the sensor errors
        assert on.metrics["ratio_rms_pct"] < 10.0
        assert on.metrics["saturated_pct"] == 0.0
    else:  # calm: the motion is smaller than the sensor's errors, compensating adds them
        assert on.metrics["e_c_rms_mm"] > on.metrics["e_s_rms_mm"]
        assert on.metrics["e_c_rms_mm"] < 100.0


def test_a_high_sea_drives_the_head_out_of_its_workspace() -> None:
    run = simulate(replace(SHORT, hs=6.0, duration=300.0))
    assert run.metrics["saturated_pct"] > 0.0
    # the commanded point is always reachable (saturated), the joint range is kept
    assert (
        -40.0 - 1e-6 <= run.metrics["alpha_min_deg"] and run.metrics["alpha_max_deg"] <= 70.0 + 0.5
    )


def _csv(path: Path) -> dict[str, np.ndarray]:
    with path.open() as fh:
        rows = list(csv.reader(fh))
    data = np.array(rows[1:], dtype=float)
    return {name: data[:, i] for i, name in enumerate(rows[0])}


def test_kvp_crane_head_at_hs_3_meets_the_target_and_its_csv_gives_its_figures(
    tmp_path: Path,
) -> None:
    res = runner.invoke(
        app, ["crane-head", "--hs", "3.0", "--json", "--no-plots", "--out", str(tmp_path)]
    )
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert doc["sea_state"] == 5
    # the head takes out > 90 % of the motion; whether the 5 % target is met depends on the
    # draw of sea and sensor errors (docs/maritime.md gives five seeds), the flag says which
    assert doc["ratio_rms_pct"] < 10.0
    assert doc["target_met"] is (doc["ratio_rms_pct"] <= 5.0)
    c = _csv(tmp_path / "crane_head.csv")
    p_c = np.stack([c[f"p_c_n_{a}"] for a in "xyz"], axis=1)
    p_s = np.stack([c[f"p_s_n_{a}"] for a in "xyz"], axis=1)
    p_d = np.stack([c[f"p_d_n_{a}"] for a in "xyz"], axis=1)
    e_c = np.linalg.norm(p_d - p_c, axis=1)
    e_s = np.linalg.norm(p_d - p_s, axis=1)
    assert e_c == pytest.approx(c["e_c"], abs=1e-9)
    assert 1000 * math.sqrt(np.mean(e_c**2)) == pytest.approx(doc["e_c_rms_mm"], rel=1e-9)
    assert 1000 * e_c.max() == pytest.approx(doc["e_c_max_mm"], rel=1e-9)
    assert 1000 * math.sqrt(np.mean(e_s**2)) == pytest.approx(doc["e_s_rms_mm"], rel=1e-9)
    assert len(e_c) == int(300 / 0.02) + 1
    # the head's TCP is p_d in the body frame moved by the true motion: the still head's
    # error is the vessel's own displacement of that point (independent of the controller)
    assert np.ptp(c["p_d_n_z"]) == 0.0


def test_kvp_crane_head_sweep_finds_the_workspace_limit(tmp_path: Path) -> None:
    res = runner.invoke(app, ["crane-head", "--sweep", "--range", "2:6:2", "--duration", "300", "--json", "--out",
                              str(tmp_path)])  # fmt: skip
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert [r["hs_m"] for r in doc["sweep"]] == [2.0, 4.0, 6.0]
    assert doc["workspace_limit_hs_m"] in (4.0, 6.0)
    assert doc["sweep"][0]["saturated_pct"] == 0.0
    assert (tmp_path / "crane_head_sweep.png").stat().st_size > 10_000
    with (tmp_path / "crane_head_sweep.csv").open() as fh:
        assert len(list(csv.DictReader(fh))) == 3


def test_kvp_crane_head_refuses_bad_input(tmp_path: Path) -> None:
    for args in (["--hs", "-1"], ["--spectrum", "foo"], ["--sweep", "--range", "3:1:1"]):
        res = runner.invoke(app, ["crane-head", *args, "--out", str(tmp_path)])
        assert res.exit_code == 2, (args, res.output)
