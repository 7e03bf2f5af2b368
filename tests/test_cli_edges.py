"""The rough edges of `kvp` a new user hits (issue 14): options, literals, refusals, stops."""

from __future__ import annotations

import json
import socket
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
import typer
from pyopenshowvar_apps import cli
from pyopenshowvar_apps.cli import (
    EXIT_CONNECTION,
    EXIT_STOPPED,
    EXIT_USAGE,
    EXIT_VARIABLE,
    app,
    hoist_global_options,
)
from typer.testing import CliRunner

from kukavarproxy_emu import EmulatorThread
from kukavarproxy_emu.testing import TEST_CONFIG

runner = CliRunner()


def run(*args: str, **kw: Any) -> Any:
    return runner.invoke(app, list(args), **kw)


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def one_clean_error(res: Any, code: int) -> str:
    assert res.exit_code == code, res.output
    assert "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)
    return str(res.stderr)


# ------------------------------------------------------------------- options


@pytest.mark.parametrize(
    "args",
    [
        ["-p", "99999", "read", "$OV_PRO"],
        ["-p", "0", "read", "$OV_PRO"],
        ["read", "$OV_PRO", "--port", "-3"],
        ["-t", "0", "read", "$OV_PRO"],
        ["-t", "-1", "read", "$OV_PRO"],
        ["read", "$OV_PRO", "-t", "nan"],
        ["read", "$OV_PRO", "--timeout=inf"],
        ["discover", "--udp-port", "0"],
        ["discover", "--listen-port", "70000"],
        ["discover", "-t", "0"],
    ],
)
def test_ports_and_timeouts_are_validated(args: list[str]) -> None:
    err = one_clean_error(run(*args), EXIT_USAGE)
    assert "Invalid value" in err and ("port" in err or "seconds" in err)


def test_port_from_the_environment_is_validated() -> None:
    err = one_clean_error(run("read", "$OV_PRO", env={"KVP_PORT": "99999"}), EXIT_USAGE)
    assert "99999 is not a port" in err


def test_hoist_global_options() -> None:
    own = {"--json": False, "--timeout": True, "--out": True, "-o": True}
    assert hoist_global_options(["read", "X", "-p", "7001"], own, 0) == [
        "-p",
        "7001",
        "read",
        "X",
    ]
    assert hoist_global_options(["-H", "h", "read", "--port=1", "-t0.5", "X"], own, 2) == [
        "-H",
        "h",
        "--port=1",
        "-t0.5",
        "read",
        "X",
    ]
    # the command's own option wins, its value is never taken for a global option
    assert hoist_global_options(["d", "--timeout", "3", "--out", "-p"], own, 0) == [
        "d",
        "--timeout",
        "3",
        "--out",
        "-p",
    ]
    # nothing moves after "--", and a pass-through command keeps everything
    assert hoist_global_options(["write", "--", "X", "--emulate"], own, 0)[-1] == "--emulate"
    assert hoist_global_options(["emu", "--port", "1"], None, 0) == ["emu", "--port", "1"]
    with pytest.raises(typer.BadParameter):  # a value is missing: say so, do not take "read"
        hoist_global_options(["read", "X", "-H"], own, 0)


def test_global_options_after_the_command(emulator_thread: Any) -> None:
    port = str(emulator_thread.port)
    for args in (
        ["read", "$OV_PRO", "--port", port],
        ["read", f"--port={port}", "$OV_PRO", "-t", "0.5"],
        ["--port", "1", "read", "$OV_PRO", f"-p{port}"],  # the later one wins
        ["read", "$OV_PRO", "--emulate"],
        ["read", "$OV_PRO", "--emulate", "--plant", "ideal"],
    ):
        res = run(*args)
        assert res.exit_code == 0 and res.stdout.strip() == "100", (args, res.output)
    res = run("read", "--json", "$OV_PRO", "-H", "127.0.0.1", "-p", port)
    assert json.loads(res.stdout) == {"$OV_PRO": 100}
    assert "Global options" in run("read", "--help").stdout


def test_emu_takes_its_own_options() -> None:
    res = run("emu", "--help")
    assert res.exit_code == 0
    for option in ("usage: kvp emu", "--latency", "--program", "--udp-reply-port", "--fault"):
        assert option in res.stdout
    res = run("emu", "--port", "99999")  # the emulator's --port, not kvp's
    assert res.exit_code == EXIT_USAGE and "kvp emu: error" in res.stderr


# ------------------------------------------------------------------- write


def test_a_value_may_start_with_minus(emulator_thread: Any) -> None:
    port = str(emulator_thread.port)
    for value, stored in (("-5", "-5.00000"), ("-80.5", "-80.5000"), ("-1.5E-3", "-0.00150000")):
        res = run("--port", port, "write", "MYREAL", value, "--stop-window", "0")
        assert res.exit_code == 0 and res.stdout.strip() == value, res.output
        assert emulator_thread.store.read("MYREAL") == stored
    err = one_clean_error(run("--port", port, "write", "$OV_PRO", "-5"), EXIT_VARIABLE)
    assert "out of range 0..100" in err


def test_a_bad_literal_is_caught_before_sending(emulator_thread: Any) -> None:
    port = str(emulator_thread.port)
    before = emulator_thread.stats.requests
    err = one_clean_error(run("--port", port, "write", "MYAXIS", "{A1 10.0, A2 -80.0"), EXIT_USAGE)
    lines = err.splitlines()
    assert "is not a KRL literal" in lines[0] and "expected ',' or '}'" in lines[0]
    assert lines[1] == "  {A1 10.0, A2 -80.0" and lines[2] == "  " + " " * 18 + "^"
    err = one_clean_error(run("--port", port, "write", "MYAXIS", "{A1 1O.0}"), EXIT_USAGE)
    assert err.splitlines()[2].index("^") == 2 + 4
    assert emulator_thread.stats.requests == before  # nothing was sent
    # --no-check sends it as it is: the controller refuses
    res = run("--port", port, "write", "--no-check", "MYAXIS", "{A1 1O.0}")
    assert res.exit_code == EXIT_VARIABLE and emulator_thread.stats.requests > before


@pytest.mark.parametrize(
    ("name", "value", "reason"),
    [
        ("NOPE", "5", "reads as unknown"),
        ("$AXIS_ACT", "{A1 1.0}", "read-only"),
        ("$MODE_OP", "#T1", "read-only"),
        ("$OV_PRO", "150", "out of range 0..100"),
        ("MYINT", "5.5", "wrong type: the variable is INT (now 0); expected an INT"),
        ("MYAXIS", "{X 1}", "E6AXIS has no member X"),
        ("MYAXIS", "5", "wrong type: the variable is E6AXIS"),
        ("MYBOOL", "1", "expected a BOOL"),
    ],
)
def test_a_refusal_says_why(emulator_thread: Any, name: str, value: str, reason: str) -> None:
    err = one_clean_error(run("--port", str(emulator_thread.port), "write", name, value), 5)
    assert err.startswith(f"kvp: write refused: {name!r} on 127.0.0.1:") and reason in err
    assert len(err.strip().splitlines()) == 1


def test_a_write_that_stops_the_program_is_reported(emulator_thread: Any) -> None:
    port = str(emulator_thread.port)
    res = run("--port", port, "write", "MYAXIS", "{A1 10.0}")
    assert res.exit_code == 0 and res.stderr == ""
    res = run("--port", port, "write", "MYAXIS", "{A1 9999}", "--stop-window", "3")  # load
    assert res.exit_code == EXIT_STOPPED, res.output
    assert res.stdout.strip() == "{A1 9999}"  # the controller accepted it
    assert "stopped right after writing 'MYAXIS'" in res.stderr
    assert "$PRO_STATE1 #P_STOP" in res.stderr and "$STOPMESS TRUE" in res.stderr
    assert "Software limit switch +A1" in res.stderr  # the emulator's $EMU_MESSAGE[]
    # the program is stopped now: a further write is not watched and not blamed
    res = run("--port", port, "write", "MYAXIS", "{A1 20.0}")
    assert res.exit_code == 0 and res.stderr == ""


# ------------------------------------------------------------------- bench, discover


def test_bench_checks_its_csv_before_running(tmp_path: Path) -> None:
    closed = str(free_port())
    err = one_clean_error(run("-p", closed, "bench", "--csv", "/nonexistent/x.csv"), EXIT_USAGE)
    assert "cannot write /nonexistent/x.csv" in err
    out = tmp_path / "x.csv"  # a good path, then the benchmark fails: no empty file left
    assert run("-p", closed, "-t", "0.3", "bench", "--csv", str(out)).exit_code == EXIT_CONNECTION
    assert not out.exists()


def test_a_proxy_still_starting_is_waited_for_until_the_timeout() -> None:
    """An emulator started in the background a moment before refuses until it listens: the
    command asks again (README: ``kukavarproxy-emu ... &`` then ``kvp read`` on the next line)."""
    import subprocess
    import threading
    import time

    port = free_port()
    kvp = str(Path(sys.executable).with_name("kvp"))
    started = time.monotonic()
    proc = subprocess.Popen(
        [kvp, "-p", str(port), "-t", "30", "read", "$OV_PRO"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    stop = threading.Event()

    def late_emulator() -> None:
        time.sleep(1.0)
        with EmulatorThread(replace(TEST_CONFIG, port=port)):
            stop.wait(60)

    thread = threading.Thread(target=late_emulator)
    thread.start()
    try:
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
        stop.set()
        thread.join()
    assert proc.returncode == 0, err
    assert out.strip() == "100" and time.monotonic() - started > 1.0


def test_discover_the_embedded_emulator() -> None:
    for args in (["--emulate", "discover", "-t", "0.3"], ["discover", "--json", "--emulate"]):
        res = run(*args)
        assert res.exit_code == 0, res.output
        assert "#KR6R900SIXX C4SR FLR" in res.stdout


def test_discover_doc_example_with_a_kvp_style_reply_port() -> None:
    """docs/cli.md: a default proxy answers on a fixed port (KVP: 7000); listen on it."""
    reply = free_port(socket.SOCK_DGRAM)
    config = replace(
        TEST_CONFIG, discovery=True, udp_port=free_port(socket.SOCK_DGRAM), udp_reply_port=reply
    )
    with EmulatorThread(config) as emu:
        udp = str(emu.config.udp_port)
        ask = ["discover", "--to", "127.0.0.1", "--udp-port", udp, "-t", "0.3"]
        res = run(*ask, "--listen-port", str(reply))
        assert res.exit_code == 0 and "KR6R900SIXX" in res.stdout, res.output
        # listening anywhere else hears nothing: the doc's old example
        res = run(*ask, "--listen-port", "0")
        assert res.exit_code == EXIT_CONNECTION


# ------------------------------------------------------------------- one flag, no tracebacks


def test_emulate_is_the_one_flag_and_sim_a_hidden_alias() -> None:
    for command in ("linefollow", "teleop", "haptic", "repl", "monitor"):
        help_text = run(command, "--help").stdout
        assert "--sim" not in help_text and "--emulate" in help_text, command
    res = run("haptic", "--sim", "--duration", "-1")  # still parsed, then validated
    assert res.exit_code == EXIT_USAGE and "--duration" in res.stderr


@pytest.mark.parametrize(
    "args",
    [
        ["teleop", "--mode", "nope"],
        ["teleop", "--device", "/nonexistent.csv", "--duration", "1"],
        ["haptic", "--duration", "0"],
        ["linefollow", "--start", "abc"],
        ["linefollow", "--table", "1,2"],
    ],
)
def test_case_study_options_are_validated(args: list[str]) -> None:
    one_clean_error(run(*args), EXIT_USAGE)


def test_an_unexpected_error_is_one_line(monkeypatch: Any, capsys: Any) -> None:
    def broken() -> None:
        raise RuntimeError("boom")

    monkeypatch.setattr(cli, "app", broken)
    monkeypatch.delenv("KVP_DEBUG", raising=False)
    with pytest.raises(SystemExit) as exit_info:
        cli.main()
    assert exit_info.value.code == 1
    err = capsys.readouterr().err
    assert err.startswith("kvp: unexpected error RuntimeError: boom") and err.count("\n") == 1
    monkeypatch.setenv("KVP_DEBUG", "1")
    with pytest.raises(RuntimeError):
        cli.main()
    assert sys.exc_info()[0] is None


def test_the_case_studies_emulate_the_program_they_need(capsys: Any) -> None:
    """kvp [--emulate] teleop/haptic [--emulate]: an emulator running EXT_MOVE_AXIS/ACTUATOR."""
    from pyopenshowvar_apps.casestudies import teleop_cli
    from pyopenshowvar_apps.casestudies.common import CaseResult
    from pyopenshowvar_apps.common import Opts

    seen: list[str] = []

    async def probe(kvp: Any, emu: Any) -> CaseResult:
        seen.append(await kvp.read("$PRO_NAME1[]"))
        return CaseResult("probe")

    for program in ("actuator", "ext_move_axis"):
        Opts.reset("127.0.0.1", free_port(), 1.0, emulate=True)  # nothing listens there
        teleop_cli._run(program, False, probe)
    assert seen == ['"ACTUATOR"', '"EXT_MOVE_AXIS"']
    assert "--sim is deprecated" not in capsys.readouterr().err
