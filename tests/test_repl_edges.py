"""`kvp repl` (issue 14): layout at 80 columns, Ctrl-C, one message per lost connection, piped
scripts, Ctrl-R + Enter, completion marks, checked writes (pexpect / a pipe, real emulator)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from prompt_toolkit.completion import CompleteEvent
from prompt_toolkit.document import Document
from pyopenshowvar_apps.completion import NameCompleter
from pyopenshowvar_apps.names import completion_names
from rich.console import Console

from kukavarproxy_emu import EmulatorThread
from kukavarproxy_emu.faults import Fault
from kukavarproxy_emu.store import VariableStore
from kukavarproxy_emu.testing import TEST_CONFIG

pexpect = pytest.importorskip("pexpect")

KVP = str(Path(sys.executable).with_name("kvp"))
PROMPT = "kvp>"
STILL = replace(TEST_CONFIG, robot=False)  # values stay where the test puts them
POSE = (
    "{E6POS: X 412.345612, Y -123.456789, Z 712.123456, A -170.123456, B 45.6543210,"
    " C -179.987654, S 6, T 27, E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)


def env(tmp_path: Path) -> dict[str, str]:
    return {
        **os.environ,
        "KVP_HISTORY": str(tmp_path / "history"),
        "PROMPT_TOOLKIT_NO_CPR": "1",
        "TERM": "dumb",
        "NO_COLOR": "1",
    }


def spawn(port: int, tmp_path: Path, *extra: str, term: str = "dumb") -> Any:
    child = pexpect.spawn(
        KVP,
        ["--port", str(port), *extra, "repl"],
        env={**env(tmp_path), "TERM": term},
        encoding="utf-8",
        timeout=10,
        dimensions=(30, 80),
    )
    child.expect_exact(PROMPT)
    return child


def command(child: Any, line: str) -> str:
    child.sendline(line)
    child.expect_exact(PROMPT)
    return str(child.before)


def output(child: Any, line: str) -> list[str]:
    """The lines a command printed (without the echo of the command itself)."""
    text = command(child, line).replace("\r", "")
    return [out for out in text.splitlines() if out.strip() and out.strip() != line]


def test_the_narrow_layout_keeps_every_member() -> None:
    from pyopenshowvar_apps.pretty import render_text

    for width in (40, 80, 200):
        console = Console(width=width, record=True, file=open(os.devnull, "w"))
        console.print(render_text("$POS_ACT", POSE))
        text = console.export_text()
        assert "…" not in text and "-179.9877" in text and "E6" in text, width
        assert max(len(line.rstrip()) for line in text.splitlines()) <= width


def test_ctrl_c_abandons_a_waiting_read_and_a_lost_connection_is_one_message(
    tmp_path: Path,
) -> None:
    first = EmulatorThread(STILL).start()
    port = first.port
    child = spawn(port, tmp_path, "--timeout", "8")
    # Ctrl-C while a read waits: back at the prompt, still in the REPL
    first.faults.add(Fault("delay", seconds=5.0, count=1))
    before = first.stats.requests
    child.sendline("$OV_PRO")
    deadline = time.monotonic() + 5
    while first.stats.requests == before:  # the read is in flight: the REPL waits for it
        assert time.monotonic() < deadline
        time.sleep(0.01)
    child.sendintr()
    child.expect_exact("interrupted")
    child.expect_exact(PROMPT)
    out = output(child, "$OV_JOG")  # does not wait behind the abandoned read
    assert len(out) == 1 and out[0].startswith("100") and "ms)" in out[0], out
    # a lost connection: one message, then one line per command while it is away
    first.stop()
    out = output(child, "$OV_PRO")
    assert len(out) == 1 and "lost" in out[0], out
    out = output(child, "$OV_PRO")
    assert len(out) == 1 and "still not connected" in out[0], out
    with EmulatorThread(replace(STILL, port=port)) as second:
        second.store.set_system("$OV_PRO", 42)
        out = output(child, "$OV_PRO")
        assert len(out) == 1 and out[0].startswith("42"), out  # back: no further message
        child.sendline("q")
        child.expect(pexpect.EOF)
        child.close()
    assert child.exitstatus == 0


def test_enter_in_a_ctrl_r_search_runs_the_line(tmp_path: Path) -> None:
    (tmp_path / "history").write_text("\n# 1\n+$OV_JOG\n\n# 2\n+MYINT\n", encoding="utf-8")
    with EmulatorThread(STILL) as emu:
        emu.store.set_system("$OV_JOG", 33)
        child = spawn(emu.port, tmp_path, term="xterm")  # "dumb" has no line editor
        child.send("\x12")  # Ctrl-R
        child.send("OV_J")
        child.send("\r")
        child.expect_exact("33")  # ran, not just put back on the line
        child.expect_exact(PROMPT)
        child.sendline("q")
        child.expect(pexpect.EOF)


def run_script(port: int, tmp_path: Path, script: str, *extra: str) -> Any:
    return subprocess.run(
        [KVP, "--port", str(port), "repl", *extra],
        input=script,
        capture_output=True,
        text=True,
        env={**env(tmp_path), "COLUMNS": "80"},
        timeout=30,
    )


def test_a_piped_script(tmp_path: Path) -> None:
    with EmulatorThread(TEST_CONFIG) as emu:  # the follow program runs: writes are watched
        emu.store.write("MYSTRING[]", '"' + "x" * 30 + '"')
        ok = run_script(emu.port, tmp_path, "$OV_PRO\n$TORQUE_AXIS_MAX[]\nMYSTRING[]\n", "--raw")
        assert ok.returncode == 0, ok.stdout + ok.stderr
        torque = next(line for line in ok.stdout.splitlines() if line.startswith("334.8"))
        assert len(torque) > 80  # one raw line, not wrapped at 80 columns
        emu.store.write("MYE6POS", POSE)  # a pose away from HOME: long numbers
        script = "MYE6POS\nMYAXIS {A1 1O}\nNOPE\nMYINT 5.5\nMYAXIS {A1 9999}\n$OV_PRO\n"
        bad = run_script(emu.port, tmp_path, script, "--stop-window", "3")  # margin for load
    out = bad.stdout
    pose = out[out.index("MYE6POS (E6POS)") : out.index("not a KRL literal")]
    assert "…" not in pose and all(len(line) <= 80 for line in pose.splitlines())  # 80 columns
    for value in ("412.3456", "-123.4568", "712.1235", "-170.1235", "45.6543", "-179.9877", "27"):
        assert value in pose, value
    assert bad.returncode == 2  # the first failure: a literal that is not KRL
    assert "not a KRL literal: unexpected '1O'" in out and "      ^" in out
    assert "unknown variable: 'NOPE'" in out
    assert "wrong type: the variable is INT" in out
    assert "the robot program stopped: $PRO_STATE1 #P_STOP" in out
    assert out.rstrip().splitlines()[-1].startswith("100")  # the script went on


def test_completion_offers_only_names_that_can_read_and_marks_unset_ones() -> None:
    store = VariableStore()
    names = completion_names(store)
    listed = list(names)
    assert "$TORQUE_AXIS_ACT[]" in listed and "$TORQUE_AXIS_ACT" not in listed  # bare array
    assert "$ANIN[]" not in listed  # built in, but this emulator has no such variable
    assert "@PROXY_VERSION" in listed
    completer = NameCompleter(names)

    def complete(text: str) -> dict[str, str]:
        found = completer.get_completions(Document(text), CompleteEvent(completion_requested=True))
        return {c.text: c.display_meta_text for c in found}

    got = complete("MYE6")
    assert got["MYE6ARRAY[]"].startswith("not every element set") and got["MYE6POS"]
    assert list(got)[-1] in ("MYE6ARRAY[]", "MYE6POS")  # marked names come last
    store.write("MYE6POS", "{X 1.0, Y 2.0, Z 3.0, A 0.0, B 0.0, C 0.0}")
    assert complete("MYE6")["MYE6POS"] == ""  # live: written since, no longer marked
    assert complete("$OV_P") == {"$OV_PRO": ""}
