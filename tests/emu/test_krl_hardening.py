"""Regression tests of issue 16, item 5: KRL cannot starve or hang the emulator.

Runaway functions, slow functions in a loop, functions calling functions, huge local arrays,
absurd nesting: each cycle stays within its statement budget (counted over every statement,
inside functions too), errors name ``file:line:column``, and SIGTERM/SIGINT end the process
within a second whatever runs. Cycle costs are asserted as statement counts and CPU time
(``time.process_time``), never as wall-clock latency.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from kukavarproxy_emu.krl import interp
from kukavarproxy_emu.krl.executor import KrlProgram, load_module
from kukavarproxy_emu.krl.parser import KrlSyntaxError, parse_src
from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.store import VariableStore
from pyopenshowvar.krl.datfile import DatSyntaxError, parse_dat

DAT = "DEFDAT $CONFIG\nDECL INT RI=0\nDECL REAL RR=0.0\nENDDAT\n"
#: CPU seconds one cycle may take: the 2 ms budget plus one statement, with a wide margin.
CYCLE_CPU = 0.05


def robot_for(tmp_path: Path, body: str, extra: str = "") -> Robot:
    src = tmp_path / "t.src"
    src.write_text(f"DEF T()\n{textwrap.dedent(body)}\nEND\n{textwrap.dedent(extra)}")
    store = VariableStore()
    store.load_dat(DAT)
    robot = Robot(store, program=str(src), sps="none")
    robot._begin()
    return robot


def cycles(robot: Robot, n: int) -> list[tuple[int, float]]:
    """Run ``n`` cycles; (statements, CPU seconds) of each."""
    prog = robot.program
    assert isinstance(prog, KrlProgram) and prog.interp is not None
    interp = prog.interp
    out = []
    for _ in range(n):
        total, cpu = interp.total, time.process_time()
        robot.tick()
        out.append((interp.total - total, time.process_time() - cpu))
    return out


def state(robot: Robot) -> str:
    return robot.store.read("$PRO_STATE1")


RUNAWAY = """
DEFFCT INT SPIN()
  DECL INT I
  I = 0
  LOOP
    I = I + 1
  ENDLOOP
ENDFCT
"""


@pytest.mark.timeout(30)
def test_runaway_function_is_suspended_every_cycle(tmp_path: Path) -> None:
    robot = robot_for(tmp_path, "RI = SPIN()", RUNAWAY)
    budget = robot.program.budget  # type: ignore[attr-defined]
    for statements, cpu in cycles(robot, 5):
        assert statements <= budget + 1 and cpu < CYCLE_CPU
    assert state(robot) == "#P_ACTIVE"  # still running, as a KRC would: not an error


@pytest.mark.timeout(30)
def test_slow_function_in_a_loop_counts_against_the_budget(tmp_path: Path) -> None:
    slow = """
    DEFFCT REAL SLOW()
      DECL INT I
      FOR I = 1 TO 100
        RR = RR + 1
      ENDFOR
      RETURN RR
    ENDFCT
    """
    robot = robot_for(tmp_path, "LOOP\n  RR = SLOW()\n  RI = RI + 1\nENDLOOP", slow)
    budget = robot.program.budget  # type: ignore[attr-defined]
    runs = cycles(robot, 40)
    assert all(statements <= budget + 1 and cpu < CYCLE_CPU for statements, cpu in runs)
    assert robot.store.get("RI") >= 2  # the loop makes progress across cycles
    assert robot.store.get("RR") >= 200


@pytest.mark.timeout(30)
def test_function_calling_a_function_in_a_loop_does_not_hang(tmp_path: Path) -> None:
    extra = """
    DEFFCT INT ONE()
      RETURN 1
    ENDFCT
    DEFFCT INT OUTER()
      LOOP
        RI = RI + ONE()
      ENDLOOP
    ENDFCT
    """
    robot = robot_for(tmp_path, "RI = OUTER()", extra)
    budget = robot.program.budget  # type: ignore[attr-defined]
    for statements, cpu in cycles(robot, 5):
        assert statements <= budget + 1 and cpu < CYCLE_CPU
    assert robot.store.get("RI") > 0 and state(robot) == "#P_ACTIVE"


def test_function_results_and_side_effects_stay_exact(tmp_path: Path) -> None:
    extra = """
    DEFFCT INT BUMP(N:IN)
      DECL INT N
      RI = RI + N
      RETURN RI
    ENDFCT
    DEFFCT BOOL NO()
      RI = RI + 1000
      RETURN FALSE
    ENDFCT
    """
    body = """
    DECL INT A[3]
    A[1] = 0
    A[2] = 0
    A[3] = 0
    RI = 1
    A[BUMP(1)] = RI + BUMP(BUMP(0))
    IF (RI < 0) AND NO() THEN
      RI = -1
    ENDIF
    RR = A[3]
    """
    robot = robot_for(tmp_path, body, extra)
    for _ in range(20):
        robot.tick()
    # RI + BUMP(BUMP(0)) reads RI (1) before the calls run (1 + 2), the target's BUMP(1) runs
    # after the value (A[3]), and a short-circuit AND never calls NO()
    assert robot.store.get("RI") == 3 and robot.store.get("RR") == 3.0
    assert state(robot) == "#P_END"


def test_huge_local_array_is_a_syntax_error_with_position(tmp_path: Path) -> None:
    src = tmp_path / "big.src"
    src.write_text("DEF BIG()\n  SUB()\nEND\nDEF SUB()\n  DECL INT A[5000000]\nEND\n")
    with pytest.raises(KrlSyntaxError) as info:
        load_module(src)
    assert "big.src:5:14: array of 5000000 elements exceeds" in str(info.value)


@pytest.mark.timeout(30)
def test_recursion_with_big_locals_stops_with_an_error(tmp_path: Path) -> None:
    extra = """
    DEF DEEP()
      DECL INT A[200000]
      RI = RI + 1
      DEEP()
    END
    """
    robot = robot_for(tmp_path, "DEEP()", extra)
    for _statements, cpu in cycles(robot, 10):
        assert cpu < CYCLE_CPU
    assert state(robot) == "#P_STOP"
    message = robot.store.read("$EMU_MESSAGE[]")
    assert "t.src:8:3: calling DEEP: local variables" in message
    assert robot.store.get("RI") == 5  # 5 x 200 000 elements fit, the 6th call does not


@pytest.mark.timeout(30)
def test_loop_calling_a_routine_with_a_big_local_is_budgeted(tmp_path: Path) -> None:
    extra = """
    DEF USE()
      DECL INT A[200000]
      RI = RI + 1
    END
    """
    robot = robot_for(tmp_path, "LOOP\n  USE()\nENDLOOP", extra)
    runs = cycles(robot, 5)
    assert all(cpu < CYCLE_CPU for _statements, cpu in runs)
    assert robot.store.get("RI") >= 5


@pytest.mark.parametrize(
    ("expr", "column"),
    [
        ("(" * 250 + "1" + ")" * 250, 69),
        ("-" * 300 + "1", 69),
        ("NOT " * 300 + "TRUE", 261),
        ("{A " * 300 + "1" + "}" * 300, 197),
        ("1" + "+1" * 5000, 5),
        ("F(" * 300 + "1" + ")" * 300, 133),
    ],
)
def test_deep_expressions_are_syntax_errors(expr: str, column: int) -> None:
    with pytest.raises(KrlSyntaxError) as info:
        parse_src(f"DEF T()\nX = {expr}\nEND\n", "t.src")
    assert str(info.value).startswith(f"t.src:2:{column}: expression nested deeper than 64")


@pytest.mark.parametrize("opener", ["IF TRUE THEN", "LOOP", "WHILE TRUE"])
def test_deep_blocks_are_syntax_errors(opener: str) -> None:
    closer = {"IF TRUE THEN": "ENDIF", "LOOP": "ENDLOOP", "WHILE TRUE": "ENDWHILE"}[opener]
    text = "DEF T()\n" + f"{opener}\n" * 330 + f"{closer}\n" * 330 + "END\n"
    with pytest.raises(KrlSyntaxError) as info:
        parse_src(text, "t.src")
    assert str(info.value).startswith("t.src:66:1: control structures nested deeper than 64")
    parse_src("DEF T()\n" + f"{opener}\n" * 64 + f"{closer}\n" * 64 + "END\n", "t.src")


@pytest.mark.parametrize(
    ("decl", "where", "message"),
    [
        ("DECL INT A[999999999]", "2:12", "array of 999999999 elements exceeds"),
        ("DECL INT A[99999,99999]", "2:18", "array of 9999800001 elements exceeds"),
        ("DECL INT A[" + "9" * 5000 + "]", "2:12", "an array size is too large"),
    ],
)
def test_absurd_dat_dimensions_are_positioned_errors(decl: str, where: str, message: str) -> None:
    with pytest.raises(DatSyntaxError) as info:
        parse_dat(f"DEFDAT $CONFIG\n{decl}\nENDDAT\n", "x.dat")
    assert str(info.value).startswith(f"x.dat:{where}: {message}")


def test_deep_aggregate_in_a_dat_is_a_positioned_error() -> None:
    deep = "{A1 " * 3000 + "1" + "}" * 3000
    text = f"DEFDAT $CONFIG\nDECL E6AXIS DEEP_AX={deep}\nENDDAT\n"
    with pytest.raises(ValueError, match=r"^x\.dat:2:13: declaration of DEEP_AX"):
        VariableStore(strict=True).load_dat(parse_dat(text, "x.dat"))


# --- SIGTERM / Ctrl-C ----------------------------------------------------------------------


def start_emulator(*args: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "kukavarproxy_emu", "--port", "0", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().startswith("listening on ")
    return proc


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_ends_the_emulator_while_krl_runs_away(tmp_path: Path, sig: int) -> None:
    src = tmp_path / "hang.src"
    src.write_text(
        "DEF HANG()\n  DECL INT R\n  R = OUTER()\nEND\n"
        "DEFFCT INT ONE()\n  RETURN 1\nENDFCT\n"
        "DEFFCT INT OUTER()\n  DECL INT X\n  X = 0\n  LOOP\n    X = X + ONE()\n  ENDLOOP\nENDFCT\n"
    )
    proc = start_emulator("--program", str(src))
    try:
        time.sleep(0.3)  # the program is deep in its endless function by now
        sent = time.monotonic()
        proc.send_signal(sig)
        assert proc.wait(timeout=5) == 0
        assert time.monotonic() - sent < 1.0
    finally:
        proc.kill()
        proc.wait()


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_watchdog_ends_a_process_whose_loop_is_held() -> None:
    script = textwrap.dedent(
        """
        import asyncio, time
        from kukavarproxy_emu.__main__ import _arm_stop_signals
        async def main():
            _arm_stop_signals(asyncio.get_running_loop(), asyncio.Event())
            print("ready", flush=True)
            time.sleep(30)  # something holds the event loop
        asyncio.run(main())
        """
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
        sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=5) == 0
        assert time.monotonic() - sent < 1.0
        assert proc.stderr is not None and "exiting now" in proc.stderr.read()
    finally:
        proc.kill()
        proc.wait()


class _FakeClock:
    """``time`` for the interpreter: each reading advances 100 µs; ``wait`` adds a gap."""

    def __init__(self) -> None:
        self.now = 100.0

    def perf_counter(self) -> float:
        self.now += 100e-6
        return self.now

    def wait(self, seconds: float) -> None:
        self.now += seconds


def test_back_to_back_cycles_get_a_smaller_time_budget(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    clock = _FakeClock()
    monkeypatch.setattr(interp, "time", clock)
    robot = robot_for(tmp_path, "LOOP\n  RI = RI + 1\nENDLOOP")
    prog = robot.program
    assert isinstance(prog, KrlProgram) and prog.interp is not None
    ran = []
    for gap in (0.012, 0.0, 0.0, 0.012):  # on time, two catch-up cycles, on time again
        clock.wait(gap)
        before = prog.interp.total
        prog.interp.step()
        ran.append(prog.interp.total - before)
    checks = [n // interp.CHECK_EVERY for n in ran]  # one clock reading per 64 statements
    # on time: 2 ms are over after 20 readings of 100 µs; back to back: the 0.5 ms floor, 5
    assert checks == [20, 5, 5, 20], ran
