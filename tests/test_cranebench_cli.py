"""``kvp crane-bench`` end to end on a tiny profile: its JSON keys, and its figures recomputed
from the CSVs it writes; a broken profile is one clear error."""

from __future__ import annotations

import csv
import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from pyopenshowvar_apps.cli import app
from pyopenshowvar_apps.cranebench.profiles import builtin_profile
from typer.testing import CliRunner

runner = CliRunner()


def _csv(path: Path) -> dict[str, np.ndarray]:
    with path.open() as fh:
        rows = list(csv.reader(fh))
    data = np.array(rows[1:], dtype=float)
    return {name: data[:, i] for i, name in enumerate(rows[0])}


def _tiny(tmp_path: Path) -> Path:
    """The thesis' profile cut to a 4° slew with short holds (about 4 s of crane time)."""
    text = builtin_profile().read_text()
    text = text.replace("hold_s = 2.0", "hold_s = 0.5")
    text = text.replace(
        'operations = ["raise boom", "slew", "lower boom"]', 'operations = ["slew"]'
    )
    text = text.replace("move_deg = 90.0", "move_deg = 4.0")
    assert tomllib.loads(text)["hold_s"] == 0.5
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    return path


def test_kvp_crane_bench_json_keys_and_figures_from_its_csv(tmp_path: Path) -> None:
    """About 3 s on an idle machine, most of it the first import of the sea spectrum's
    library (scipy) and MuJoCo; the crane flies 2.25 s (plus 3 s settling) three times."""
    out = tmp_path / "out"
    res = runner.invoke(app, ["crane-bench", "--profile", str(_tiny(tmp_path)), "--solvers", "dls",
                              "--json", "--no-plots", "--out", str(out), "--seed", "3"])  # fmt: skip
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    m = doc["solvers"]["dls"]
    assert set(m["position_error_mm"]) == {"rms", "max"}
    assert set(m["joint_effort"]) == {"slew", "boom", "jib", "total"}
    assert set(m["heave"]) >= {"uncompensated_rms_mm", "compensated_rms_mm"}
    assert doc["coverage"] == 1.0 and len(doc["runs"]) == 1
    c = _csv(out / "crane_bench_dls.csv")
    xt = np.stack([c[f"x_t_{a}"] for a in "xyz"], 1)
    xc = np.stack([c[f"x_c_{a}"] for a in "xyz"], 1)
    a = np.linalg.norm(xt - xc, axis=1)
    assert math.sqrt(np.mean(a**2)) == pytest.approx(m["position_error_mm"]["rms"], rel=1e-9)
    assert a.max() == pytest.approx(m["position_error_mm"]["max"], rel=1e-9)
    # eq. 5.4 against the joint target of the sample the solver was given (every 5th: 0.1 s)
    held = (np.arange(len(c["t"])) // 5) * 5
    theta_t = np.stack([c[f"theta_t_{j}"] for j in ("slew", "boom", "jib")], 1)[held]
    theta_c = np.stack([c[f"theta_c_{j}"] for j in ("slew", "boom", "jib")], 1)
    b = np.linalg.norm(theta_t - theta_c, axis=1)
    assert b.max() == pytest.approx(m["joint_error_deg"]["max"], rel=1e-9)
    assert math.sqrt(np.mean(b**2)) == pytest.approx(m["joint_error_deg"]["rms"], rel=1e-9)
    for j in ("slew", "boom", "jib"):
        effort = np.trapezoid(0.5 * c[f"tau_{j}"] ** 2, c["t"])
        assert effort == pytest.approx(m["joint_effort"][j], rel=1e-9)
    h = _csv(out / "crane_bench_dls_heave.csv")
    target = np.stack([h[f"target_n_{a}"] for a in "xyz"], 1)
    for key, col in (("uncompensated_rms_mm", "off_n"), ("compensated_rms_mm", "on_n")):
        e = np.linalg.norm(target - np.stack([h[f"{col}_{a}"] for a in "xyz"], 1), axis=1)
        assert math.sqrt(np.mean(e**2)) == pytest.approx(m["heave"][key], rel=1e-9)
    # the slew really happened on the plant
    assert c["theta_a_slew"][-1] == pytest.approx(4.0, abs=0.5)
    assert not list(out.glob("*.png"))


def test_the_figures_of_a_solver_are_drawn(tmp_path: Path) -> None:
    """The four figures (Figs. 5.5/5.7/5.9/5.11 alike) from a hand-made 5-sample trace; about
    2 s on an idle machine: matplotlib's import and four small PNGs, drawn in this test only."""
    from pyopenshowvar_apps.cranebench.bench import Trace
    from pyopenshowvar_apps.cranebench.report import _figures

    n = 5
    t = np.arange(n) * 0.02
    xyz = np.tile([9000.0, 0.0, 4400.0], (n, 1))
    q = np.tile([0.0, 30.0, -60.0], (n, 1))
    trace = Trace(t, xyz, xyz, xyz, xyz, q, q, q, np.ones((n, 3)), np.zeros((n, 3)),
                  np.ones((n, 2)), np.full(n, 1.0), xyz, xyz)  # fmt: skip
    files = _figures("pso", {"calm": trace, "off": trace, "on": trace}, tmp_path)
    assert [f.name for f in files] == ["fig5_5_tracking_pso.png", "fig5_7_error_pso.png",
                                       "fig5_9_torque_pso.png", "fig5_11_heave_pso.png"]  # fmt: skip
    assert all(f.stat().st_size > 1000 for f in files)


def test_kvp_crane_bench_names_the_bad_key_of_a_profile(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(builtin_profile().read_text().replace("payload_kg", "payload_kgs"))
    res = runner.invoke(app, ["crane-bench", "--profile", str(bad), "--out", str(tmp_path)])
    assert res.exit_code == 2
    assert "unknown key 'payload_kgs' (did you mean 'payload_kg'?)" in res.output
    res = runner.invoke(app, ["crane-bench", "--solvers", "ga,simplex", "--out", str(tmp_path)])
    assert res.exit_code != 0 and "simplex" in res.output
