"""``kvp demo --quick``: every case study on an embedded emulator, one table."""

from __future__ import annotations

import time

from pyopenshowvar_apps.cli import app
from typer.testing import CliRunner


def test_demo_quick_linefollow_prints_table(tmp_path) -> None:
    t0 = time.monotonic()
    res = CliRunner().invoke(
        app, ["demo", "--quick", "--only", "linefollow", "--out", str(tmp_path)]
    )
    assert res.exit_code == 0, res.output
    assert time.monotonic() - t0 < 60
    assert "ours vs thesis" in res.output
    assert "max_error_mm" in res.output and "< 5" in res.output
    assert "better" in res.output
    assert (tmp_path / "linefollow" / "linefollow_path.png").stat().st_size > 0
