"""`kvp repl` through a pseudo-terminal (pexpect): reads, struct writes, history, errors, reconnect."""

from __future__ import annotations

import os
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from pyopenshowvar_apps.repl import split_command

from kukavarproxy_emu import EmulatorThread
from kukavarproxy_emu.testing import TEST_CONFIG

pexpect = pytest.importorskip("pexpect")

KVP = str(Path(sys.executable).with_name("kvp"))
PROMPT = "kvp>"


def spawn(port: int, history: Path, *extra: str) -> Any:
    env = {
        **os.environ,
        "KVP_HISTORY": str(history),
        "PROMPT_TOOLKIT_NO_CPR": "1",
        "TERM": "xterm",
        "NO_COLOR": "1",
        "COLUMNS": "100",
    }
    child = pexpect.spawn(
        KVP,
        ["--port", str(port), *extra, "repl"],
        env=env,
        encoding="utf-8",
        timeout=10,
        dimensions=(30, 100),
    )
    child.expect_exact(PROMPT)
    return child


def command(child: Any, line: str, *expected: str) -> str:
    child.sendline(line)
    for text in expected:
        child.expect_exact(text)
    child.expect_exact(PROMPT)
    return str(child.before)


def test_split_command() -> None:
    assert split_command("$OV_PRO") == ("$OV_PRO", None)
    assert split_command("MYAXIS {A1 1.0, A2 2.0}") == ("MYAXIS", "{A1 1.0, A2 2.0}")
    assert split_command("MYAXIS = {A1 1.0}") == ("MYAXIS", "{A1 1.0}")
    assert split_command("MYINT=5") == ("MYINT", "5")
    assert split_command("GRID[1, 2] 7") == ("GRID[1, 2]", "7")
    assert split_command("MYINT =") == ("MYINT", "")


def test_read_write_error_history_and_quit(emulator_thread: Any, tmp_path: Path) -> None:
    history = tmp_path / "hist"
    child = spawn(emulator_thread.port, history)
    command(child, "$OV_PRO", "100", "ms)")
    # a struct literal with commas and braces, no quoting
    command(child, "MYAXIS {A1 10.5, A2 -80.0}", "written", "ms)")
    assert emulator_thread.store.read("MYAXIS.A1") == "10.5000"
    command(child, "MYAXIS = {A3 33.0}", "written")
    assert emulator_thread.store.read("MYAXIS.A3") == "33.0000"
    # typed pretty printing: a labelled row
    command(child, "MYAXIS", "MYAXIS (E6AXIS)", "A1", "E6", "10.5", "-80", "33")
    command(child, "$VEL", "CP", "ORI1", "400")
    out = command(child, "NOPE", "unknown variable")
    assert "Traceback" not in out
    command(child, "$AXIS_ACT {A1 1.0}", "write refused")
    command(child, ":help", ":watch")
    child.sendline(":quit")
    child.expect(pexpect.EOF)
    child.close()
    assert child.exitstatus == 0
    lines = history.read_text(encoding="utf-8")
    assert "+$OV_PRO" in lines and "+MYAXIS {A1 10.5, A2 -80.0}" in lines

    # a second session sees the history: ↑ ↑ ↑ recalls the refused write (before :help, :quit)
    child = spawn(emulator_thread.port, history)
    for _ in range(3):
        child.send("\x1b[A")
    child.expect_exact("$AXIS_ACT {A1 1.0}")
    child.send("\r")
    child.expect_exact("write refused")
    child.expect_exact(PROMPT)
    child.sendline("q")
    child.expect(pexpect.EOF)


def test_watch_until_ctrl_c_and_tab_completion(tmp_path: Path) -> None:
    child = pexpect.spawn(
        KVP,
        ["--emulate", "--plant", "ideal", "repl"],
        env={
            **os.environ,
            "KVP_HISTORY": str(tmp_path / "h"),
            "PROMPT_TOOLKIT_NO_CPR": "1",
            "TERM": "xterm",
        },
        encoding="utf-8",
        timeout=10,
        dimensions=(30, 100),
    )
    child.expect_exact(PROMPT)
    # completes to $TORQUE_AXIS_ACT[] (emulator + built-in names; the bare array name, which
    # only reads as unknown, is not offered)
    child.send("$TORQUE_AXIS_A\t")
    child.expect_exact("CT[]")
    child.send("\r")
    child.expect_exact("-24.78")
    child.expect_exact(PROMPT)
    child.sendline(":watch $OV_PRO 20")
    child.expect_exact("Ctrl-C stops")
    child.sendintr()
    child.expect_exact(PROMPT)
    child.sendline("$OV_PRO")
    child.expect_exact("100")
    child.expect_exact(PROMPT)
    child.sendeof()
    child.expect(pexpect.EOF)


def test_reconnects_after_a_drop(tmp_path: Path) -> None:
    first = EmulatorThread(TEST_CONFIG).start()
    port = first.port
    try:
        child = spawn(port, tmp_path / "h")
        command(child, "$OV_PRO", "100")
        first.stop()
        second = EmulatorThread(replace(TEST_CONFIG, port=port)).start()
        try:
            second.store.set_system("$OV_PRO", 55)
            child.sendline("$OV_PRO")
            child.expect("lost|reconnect")
            child.expect_exact("55")
            child.expect_exact(PROMPT)
            child.sendline(":quit")
            child.expect(pexpect.EOF)
        finally:
            second.stop()
    finally:
        first.stop()


def test_first_connection_refused_exits_3(tmp_path: Path) -> None:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    child = pexpect.spawn(KVP, ["--port", str(port), "repl"], encoding="utf-8", timeout=10)
    child.expect(pexpect.EOF)
    child.close()
    assert child.exitstatus == 3
    assert f"127.0.0.1:{port}" in str(child.before) and "Traceback" not in str(child.before)
