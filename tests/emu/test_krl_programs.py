"""The shipped KRL programs and users' own .src files, driven over real TCP at 20× speed."""

from __future__ import annotations

import asyncio
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from kukavarproxy_emu.__main__ import main
from kukavarproxy_emu.config import EmulatorConfig
from kukavarproxy_emu.krl.parser import KrlSyntaxError
from kukavarproxy_emu.server import Emulator
from kukavarproxy_emu.testing import EmulatorFactory
from pyopenshowvar import Client
from pyopenshowvar.kinematics import KR6R900SIXX, forward

SPEED = 20.0
HOME = np.array([0.0, -90.0, 90.0, 0.0, 0.0, 0.0])


async def wait_for(cond: Any, timeout: float = 8.0) -> None:
    async with asyncio.timeout(timeout):
        while not await cond():  # noqa: ASYNC110 - polling over KVP is what a client does
            await asyncio.sleep(0.002)


def axis_text(q: np.ndarray) -> str:
    return "{" + ", ".join(f"A{i + 1} {v!r}" for i, v in enumerate(q.tolist())) + "}"


async def test_follow_src_follows_myaxis(emulator_factory: Any) -> None:
    emu = await emulator_factory(speed=SPEED, program="follow")
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        assert await kvp.read("$PRO_NAME1[]") == '"FOLLOW"'
        assert await kvp.read("$PRO_STATE1") == "#P_ACTIVE"
        for a1 in (25.0, -15.0):
            await kvp.write("MYAXIS", f"{{A1 {a1}}}")

            async def arrived(a1: float = a1) -> bool:
                return float(await kvp.read("$AXIS_ACT.A1")) == a1 and not emu.robot.kernel.moving

            await wait_for(arrived)
    np.testing.assert_array_equal(emu.robot.q, [-15.0, -90.0, 90.0, 0.0, 0.0, 0.0])


async def test_joint_path_visits_every_point_in_order(emulator_factory: Any) -> None:
    emu = await emulator_factory(speed=SPEED, program="joint_path")
    emu.robot.kernel.trace = []
    offsets = [(20, 0, 0), (20, 15, 0), (-10, 15, -10), (-10, 0, 0)]
    points = [HOME + np.array([a, b, c, 0, 0, 0], dtype=float) for a, b, c in offsets]
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        for i, p in enumerate(points, start=1):
            await kvp.write(f"MYE6ARRAY[{i}]", axis_text(p))
        await kvp.write("PATH_COUNT", str(len(points)))
        await kvp.write("PATH_START", "TRUE")
        seen: list[int] = []

        async def done() -> bool:
            seen.append(int(await kvp.read("PATH_INDEX")))
            return await kvp.read("PATH_DONE") == "TRUE"

        await wait_for(done)
        assert await kvp.read("PATH_BUSY") == "FALSE" and await kvp.read("PATH_START") == "FALSE"
    assert seen == sorted(seen) and seen[-1] == len(points)
    qs = np.array([q for _t, q, _qd in emu.robot.kernel.trace])
    closest = [int(np.argmin(np.linalg.norm(qs - p, axis=1))) for p in points]
    assert closest == sorted(closest)  # in order...
    dists = [float(np.linalg.norm(qs[i] - p)) for i, p in zip(closest, points, strict=True)]
    assert max(dists[:-1]) < 10.0 and dists[-1] == 0.0  # ...near each, exactly on the last
    np.testing.assert_array_equal(emu.robot.q, points[-1])


async def test_actuator_keeps_moving_for_queued_increments(emulator_factory: Any) -> None:
    emu = await emulator_factory(plant="ideal", speed=SPEED, program="actuator")
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        await wait_for(lambda: _eq(kvp, "$ADVANCE", "1"))
        await kvp.write("$OV_PRO", "10")  # slow increments: the test sees them queue up
        x0 = float(await kvp.read("$POS_ACT.X"))
        await kvp.write("MYPOS", "{X 2.0}")
        await wait_for(lambda: _gt(kvp, "$POS_ACT.X", x0 + 4.0))
        await kvp.write("MYPOS", "{X 0.0}")
        kernel = emu.robot.kernel  # no await below: one consistent in-process snapshot
        planned_at_zero = float(kernel.planned_pose()[0])
        x_zero = float(forward(KR6R900SIXX, kernel.q)[0])
        queued = kernel.queued
        await wait_for(lambda: _still(emu))
        x1 = float(await kvp.read("$POS_ACT.X"))
    steps = (x1 - x0) / 2.0
    assert steps == pytest.approx(round(steps), abs=1e-3)  # whole increments only
    # it moved on after MYPOS was zeroed, to the end of what was planned: the running
    # increment plus at most $ADVANCE (= 1) queued one
    assert queued <= 1
    assert x_zero < x1 <= x_zero + 2.0 * 2 + 1e-3
    assert x1 == pytest.approx(planned_at_zero, abs=1e-3)


async def test_ext_move_axis_assigns_myaxis(emulator_factory: Any) -> None:
    emu = await emulator_factory(speed=SPEED, program="ext_move_axis")
    target = HOME + np.array([10.0, 5.0, -5.0, 20.0, 15.0, -30.0])
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        assert await kvp.read("$PRO_NAME1[]") == '"EXT_MOVE_AXIS"'
        await kvp.write("MYAXIS", axis_text(target))
        await wait_for(lambda: _still_at(emu, target))
        assert await kvp.read("$ADVANCE") == "1"


async def test_sps_copies_output_vars_over_kvp(emulator_factory: Any) -> None:
    emu = await emulator_factory(speed=SPEED)
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        assert await kvp.read("$PRO_STATE0") == "#P_ACTIVE"
        await kvp.write("OUTPUT_VARS[3]", "TRUE")
        await wait_for(lambda: _eq(kvp, "$OUT[3]", "TRUE"))
        await kvp.write("OUTPUT_VARS[3]", "FALSE")
        await wait_for(lambda: _eq(kvp, "$OUT[3]", "FALSE"))


async def test_user_program_and_dat_from_a_temp_dir(emulator_factory: Any, tmp_path: Path) -> None:
    (tmp_path / "pick.src").write_text(
        """&ACCESS RVP
DEF PICK()
  DECL INT I
  DECL AXIS D
  LOOP
    WAIT FOR GO
    GO = FALSE
    D.A1 = STEP_DEG
    FOR I = 1 TO NPTS
      PTP_REL D C_PTP
    ENDFOR
    WAIT SEC 0
    CYCLES = CYCLES + 1
  ENDLOOP
END
"""
    )
    (tmp_path / "pick.dat").write_text(
        "DEFDAT PICK\nDECL BOOL GO=FALSE\nDECL INT NPTS=3\nDECL REAL STEP_DEG=5.0\n"
        "DECL INT CYCLES=0\nENDDAT\n"
    )
    emu = await emulator_factory(plant="ideal", speed=SPEED, program=str(tmp_path / "pick.src"))
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        assert await kvp.read("$PRO_NAME1[]") == '"PICK"'
        await kvp.write("GO", "TRUE")
        await wait_for(lambda: _eq(kvp, "CYCLES", "1"))
        assert float(await kvp.read("$AXIS_ACT.A1")) == 15.0
        await kvp.write("STEP_DEG", "-10")
        await kvp.write("GO", "TRUE")
        await wait_for(lambda: _eq(kvp, "CYCLES", "2"))
        assert float(await kvp.read("$AXIS_ACT.A1")) == -15.0


async def test_runtime_error_is_readable_and_server_keeps_serving(
    emulator_factory: Any, tmp_path: Path
) -> None:
    (tmp_path / "oops.src").write_text(
        "DEF OOPS()\n  DECL E6AXIS T\n  PTP {A1 30}\n  T = $AXIS_ACT\n  MYINT = MYINT + 1\n"
        "  T.A1 = MYINT * 200\n  PTP T\nEND\n"
    )
    emu = await emulator_factory(plant="ideal", speed=SPEED, program=str(tmp_path / "oops.src"))
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        await wait_for(lambda: _eq(kvp, "$PRO_STATE1", "#P_STOP"))
        message = await kvp.read("$EMU_MESSAGE[]")
        assert "oops.src:7:" in message and "Software limit switch +A1" in message
        assert await kvp.read("$STOPMESS") == "TRUE"
        await wait_for(lambda: _still(emu))
        assert float(await kvp.read("$AXIS_ACT.A1")) == 30.0  # the valid move ended exactly
        await kvp.write("MYINT", "-1")
        await kvp.write("EMU_RESTART", "TRUE")
        await wait_for(lambda: _eq(kvp, "$PRO_STATE1", "#P_END"))
        assert await kvp.read("$EMU_MESSAGE[]") == '""'
        assert float(await kvp.read("$AXIS_ACT.A1")) == 0.0  # MYINT = 0 -> A1 0
        assert await kvp.read("$OV_PRO") == "100"  # still serving


async def test_runaway_loop_does_not_starve_the_server(
    emulator_factory: Any, tmp_path: Path
) -> None:
    (tmp_path / "spin.src").write_text(
        "DEF SPIN()\n  DECL INT N\n  N = 0\n  LOOP\n    N = N + 1\n    MYINT = N\n  ENDLOOP\nEND\n"
    )
    emu = await emulator_factory(speed=SPEED, program=str(tmp_path / "spin.src"))
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        await wait_for(lambda: _gt(kvp, "MYINT", 1000))
        worst = 0.0
        for _ in range(30):
            t0 = time.perf_counter()
            await kvp.read("$AXIS_ACT")
            worst = max(worst, time.perf_counter() - t0)
        assert worst < 0.1  # a cycle spends at most 2 ms on statements
        assert await kvp.read("$PRO_STATE1") == "#P_ACTIVE"
        a = int(await kvp.read("MYINT"))
        await asyncio.sleep(0.05)
        assert int(await kvp.read("MYINT")) > a  # still running


async def test_syntax_error_is_raised_at_emulator_start(tmp_path: Path) -> None:
    bad = tmp_path / "bad.src"
    bad.write_text("DEF BAD()\n  LOOP\n    PTP MYAXIS C_PTP\n  ENDLLOOP\nEND\n")
    emu = Emulator(EmulatorConfig(port=0, discovery=False, program=str(bad)))
    with pytest.raises(KrlSyntaxError, match=r"bad\.src:4:"):
        await emu.start()


def test_cli_syntax_error_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.src"
    bad.write_text("DEF BAD()\n  X = = 1\nEND\n")
    assert main(["--port", "0", "--no-discovery", "--program", str(bad)]) == 1
    assert "bad.src:2:" in capsys.readouterr().err
    assert main(["--port", "0", "--no-discovery", "--program", str(tmp_path / "no.src")]) == 1


# --- helpers --------------------------------------------------------------------------------
async def _eq(kvp: Client, name: str, text: str) -> bool:
    return await kvp.read(name) == text


async def _gt(kvp: Client, name: str, value: float) -> bool:
    return float(await kvp.read(name)) > value


async def _still(emu: Emulator) -> bool:
    assert emu.robot is not None
    return not emu.robot.kernel.moving and not np.any(emu.robot.kernel.qd)


async def _still_at(emu: Emulator, q: np.ndarray) -> bool:
    assert emu.robot is not None
    return await _still(emu) and bool(np.allclose(emu.robot.q, q, atol=1e-9))


@pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning")
async def test_restarting_a_running_submit_interpreter_leaves_no_stale_frames(
    emulator_factory: EmulatorFactory,
) -> None:
    """The C3 cancel and start of the submit interpreter restart it while its main routine
    runs: the old run is unwound at once. Left to the garbage collector, its ``finally``
    clauses popped the new run's frames ("IndexError: pop from empty list", ignored)."""
    import gc

    from pyopenshowvar.c3 import Interpreter

    emu = await emulator_factory(proxy="c3bridge", plant="ideal")
    unraisable: list[object] = []
    old_hook = sys.unraisablehook
    sys.unraisablehook = unraisable.append
    try:
        async with Client(emu.host, emu.port) as kvp:
            for _ in range(3):
                await kvp.program_cancel(Interpreter.SUBMIT)
                await kvp.program_start(Interpreter.SUBMIT)
                gc.collect()
                assert (await kvp.program_state()).submit_state == "P_ACTIVE"
    finally:
        sys.unraisablehook = old_hook
    assert not unraisable, unraisable
