"""`kvp watch`, `record`, `bench`, `discover`: output, files and exit codes against the emulator."""

from __future__ import annotations

import csv
import json
import re
import socket
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from pyopenshowvar_apps.cli import EXIT_CONNECTION, EXIT_TIMEOUT, EXIT_USAGE, EXIT_VARIABLE, app
from typer.testing import CliRunner

from kukavarproxy_emu import EmulatorThread
from kukavarproxy_emu.faults import Fault
from kukavarproxy_emu.testing import TEST_CONFIG

runner = CliRunner()


def run(*args: str) -> Any:
    return runner.invoke(app, list(args))


def closed_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# ----------------------------------------------------------------------------- watch


def test_watch_runs_a_bounded_number_of_polls(emulator_thread: Any) -> None:
    res = run(
        "--port",
        str(emulator_thread.port),
        "watch",
        "$OV_PRO",
        "$AXIS_ACT",
        "--hz",
        "50",
        "--count",
        "3",
    )
    assert res.exit_code == 0, res.output
    assert "$OV_PRO" in res.stdout and "100" in res.stdout and "poll 3" in res.stdout
    assert "E6AXIS" in res.stdout


def test_watch_duration_option(emulator_thread: Any) -> None:
    res = run(
        "--port", str(emulator_thread.port), "watch", "$OV_PRO", "--hz", "20", "--duration", "0.2"
    )
    assert res.exit_code == 0, res.output


def test_watch_unknown_variable_exits_5(emulator_thread: Any) -> None:
    res = run("--port", str(emulator_thread.port), "watch", "NOPE", "--count", "2")
    assert res.exit_code == EXIT_VARIABLE
    assert "NOPE" in res.stderr and "Traceback" not in res.output


def test_watch_connection_refused_and_bad_rate() -> None:
    port = closed_port()
    res = run("--port", str(port), "-t", "0.3", "watch", "$OV_PRO", "--count", "1")
    assert res.exit_code == EXIT_CONNECTION and f"127.0.0.1:{port}" in res.stderr
    assert run("watch", "$OV_PRO", "--hz", "0").exit_code == EXIT_USAGE


# ----------------------------------------------------------------------------- record


def test_record_writes_a_timestamped_csv(ideal_emulator_thread: Any, tmp_path: Path) -> None:
    out = tmp_path / "log.csv"
    ideal_emulator_thread.store.set_system("MYINT", 42)
    res = run(
        "--port", str(ideal_emulator_thread.port),
        "record", "$OV_PRO", "MYINT", "$AXIS_ACT", "--hz", "20", "--duration", "0.5", "--out", str(out), "--split",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    rows = list(csv.reader(out.open(encoding="utf-8")))
    header, data = rows[0], rows[1:]
    assert header[:5] == ["t", "wall", "$OV_PRO", "MYINT", "$AXIS_ACT"]
    assert "$AXIS_ACT.A2" in header
    assert 5 <= len(data) <= 13
    times = [float(r[0]) for r in data]
    assert times == sorted(times) and times[-1] < 0.7
    assert all(r[2] == "100" and r[3] == "42" for r in data)
    assert data[0][4].startswith("{E6AXIS: A1 0.0, A2 -90.0000")
    assert float(data[0][header.index("$AXIS_ACT.A2")]) == -90.0
    assert "T" in data[0][1]  # ISO 8601 wall time
    # docs/cli.md: the closing line (", K missed" only when polls were missed)
    assert re.search(r"recorded \d+ rows of 3 variables to \S+\.csv$", res.stderr.strip())


def test_record_unknown_variable_exits_5(emulator_thread: Any, tmp_path: Path) -> None:
    res = run(
        "--port",
        str(emulator_thread.port),
        "record",
        "NOPE",
        "--duration",
        "0.2",
        "--out",
        str(tmp_path / "x.csv"),
    )
    assert res.exit_code == EXIT_VARIABLE and "NOPE" in res.stderr


def test_record_timeout_with_a_stalled_emulator(emulator_thread: Any, tmp_path: Path) -> None:
    emulator_thread.faults.add(Fault("delay", seconds=1.0, count=None))
    res = run(
        "--port", str(emulator_thread.port), "--timeout", "0.2",
        "record", "$OV_PRO", "--duration", "0.2", "--out", str(tmp_path / "x.csv"),
    )  # fmt: skip
    assert res.exit_code == EXIT_TIMEOUT
    assert "$OV_PRO" in res.stderr and f"127.0.0.1:{emulator_thread.port}" in res.stderr


# ----------------------------------------------------------------------------- bench


def test_bench_prints_statistics_and_histogram(emulator_thread: Any, tmp_path: Path) -> None:
    out = tmp_path / "bench.csv"
    res = run(
        "--port",
        str(emulator_thread.port),
        "bench",
        "--reads",
        "200",
        "--writes",
        "20",
        "--csv",
        str(out),
    )
    assert res.exit_code == 0, res.output
    for word in ("count", "mean", "median", "p99", "max", "read histogram", "write histogram", "│"):
        assert word in res.stdout
    assert "200" in res.stdout
    rows = list(csv.reader(out.open(encoding="utf-8")))
    assert rows[0] == ["op", "index", "seconds"] and len(rows) == 221
    assert emulator_thread.store.read("$OV_PRO") == "100"  # writes put the value back


def test_bench_errors(emulator_thread: Any) -> None:
    port = str(emulator_thread.port)
    assert run("--port", port, "bench", "--reads", "0").exit_code == EXIT_USAGE
    res = run("--port", port, "bench", "--reads", "5", "--var", "NOPE")
    assert res.exit_code == EXIT_VARIABLE and "NOPE" in res.stderr
    res = run("--port", port, "bench", "--reads", "1", "--writes", "5", "--write-var", "$AXIS_ACT")
    assert res.exit_code == EXIT_VARIABLE and "$AXIS_ACT" in res.stderr
    emulator_thread.faults.add(Fault("delay", seconds=1.0, count=None))
    res = run("--port", port, "--timeout", "0.2", "bench", "--reads", "5")
    assert res.exit_code == EXIT_TIMEOUT and "Traceback" not in res.output


# ----------------------------------------------------------------------------- discover


@pytest.fixture
def discoverable() -> Any:
    config = replace(
        TEST_CONFIG, discovery=True, udp_port=closed_port(socket.SOCK_DGRAM), udp_reply_port=0
    )
    with EmulatorThread(config) as emu:
        yield emu


def test_discover_finds_the_emulator(discoverable: Any) -> None:
    udp = str(discoverable.config.udp_port)
    args = [
        "discover",
        "--to",
        "127.0.0.1",
        "--udp-port",
        udp,
        "--listen-port",
        "0",
        "--timeout",
        "0.5",
    ]
    res = run(*args, "--json")
    assert res.exit_code == 0, res.output
    (answer,) = json.loads(res.stdout)
    assert answer["host"] == "127.0.0.1"
    assert answer["model"] == "#KR6R900SIXX C4SR FLR" and answer["serial"] == "123456"
    res = run(*args)
    assert res.exit_code == 0 and "KR6R900SIXX" in res.stdout and "123456" in res.stdout


def test_discover_nothing_answers_exits_3() -> None:
    udp = str(closed_port(socket.SOCK_DGRAM))
    res = run(
        "discover", "--to", "127.0.0.1", "--udp-port", udp, "--listen-port", "0", "--timeout", "0.3"
    )
    assert res.exit_code == EXIT_CONNECTION and "no proxy answered" in res.stderr


# ----------------------------------------------------------------------------- misc


def test_write_refused_and_timeout_of_read(emulator_thread: Any) -> None:
    port = str(emulator_thread.port)
    res = run("--port", port, "write", "$OV_PRO", "150")  # out of range 0..100
    assert res.exit_code == EXIT_VARIABLE and "$OV_PRO" in res.stderr
    emulator_thread.faults.add(Fault("drop", count=None))
    res = run("--port", port, "--timeout", "0.2", "read", "$OV_PRO")
    assert res.exit_code == EXIT_TIMEOUT and f"127.0.0.1:{port}" in res.stderr


def test_help_lists_every_command() -> None:
    res = run("--help")
    for cmd in ("read", "write", "watch", "record", "bench", "discover", "repl", "monitor", "emu"):
        assert cmd in res.stdout
