"""``kvp program``, ``kvp files`` and ``kvp discover`` against C3 Bridge emulators (CliRunner)."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from pyopenshowvar_apps.cli import EXIT_PROTOCOL, EXIT_USAGE, EXIT_VARIABLE, app
from typer.testing import CliRunner

from kukavarproxy_emu import EmulatorThread
from kukavarproxy_emu.testing import TEST_CONFIG

runner = CliRunner()

SRC = "DEF PICK()\n  PTP {A1 20, A2 -80, A3 85, A4 0, A5 10, A6 0}\n  DONE = DONE + 1\nEND\n"
DAT = "DEFDAT PICK PUBLIC\n  DECL GLOBAL INT DONE = 0\nENDDAT\n"


def run(*args: str) -> Any:
    return runner.invoke(app, list(args))


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def c3() -> Iterator[EmulatorThread]:
    config = replace(TEST_CONFIG, proxy="c3bridge", plant="ideal", speed=8.0)
    with EmulatorThread(config) as emu:
        yield emu


def test_upload_select_start_status_stop(c3: EmulatorThread, tmp_path: Path) -> None:
    (tmp_path / "pick.src").write_text(SRC)
    (tmp_path / "pick.dat").write_text(DAT)  # found beside the .src
    port = ["--port", str(c3.port)]
    res = run("program", "upload", str(tmp_path / "pick.src"), *port)
    assert res.exit_code == 0, res.output
    assert "pick.src (" in res.stdout and "pick.dat (" in res.stdout
    assert run("program", "select", "/R1/PICK", *port).exit_code == 0
    res = run("program", "start", *port)  # no --allow-motion: refused, nothing sent
    assert res.exit_code == EXIT_USAGE and "--allow-motion" in res.stderr
    assert json.loads(run("program", "status", "--json", *port).stdout)["state"] == "P_RESET"
    assert run("program", "start", "--allow-motion", *port).exit_code == 0
    deadline = time.monotonic() + 5
    while json.loads(run("program", "status", "--json", *port).stdout)["state"] != "P_END":
        assert time.monotonic() < deadline, "the program did not end"
        time.sleep(0.05)
    assert run("read", "DONE", *port).stdout.strip() == "1"
    res = run("program", "stop", *port)
    assert res.exit_code == EXIT_VARIABLE and "it ended already" in res.stderr
    res = run("program", "start", "--allow-motion", *port)
    assert res.exit_code == EXIT_VARIABLE and "kvp program reset" in res.stderr
    assert run("program", "reset", *port).exit_code == 0
    assert run("program", "status", *port).stdout.startswith("PICK P_RESET")
    res = run("program", "select", "/R1/NOPE", *port)
    assert res.exit_code == EXIT_VARIABLE and "no module /R1/NOPE" in res.stderr


def test_files_ls_get_put_rm(c3: EmulatorThread, tmp_path: Path) -> None:
    port = ["--port", str(c3.port)]
    local = tmp_path / "notes.txt"
    local.write_bytes(b"hello\r\nrobot\r\n")
    assert run("files", "put", str(local), "KRC:\\R1\\notes.txt", *port).exit_code == 0
    res = run("files", "ls", "KRC:\\R1", "-l", *port)
    assert res.exit_code == 0 and "14  KRC:\\R1\\notes.txt" in res.stdout, res.output
    assert "<DIR>  KRC:\\R1\\Program\\" in res.stdout
    out = tmp_path / "back.txt"
    assert run("files", "get", "KRC:/R1/NOTES.TXT", str(out), *port).exit_code == 0
    assert out.read_bytes() == local.read_bytes()
    res = run("files", "put", str(local), "C:\\Windows\\notes.txt", *port)
    assert res.exit_code == EXIT_VARIABLE and "not a valid path" in res.stderr
    assert run("files", "rm", "KRC:\\R1\\notes.txt", *port).exit_code == 0
    res = run("files", "get", "KRC:\\R1\\notes.txt", str(out), *port)
    assert res.exit_code == EXIT_VARIABLE
    res = run("files", "put", str(tmp_path / "missing"), "KRC:\\R1\\x", *port)
    assert res.exit_code == EXIT_USAGE


def test_a_kvp_server_says_what_is_missing(emulator_thread: Any, tmp_path: Path) -> None:
    (tmp_path / "pick.src").write_text(SRC)
    port = ["--port", str(emulator_thread.port)]
    for args in (("program", "upload", str(tmp_path / "pick.src")), ("files", "ls")):
        res = run(*args, *port)
        assert res.exit_code == EXIT_PROTOCOL and "KUKAVARPROXY" in res.stderr, res.output
    res = run("program", "status", *port)  # plain reads: fine on KVP
    assert res.exit_code == 0 and "P_ACTIVE" in res.stdout


def test_emulate_upload_and_start_in_one_command(tmp_path: Path) -> None:
    (tmp_path / "pick.src").write_text(SRC)
    args = ["--emulate", "--plant", "ideal", "program", "upload", str(tmp_path / "pick.src")]
    res = run(*args, "--start", "--allow-motion")
    assert res.exit_code == 0 and "started" in res.stdout, res.output


def test_discover_tells_c3_bridge_from_kvp() -> None:
    config = replace(
        TEST_CONFIG, proxy="c3bridge", robot=False, discovery=True, udp_port=free_udp_port()
    )
    config = replace(config, udp_reply_port=0)
    with EmulatorThread(config) as emu:
        e = emu.emulator
        args = ["discover", "--to", "127.0.0.1", "--udp-port", str(e.udp_port)]
        args += ["--standard-port", str(e.udp_standard_port), "--listen-port", "0", "-t", "0.3"]
        res = run(*args, "--json")
        assert res.exit_code == 0, res.output
        (answer,) = json.loads(res.stdout)  # legacy and standard answers: one server
        assert (answer["proxy"], answer["tcp_port"]) == ("C3 Bridge 1.4", e.port)
        assert "C3 Bridge 1.4" in run(*args).stdout
