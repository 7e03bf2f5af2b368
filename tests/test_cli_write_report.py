"""What a write reports: its own round trip, one stop message, and after Ctrl-C whether it
was sent (real `kvp` processes against a real emulator; SIGINT as a terminal sends it)."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from pyopenshowvar_apps.common import EXIT_INTERRUPTED, EXIT_STOPPED

from kukavarproxy_emu import EmulatorThread
from kukavarproxy_emu.latency import LatencyProfile, ServiceTime
from kukavarproxy_emu.testing import TEST_CONFIG

KVP = str(Path(sys.executable).with_name("kvp"))
FAST = ServiceTime(floor=0.0005, median=0.0)
SLOW = ServiceTime(floor=30.0, median=0.0)  # never answered within a test


def wait_for(cond: Callable[[], bool], timeout: float = 20.0) -> None:
    end = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < end, "condition not met in time"
        time.sleep(0.01)


def test_the_repl_reports_the_write_round_trip_not_the_stop_window(tmp_path: Path) -> None:
    with EmulatorThread(TEST_CONFIG) as emu:  # the follow program runs: the write is watched
        res = subprocess.run(
            [KVP, "--port", str(emu.port), "repl", "--stop-window", "1.5"],
            input="MYINT 5\n",
            capture_output=True,
            text=True,
            env={**os.environ, "KVP_HISTORY": str(tmp_path / "h"), "TERM": "dumb"},
            timeout=60,
        )
    assert res.returncode == 0, res.stdout + res.stderr
    found = re.search(r"written MYINT = 5\s+\(([0-9.]+) ms\)", res.stdout)
    assert found, res.stdout
    assert float(found.group(1)) < 750  # the 1500 ms watch after the write is not in it


def test_emulate_prints_the_program_stop_once() -> None:
    res = subprocess.run(
        [KVP, "--emulate", "write", "MYAXIS", "{A1 9999}", "--stop-window", "3"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == EXIT_STOPPED, res.stderr
    assert res.stderr.count("Software limit switch +A1") == 1, res.stderr
    assert res.stderr.startswith("kvp: the robot program stopped right after writing 'MYAXIS'")


def interrupted_write(emu: EmulatorThread, ready: Callable[[], bool]) -> str:
    """``kvp write MYINT 5`` against ``emu``, SIGINT once ``ready()``; its stderr."""
    proc = subprocess.Popen(
        [KVP, "--port", str(emu.port), "--timeout", "60", "write", "MYINT", "5"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_for(ready)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == EXIT_INTERRUPTED, err
    return err


def waiting(emu: EmulatorThread, answered: int) -> Callable[[], bool]:
    """True once the client has had ``answered`` requests answered and then sent nothing for
    1 s: it waits for the answer to its last request (a slow kind, 30 s)."""
    seen: list[tuple[int, float]] = []

    def ready() -> bool:
        received = sum(c.received for c in emu.emulator.connections())
        if not received or emu.stats.requests < answered:
            return False
        if not seen or seen[-1][0] != received:
            seen.append((received, time.monotonic()))
        return time.monotonic() - seen[-1][1] > 1.0

    return ready


def test_ctrl_c_while_the_write_waits_for_its_answer_says_it_was_sent() -> None:
    slow_writes = LatencyProfile("slow writes", read=FAST, write=SLOW)
    with EmulatorThread(replace(TEST_CONFIG, latency=slow_writes)) as emu:
        err = interrupted_write(emu, waiting(emu, answered=3))  # the state read
        where = f"127.0.0.1:{emu.port}"
    assert err.startswith("kvp: interrupted: the write was sent but not answered: 'MYINT' may")
    assert where in err and err.count("\n") == 1


def test_ctrl_c_before_the_write_was_sent_says_nothing_was_written() -> None:
    slow_reads = LatencyProfile("slow reads", read=SLOW, write=FAST)  # the state read waits
    with EmulatorThread(replace(TEST_CONFIG, latency=slow_reads)) as emu:
        err = interrupted_write(emu, waiting(emu, answered=0))
        assert emu.store.read("MYINT") == "0"
    assert err.startswith("kvp: interrupted: the write was not sent: 'MYINT' was not written")
