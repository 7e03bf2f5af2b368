"""The KRL executor without sockets: a Robot on a plain store, ticked by hand (exact time)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
import pytest

from kukavarproxy_emu.krl.executor import KrlProgram, load_module
from kukavarproxy_emu.krl.parser import KrlSyntaxError
from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.store import VariableStore

IPO = 0.012
HOME = np.array([0.0, -90.0, 90.0, 0.0, 0.0, 0.0])
DAT = """
DEFDAT $CONFIG
DECL INT RI=0
DECL REAL RR=0.0
DECL BOOL RB=FALSE
DECL INT RA[5]
RA[1]=0
RA[2]=0
RA[3]=0
RA[4]=0
RA[5]=0
DECL REAL RT=0.0
DECL CHAR RS[16]
ENDDAT
"""


def robot_for(tmp_path: Path, body: str, *, name: str = "T", extra: str = "") -> Robot:
    """A Robot running ``DEF T() <body> END`` (+ ``extra`` routines) from a temp file."""
    src = tmp_path / f"{name.lower()}.src"
    text = f"DEF {name}()\n{textwrap.dedent(body)}\nEND\n{textwrap.dedent(extra)}"
    src.write_text(text, encoding="latin-1")
    store = VariableStore()
    store.load_dat(DAT)
    robot = Robot(store, program=str(src))
    robot._begin()
    robot.kernel.trace = []
    return robot


def run(robot: Robot, ticks: int = 1) -> None:
    for _ in range(ticks):
        robot.tick()


def run_to_end(robot: Robot, limit: int = 5000) -> None:
    for _ in range(limit):
        robot.tick()
        if robot.store.read("$PRO_STATE1") != "#P_ACTIVE":
            return
    raise AssertionError("program did not end")


def g(robot: Robot, name: str) -> object:
    return robot.store.get(name)


# --- expressions, types, functions --------------------------------------------------------------
def test_arithmetic_types_and_functions(tmp_path: Path) -> None:
    robot = robot_for(
        tmp_path,
        """
        DECL INT I
        DECL REAL X
        I = 7 / 2
        RI = I * 10 + -7 / 2
        RR = 7 / 2.0
        I = 2.5
        RA[1] = I
        I = -2.5
        RA[2] = I
        RA[3] = ABS(-4) + SQRT(16)
        RT = SIN(30) + COS(60) + TAN(45) + ATAN2(1, 1)
        RB = (RI > 20) AND NOT (RR < 3.0) EXOR FALSE OR (RA[1] == 3)
        X = 1
        RA[4] = 'B1010' B_AND 'H0F'
        RS[] = "hi"
        """,
    )
    run_to_end(robot)
    assert robot.store.read("$PRO_STATE1") == "#P_END"
    assert g(robot, "RI") == 30 - 3  # INT/INT truncates towards zero
    assert g(robot, "RR") == 3.5
    assert g(robot, "RA[1]") == 3 and g(robot, "RA[2]") == -3  # REAL -> INT rounds half away
    assert g(robot, "RA[3]") == 8
    assert g(robot, "RT") == pytest.approx(0.5 + 0.5 + 1.0 + 45.0)
    assert g(robot, "RB") is True
    assert g(robot, "RA[4]") == 10
    assert g(robot, "RS[]") == "hi"


def test_control_flow_statements(tmp_path: Path) -> None:
    robot = robot_for(
        tmp_path,
        """
        DECL INT I, N
        N = 0
        FOR I = 1 TO 10 STEP 3
          N = N + I
        ENDFOR
        RA[1] = N
        FOR I = 5 TO 1 STEP -2
          RA[2] = I
        ENDFOR
        N = 0
        WHILE N < 5
          N = N + 1
        ENDWHILE
        RA[3] = N
        REPEAT
          N = N - 2
        UNTIL N < 0
        RA[4] = N
        N = 0
        LOOP
          N = N + 1
          IF N >= 4 THEN
            EXIT
          ELSE
            RI = N
          ENDIF
        ENDLOOP
        SWITCH N
        CASE 1, 2
          RA[5] = 12
        CASE 4
          RA[5] = 4
        DEFAULT
          RA[5] = -1
        ENDSWITCH
        SWITCH 99
        CASE 1
          RB = FALSE
        DEFAULT
          RB = TRUE
        ENDSWITCH
        """,
    )
    run_to_end(robot)
    assert [g(robot, f"RA[{i}]") for i in range(1, 6)] == [1 + 4 + 7 + 10, 1, 5, -1, 4]
    assert g(robot, "RI") == 3 and g(robot, "RB") is True


def test_subroutines_deffct_and_out_parameters(tmp_path: Path) -> None:
    robot = robot_for(
        tmp_path,
        """
        DECL INT K
        K = 5
        BUMP(K, 10)
        RI = K
        RR = SQUARE(3) + SQUARE(0.5)
        RA[1] = FACT(5)
        """,
        extra="""
        DEF BUMP(V:OUT, BY:IN)
          DECL INT V, BY
          V = V + BY
          RETURN
          V = -1000
        END

        DEFFCT REAL SQUARE(X:IN)
          DECL REAL X
          RETURN X * X
        ENDFCT

        DEFFCT INT FACT(N:IN)
          DECL INT N
          IF N <= 1 THEN
            RETURN 1
          ENDIF
          RETURN N * FACT(N - 1)
        ENDFCT
        """,
    )
    run_to_end(robot)
    assert g(robot, "RI") == 15
    assert g(robot, "RR") == 9.25
    assert g(robot, "RA[1]") == 120


def test_locals_structs_enums_and_global_aliasing(tmp_path: Path) -> None:
    robot = robot_for(
        tmp_path,
        """
        DECL AXIS LOCAL
        DECL E6POS P
        DECL POS Q
        LOCAL = {A1 1, A2 -90, A3 90, A4 0, A5 0, A6 0}
        LOCAL.A1 = LOCAL.A1 + 2
        RR = LOCAL.A1
        P = $POS_ACT
        Q = P
        RT = Q.Z
        RB = $MODE_OP == #AUT
        """,
    )
    run_to_end(robot)
    assert g(robot, "RR") == 3.0
    assert g(robot, "RT") == pytest.approx(float(robot.store.read("$POS_ACT.Z")))
    assert g(robot, "RB") is True


def test_wait_sec_takes_simulated_time(tmp_path: Path) -> None:
    robot = robot_for(tmp_path, "RI = 1\nWAIT SEC 0.5\nRI = 2")
    run(robot)
    t0 = robot.time
    assert g(robot, "RI") == 1
    while g(robot, "RI") != 2:
        robot.tick()
    assert robot.time - t0 == pytest.approx(0.5, abs=IPO + 1e-9)


def test_wait_for_is_reevaluated_every_cycle(tmp_path: Path) -> None:
    robot = robot_for(tmp_path, "WAIT FOR RB\nRI = 7")
    run(robot, 20)
    assert g(robot, "RI") == 0 and robot.store.read("$PRO_STATE1") == "#P_ACTIVE"
    robot.store.write("RB", "TRUE")
    run(robot, 2)
    assert g(robot, "RI") == 7


def test_halt_stops_the_program(tmp_path: Path) -> None:
    robot = robot_for(tmp_path, "RI = 1\nHALT\nRI = 2")
    run(robot, 5)
    assert robot.store.read("$PRO_STATE1") == "#P_STOP" and g(robot, "RI") == 1
    assert "HALT" in robot.store.read("$EMU_MESSAGE[]")


def test_timers_count_simulated_milliseconds(tmp_path: Path) -> None:
    robot = robot_for(
        tmp_path, "$TIMER[1] = 0\n$TIMER_STOP[1] = FALSE\nWAIT SEC 1.2\nRI = $TIMER[1]"
    )
    run_to_end(robot)
    assert abs(int(g(robot, "RI")) - 1200) <= 2 * 12  # type: ignore[call-overload]


# --- motions and the advance run ----------------------------------------------------------------
def test_motions_inline_home_ptp_rel_and_lin(tmp_path: Path) -> None:
    robot = robot_for(
        tmp_path,
        """
        PTP {A1 10, A2 -80, A3 80, A4 0, A5 30, A6 0}
        PTP_REL {A1 5}
        LIN_REL {Z -20}
        RR = $AXIS_ACT.A1
        PTP HOME Vel = 50 % DEFAULT
        """,
    )
    run_to_end(robot)
    assert robot.store.read("$PRO_STATE1") == "#P_END"
    np.testing.assert_allclose(robot.q, HOME, atol=1e-9)
    assert g(robot, "RR") == pytest.approx(15.0, abs=1e-6)
    assert g(robot, "$VEL_AXIS[1]") == 50


def test_advance_run_plans_ahead_and_stops_on_pos_act(tmp_path: Path) -> None:
    robot = robot_for(
        tmp_path,
        """
        $ADVANCE = 2
        PTP {A1 10}
        RA[1] = 1
        PTP {A1 20}
        RA[2] = 1
        PTP {A1 30}
        RA[3] = 1
        RR = $POS_ACT.X
        RA[4] = 1
        """,
    )
    run(robot)
    # the advance run has planned the motions and run the assignments between them...
    assert [g(robot, f"RA[{i}]") for i in (1, 2, 3)] == [1, 1, 1]
    # ...but reading $POS_ACT waits until the robot has arrived (advance-run stop)
    assert g(robot, "RA[4]") == 0
    while g(robot, "RA[4]") == 0:
        robot.tick()
        if g(robot, "RA[4]") == 0:
            assert robot.kernel.moving or robot.q[0] == 30.0
    assert robot.q[0] == 30.0
    assert g(robot, "RR") == pytest.approx(float(robot.store.read("$POS_ACT.X")))


def test_advance_limits_the_look_ahead(tmp_path: Path) -> None:
    robot = robot_for(
        tmp_path,
        """
        DECL INT I
        $ADVANCE = 1
        FOR I = 1 TO 5
          RI = I
          PTP_REL {A1 5} C_PTP
        ENDFOR
        """,
    )
    run(robot)
    # one motion runs, one waits behind it; the FOR stands at the third
    assert robot.kernel.queued <= 1 and g(robot, "RI") == 3
    run_to_end(robot)
    assert robot.q[0] == pytest.approx(25.0)


def test_runaway_loop_is_budgeted(tmp_path: Path) -> None:
    robot = robot_for(tmp_path, "LOOP\nRI = RI + 1\nENDLOOP")
    prog = robot.program
    assert isinstance(prog, KrlProgram) and prog.interp is not None
    run(robot, 3)
    n = g(robot, "RI")
    assert isinstance(n, int) and 0 < n <= 3 * prog.budget
    assert robot.store.read("$PRO_STATE1") == "#P_ACTIVE"


# --- errors ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("body", "text"),
    [
        ("NOPE = 1", "NOPE is not declared"),
        ("RB = 1", "type mismatch"),
        ("RI = TRUE", "type mismatch"),
        ("RA[6] = 1", "index 6 out of range 1..5"),
        ("RI = 1 / 0", "division by zero"),
        ("RI = MYE6ARRAY[2].A1", "MYE6ARRAY[2].A1 is not initialised"),
        ("PTP {A1 171}", "Software limit switch +A1"),
        ("LIN {X 1500, Y 0, Z 890, A 0, B 90, C 0}", "not reachable"),
        ("$AXIS_ACT = $AXIS_ACT", "write-protected"),
        ("RR = SQRT(-1)", "SQRT"),
    ],
)
def test_runtime_errors_stop_the_program_with_file_and_line(
    tmp_path: Path, body: str, text: str
) -> None:
    robot = robot_for(tmp_path, f"RI = 1\n{body}\nRI = 2")
    run(robot, 5)
    store = robot.store
    assert store.read("$PRO_STATE1") == "#P_STOP" and store.read("$STOPMESS") == "TRUE"
    message = store.read("$EMU_MESSAGE[]")
    assert "t.src:3:" in message and text in message
    assert g(robot, "RI") == 1
    # EMU_RESTART restarts from the top (and fails the same way again)
    store.write("EMU_RESTART", "TRUE")
    robot.tick()
    assert g(robot, "RI") == 1 and store.read("$PRO_STATE1") == "#P_STOP"


def test_syntax_error_names_file_line_and_column(tmp_path: Path) -> None:
    src = tmp_path / "bad.src"
    src.write_text("DEF BAD()\n  RI = (1 +\nEND\n")
    with pytest.raises(KrlSyntaxError, match=r"bad\.src:2:\d+"):
        load_module(src)
    with pytest.raises(KrlSyntaxError):
        Robot(VariableStore(), program=str(src))


def test_own_dat_is_loaded_next_to_the_src(tmp_path: Path) -> None:
    (tmp_path / "mine.dat").write_text("DEFDAT MINE\nDECL INT COUNTER=41\nENDDAT\n")
    robot = robot_for(tmp_path, "COUNTER = COUNTER + 1", name="MINE")
    run_to_end(robot)
    assert robot.store.read("COUNTER") == "42"
    assert robot.store.read("$PRO_NAME1[]") == '"MINE"'


def test_submit_interpreter_runs_its_loop_once_per_cycle(tmp_path: Path) -> None:
    sub = tmp_path / "mysps.sub"
    sub.write_text("DEF MYSPS()\nLOOP\nRI = RI + 1\n$OUT[7] = RB\nENDLOOP\nEND\n")
    store = VariableStore()
    store.load_dat(DAT)
    robot = Robot(store, program="none", sps=str(sub))
    robot._begin()
    run(robot, 10)
    assert g(robot, "RI") == 10
    store.write("RB", "TRUE")
    robot.tick()
    assert store.read("$OUT[7]") == "TRUE"
    assert store.read("$PRO_STATE0") == "#P_ACTIVE" and store.read("$PRO_NAME0[]") == '"MYSPS"'


def test_submit_error_stops_only_the_sps(tmp_path: Path) -> None:
    sub = tmp_path / "bad.sub"
    sub.write_text("DEF BADSPS()\nLOOP\nRI = RB\nENDLOOP\nEND\n")
    store = VariableStore()
    store.load_dat(DAT)
    robot = Robot(store, program="follow", sps=str(sub))
    robot._begin()
    run(robot, 3)
    assert store.read("$PRO_STATE0") == "#P_STOP" and store.read("$PRO_STATE1") == "#P_ACTIVE"
    assert "bad.sub:3:" in store.read("$EMU_MESSAGE[]")
