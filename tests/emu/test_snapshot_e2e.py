"""Snapshots end to end: the generated KRL installed in the emulator as on a KRC, read by both
clients and by ``kvp snapshot``, with the robot moving (issue 11, item 1).

The emulator loads the generated ``.dat`` files with ``--config`` and runs one SPS holding the
copy folds of two snapshots, as a user pastes several folds into ``SPS.SUB``: ``ONE`` (one
structure, one request) and ``SPLIT`` (the same variables split by a small ``max_text``).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pyopenshowvar_apps.cli import EXIT_USAGE, app
from typer.testing import CliRunner

from kukavarproxy_emu.emulator_thread import EmulatorThread
from kukavarproxy_emu.testing import TEST_CONFIG
from pyopenshowvar import (
    Client,
    E6Axis,
    E6Pos,
    KrlValueError,
    Snapshot,
    SnapshotLimits,
    UnknownVariableError,
    sync,
)
from pyopenshowvar.kinematics import KR6R900SIXX, forward
from pyopenshowvar.snapshot_krl import copy_fold

NAMES = [
    "$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[]", "$VEL_ACT", "$OV_PRO", "$MODE_OP",
    "$PRO_STATE1", "$OUT[1]", "$TIMER[1]", ("MYINT", "INT"), ("MYPOS", "POS"),
]  # fmt: skip
ONE = Snapshot("ONE", NAMES)
SPLIT = Snapshot("SPLIT", NAMES, limits=SnapshotLimits(max_text=700))
FAR = "{A1 60.0, A2 -60.0, A3 60.0, A4 40.0, A5 40.0, A6 60.0}"
runner = CliRunner()


@pytest.fixture(scope="module")
def emu(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmulatorThread]:
    out = tmp_path_factory.mktemp("snap")
    dats = [s.write_krl(out)[0] for s in (ONE, SPLIT)]
    sps = out / "cell.sub"
    sps.write_text(
        "\n".join(["DEF CELL()", "  LOOP", *copy_fold(ONE), *copy_fold(SPLIT), "  ENDLOOP", "END"])
    )
    config = replace(TEST_CONFIG, plant="ideal", config_files=tuple(dats), sps=str(sps))
    with EmulatorThread(config) as thread:
        with sync.Client(thread.host, thread.port, keepalive=None) as kvp:
            for _ in range(200):  # the first SPS pass fills the snapshots
                if kvp.read_many(["ONE", "SPLIT"])["SPLIT"].ok:
                    break
                time.sleep(0.01)
            assert kvp.read("$PRO_STATE0") == "#P_ACTIVE", kvp.read("$EMU_MESSAGE[]")
        yield thread


def _fk_error(reading: Any) -> float:
    axis, pos = reading["$AXIS_ACT"], reading["$POS_ACT"]
    assert isinstance(axis, E6Axis) and isinstance(pos, E6Pos)
    xyz = forward(KR6R900SIXX, axis.to_numpy())[:3]
    return float(np.linalg.norm(np.asarray(xyz) - pos.to_numpy()[:3]))


def test_sync_client_reads_one_structure_in_one_request(emu: EmulatorThread) -> None:
    assert ONE.read_names == ("ONE",) and len(SPLIT.read_names) > 1
    with sync.Client(emu.host, emu.port, timeout=2.0, keepalive=None) as kvp:
        kvp.write("MYINT", 42)
        first = kvp.read_snapshot(ONE)  # may be the pass before the write: at most one old
        before = emu.emulator.stats.requests
        reading = kvp.read_snapshot(ONE)
        assert emu.emulator.stats.requests - before == 1, emu.emulator.stats
        for _ in range(200):  # the next pass after the write copies it
            if reading.cycle > first.cycle:
                break
            time.sleep(0.005)
            reading = kvp.read_snapshot(ONE)
    assert tuple(reading) == ONE.names and reading["$OV_PRO"] == 100
    assert reading.cycle > first.cycle and reading["MYINT"] == 42
    assert str(reading["$MODE_OP"]) == "#AUT" and reading["$OUT[1]"] is False
    torques = reading["$TORQUE_AXIS_ACT[]"]
    assert isinstance(torques, list) and len(torques) == 12
    assert torques[1] == pytest.approx(-24.78, abs=0.01)  # A2 holding torque at HOME


async def test_asyncio_client_sees_one_cycle_while_the_robot_moves(emu: EmulatorThread) -> None:
    async with Client(emu.host, emu.port, timeout=2.0, keepalive=None) as kvp:
        await kvp.write("MYAXIS", FAR)
        readings = []
        for _ in range(12):
            readings.append(await kvp.read_snapshot(ONE))
            await asyncio.sleep(0.02)
        split = await kvp.read_snapshot(SPLIT)
        await kvp.write("MYAXIS", "{A1 0.0, A2 -90.0, A3 90.0, A4 0.0, A5 0.0, A6 0.0}")
    moving = [r for r in readings if r["$VEL_ACT"] != 0.0]
    assert len(moving) >= 3, "the robot did not move"
    a1 = [float(r["$AXIS_ACT"]["A1"]) for r in moving]  # type: ignore[index]
    assert len(set(a1)) > 1
    # every copy in a snapshot comes from one cycle: $POS_ACT is the FK of $AXIS_ACT
    assert max(_fk_error(r) for r in readings) < 1e-3
    cycles = [r.cycle for r in readings]
    assert cycles == sorted(cycles) and cycles[-1] > cycles[0]
    # the split snapshot: parts from one pass (parse checks the counters), same values' types
    assert _fk_error(split) < 1e-3 and tuple(split) == SPLIT.names


def test_errors_say_what_is_wrong(emu: EmulatorThread) -> None:
    with sync.Client(emu.host, emu.port, timeout=2.0, keepalive=None) as kvp:
        with pytest.raises(UnknownVariableError, match="install its KRL"):
            kvp.read_snapshot(Snapshot("NOPE", ["$OV_PRO"]))
        other = Snapshot("ONE", ["$OV_PRO", "$VEL_ACT"])  # not what the controller runs
        with pytest.raises(KrlValueError, match="does not match this definition"):
            kvp.read_snapshot(other)


def test_kvp_snapshot_krl_and_read(emu: EmulatorThread, tmp_path: Path) -> None:
    res = runner.invoke(
        app, ["snapshot", "krl", "ONE", "$AXIS_ACT", "MYPOS:POS", "--out", str(tmp_path)]
    )
    assert res.exit_code == 0, res.output
    assert (tmp_path / "ONE.dat").read_bytes().count(b"\r\n") > 5  # CRLF, as a KRC expects
    assert "one request per snapshot" in res.output
    res = runner.invoke(app, ["snapshot", "krl", "ONE", "MYVAR", "--out", str(tmp_path)])
    assert res.exit_code == EXIT_USAGE and "MYVAR:REAL" in res.output
    specs = [n if isinstance(n, str) else f"{n[0]}:{n[1]}" for n in NAMES]
    res = runner.invoke(app, ["--port", str(emu.port), "snapshot", "read", "ONE", *specs])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert lines[0].startswith("CYCLE ") and lines[1].startswith("$AXIS_ACT {E6AXIS: A1")
    torques = next(line for line in lines if line.startswith("$TORQUE_AXIS_ACT[] "))
    assert len(torques.split()) == 13  # the name and twelve values


async def test_a_snapshot_is_readable_by_the_first_client_however_soon(tmp_path: Path) -> None:
    """The emulator serves only once its first IPO cycle ran, as a running KRC: a script that
    starts it and reads at once gets a filled snapshot, not "not readable"."""
    from kukavarproxy_emu import Emulator

    dat, sub = ONE.write_krl(tmp_path)
    config = replace(TEST_CONFIG, config_files=(dat,), sps=str(sub))
    async with Emulator(config) as emu, Client("127.0.0.1", emu.port, keepalive=None) as kvp:
        reading = await kvp.read_snapshot(ONE)
    assert reading.cycle >= 1
