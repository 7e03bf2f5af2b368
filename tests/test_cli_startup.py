"""``kvp read`` / ``kvp write`` start fast: their import graph holds none of the heavy modules.

A shell loop pays the start-up of every ``kvp`` call, so the common commands import only what
they need (bench/cli_startup.py measures the time; here the import graph is checked, which
does not depend on machine load). Each case runs the real entry point in a fresh interpreter,
against the emulator of this process, and reports which of the modules below it loaded.
"""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

import pytest

#: Modules ``kvp read`` used to import and must not again: numpy (through the KRL value types
#: and the robot helpers), rich (through the case studies' summary table), pydantic (typer's
#: conversion of option values, see pyopenshowvar_apps.fastparams), the C3 Bridge codec, the
#: snapshot layout, and the implementations of the other commands. ``kvp read`` (the blocking
#: client) also runs without asyncio.
HEAVY = (
    "numpy",
    "rich",
    "pydantic",
    "pyopenshowvar.c3.messages",
    "pyopenshowvar.c3.files",
    "pyopenshowvar.c3.replies",
    "pyopenshowvar.snapshot_layout",
    "pyopenshowvar_apps.demo",
    "pyopenshowvar_apps.discover",
    "pyopenshowvar_apps.watchrecord",
    "pyopenshowvar_apps.bench",
    "pyopenshowvar_apps.sessions",
    "pyopenshowvar_apps.heave.cli",
    "pyopenshowvar_apps.web.command",
)

# Runs kvp's entry point with argv[2:], then prints (stdout, last line) which HEAVY modules
# were loaded and the exit code. main() ends in sys.exit, hence the finally.
_PROBE = """
import json, sys
heavy = json.loads(sys.argv[1])
sys.argv = ["kvp", *sys.argv[2:]]
from pyopenshowvar_apps.cli import main
code = 0
try:
    main()
except SystemExit as exc:
    code = exc.code
finally:
    loaded = [m for m in heavy if m in sys.modules]
    print(json.dumps({"code": code, "loaded": loaded}))
"""


def _probe(heavy: list[str], *argv: str) -> tuple[list[str], dict[str, Any]]:
    proc = subprocess.run(
        [sys.executable, "-c", _PROBE, json.dumps(heavy), *argv],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    lines = proc.stdout.splitlines()
    assert lines, proc.stderr
    return lines[:-1], json.loads(lines[-1])


@pytest.mark.parametrize(
    ("argv", "output", "no_asyncio"),
    [
        (["read", "$OV_PRO"], ["100"], True),  # the blocking client: no event loop
        (["write", "$OV_PRO", "50", "--stop-window", "0"], ["50"], False),
        (["discover", "--help"], None, True),
    ],
    ids=["read", "write", "discover-help"],
)
def test_common_commands_import_no_heavy_module(
    emulator_thread: Any, argv: list[str], output: list[str] | None, no_asyncio: bool
) -> None:
    heavy = [*HEAVY, "asyncio"] if no_asyncio else list(HEAVY)
    printed, report = _probe(heavy, "--port", str(emulator_thread.port), *argv)
    assert report["code"] in (0, None), printed
    if output is not None:
        assert printed == output
    own = f"pyopenshowvar_apps.{argv[0]}"  # discover's implementation is its own module
    loaded = [m for m in report["loaded"] if m != own]
    assert loaded == [], f"kvp {argv[0]} imports {loaded}"


def test_the_probe_sees_a_heavy_import() -> None:
    # the check above can fail: the full help builds every command, the case studies too
    _, report = _probe(list(HEAVY), "--help")
    assert "pyopenshowvar_apps.demo" in report["loaded"]
    assert "rich" in report["loaded"]
