"""The minimal `kvp` CLI: output, JSON, exit codes and one-line errors (against a live emulator)."""

from __future__ import annotations

import json
import socket
import threading
from typing import Any

from pyopenshowvar_apps.cli import EXIT_CONNECTION, EXIT_TIMEOUT, EXIT_VARIABLE, app
from typer.testing import CliRunner

runner = CliRunner()


def run(*args: str) -> Any:
    return runner.invoke(app, list(args))


def test_read_prints_raw_values(ideal_emulator_thread: Any) -> None:
    res = run("--port", str(ideal_emulator_thread.port), "read", "$OV_PRO", "$AXIS_ACT")
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    assert lines[0] == "100"
    assert lines[1].startswith("{E6AXIS: A1 0.0, A2 -90.0000")


def test_read_json_is_typed(ideal_emulator_thread: Any) -> None:
    res = run("--port", str(ideal_emulator_thread.port), "read", "--json", "$POS_ACT", "$OV_PRO")
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["$OV_PRO"] == 100
    assert data["$POS_ACT"]["type"] == "E6POS" and data["$POS_ACT"]["X"] == 525.0
    assert data["$POS_ACT"]["S"] == 2


def test_write_struct_literal_with_commas(emulator_thread: Any) -> None:
    port = str(emulator_thread.port)
    res = run("--port", port, "write", "MYAXIS", "{A1 10.5, A2 -80.0}")
    assert res.exit_code == 0 and res.stdout.strip() == "{A1 10.5, A2 -80.0}"
    res = run("--port", port, "read", "MYAXIS.A1")
    assert res.stdout.strip() == "10.5000"


def test_env_vars_select_the_proxy(emulator_thread: Any) -> None:
    res = runner.invoke(
        app,
        ["read", "$OV_PRO"],
        env={"KVP_HOST": "127.0.0.1", "KVP_PORT": str(emulator_thread.port)},
    )
    assert res.exit_code == 0 and res.stdout.strip() == "100"


def test_unknown_variable_and_refused_write(emulator_thread: Any) -> None:
    port = str(emulator_thread.port)
    res = run("--port", port, "read", "NOPE")
    assert res.exit_code == EXIT_VARIABLE
    assert "NOPE" in res.stderr and f"127.0.0.1:{port}" in res.stderr
    assert "Traceback" not in res.output
    res = run("--port", port, "write", "$AXIS_ACT", "{A1 1.0}")
    assert res.exit_code == EXIT_VARIABLE and "$AXIS_ACT" in res.stderr


def test_connection_refused_exit_code() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # nothing listens once closed
    res = run("--port", str(port), "-t", "0.3", "read", "$OV_PRO")  # asked again for 0.3 s
    assert res.exit_code == EXIT_CONNECTION
    assert f"127.0.0.1:{port}" in res.stderr and len(res.stderr.strip().splitlines()) == 1


def test_timeout_exit_code() -> None:
    with socket.socket() as srv:  # accepts (backlog) but never answers
        srv.bind(("127.0.0.1", 0))
        srv.listen(1)
        res = run("--port", str(srv.getsockname()[1]), "--timeout", "0.2", "read", "$OV_PRO")
    assert res.exit_code == EXIT_TIMEOUT and "$OV_PRO" in res.stderr


def test_usage_error_exit_code() -> None:
    assert run("read").exit_code == 2
    assert run("--port", "notaport", "read", "X").exit_code == 2


def test_embedded_emulator() -> None:
    res = run("--emulate", "--plant", "ideal", "read", "$TORQUE_AXIS_ACT[]")
    assert res.exit_code == 0, res.output
    assert res.stdout.startswith("0.0 -24.7805920 -25.5219193")  # the model's, not the table's
    # the embedded emulator stops with the command, even when the CLI runs in-process
    assert not [t for t in threading.enumerate() if t.name == "kukavarproxy-emu"]
