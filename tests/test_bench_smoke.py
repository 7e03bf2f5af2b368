"""Smoke test of the benchmark scripts: each runs with ``--quick`` and prints its figures.

Benchmarks never fail CI on a slow machine: nothing here checks a number, only that every
script runs to the end and prints its table (peers that are not installed are skipped by the
scripts themselves).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"


# a hang guard, not a speed check: a --quick run takes a few seconds of CPU, and a loaded
# 2-core machine (the suite's own workers beside it) may stretch that several times
@pytest.mark.timeout(150)
@pytest.mark.parametrize(
    ("script", "expect"),
    [
        ("client_roundtrip.py", "serial read round trip"),
        ("codec.py", "E6POS"),
        ("emu_throughput.py", "requests/s, 10 clients"),
        ("kinematics.py", "Jacobian"),
        ("plant_cpu.py", "dynamic plant, moving"),
        ("plant_settle.py", "poses settled within 2 s"),
        ("cli_startup.py", "kvp read start-up"),
        ("latency_pacing.py", "paced"),
        ("motion_kss.py", "A2 reversal"),
        ("web_jog.py", "jog stop latency after release"),
        ("app_abuse.py", "rogue page: A1 travel after the page closed"),
        ("c3.py", "upload-to-motion"),
        ("snapshot.py", "20 variables: `read_snapshot`"),
        ("snapshot_cpu.py", "CPU at rest, README's snapshot"),
        ("cell_cpu.py", "CPU per robot, 2 robots, moving"),
        ("sync_read_cost.py", "critical path"),
        ("ik.py", "solved, numeric batched"),
    ],
)
def test_benchmark_runs_quick(script: str, expect: str) -> None:
    proc = subprocess.run(
        [sys.executable, str(BENCH / script), "--quick"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert expect in proc.stdout
    assert "ours" in proc.stdout
