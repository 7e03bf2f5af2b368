"""The wheel installs only our own top-level names (no generic ``apps`` package)."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
OURS = {"pyopenshowvar", "kukavarproxy_emu", "pyopenshowvar_apps"}


@pytest.mark.timeout(180)
def test_fresh_wheel_install_exposes_only_our_top_level_names(tmp_path: Path) -> None:
    wheels = tmp_path / "wheels"
    target = tmp_path / "site"
    # --no-build-isolation: hatchling comes with the test extras, so no download is needed.
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            str(wheels),
            str(ROOT),
        ],
        check=True,
    )
    (wheel,) = wheels.glob("pyopenshowvar-*.whl")
    # A client-only install pulls numpy and nothing else; the rest comes with extras.
    with zipfile.ZipFile(wheel) as archive:
        (metadata,) = (n for n in archive.namelist() if n.endswith(".dist-info/METADATA"))
        requires = [
            line.removeprefix("Requires-Dist: ")
            for line in archive.read(metadata).decode().splitlines()
            if line.startswith("Requires-Dist: ")
        ]
    assert [r for r in requires if "extra ==" not in r] == ["numpy>=1.24"]
    assert {"emulator", "apps", "gateway", "all", "test"} <= {
        r.rpartition("extra == ")[2].strip("'\"") for r in requires if "extra ==" in r
    }
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "-q",
            "--no-deps",
            "--target",
            str(target),
            str(wheel),
        ],
        check=True,
    )
    top = {p.name for p in target.iterdir() if not p.name.endswith(".dist-info")}
    top.discard("bin")  # console scripts
    assert top == OURS
    # The console script points at the installed name, and the package imports from there.
    out = subprocess.run(
        [sys.executable, "-c", "import pyopenshowvar_apps.cli as c; print(c.__file__)"],
        check=True,
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={"PYTHONPATH": str(target), "PATH": "/usr/bin:/bin"},
    ).stdout
    assert out.strip().startswith(str(target))
