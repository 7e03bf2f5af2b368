"""Snapshot SPS CPU benchmark: % of one core an emulator running a generated snapshot costs at rest.

Each scenario is one ``kukavarproxy-emu`` (``bench/_emu_server.py``, its own process) exactly as
README.md starts it: the default (dynamic, MuJoCo) plant, the ``follow`` program, real time,
12 ms IPO, nobody connected, the robot at rest. The figure is the process' CPU time over wall
time (% of one core). Scenarios:

* reference — the shipped SPS (``sps.sub``, Algorithm 4.11), no snapshot;
* README's snapshot — ``kvp snapshot krl CELL '$AXIS_ACT' '$POS_ACT' '$TORQUE_AXIS_ACT[]'``
  installed with ``--config CELL.dat --sps CELL.sub``;
* 20 variables — the snapshot of ``bench/snapshot.py`` (one structure, 20 variables).

A snapshot SPS copies the robot's readings every pass, and the dynamic plant's readings carry
fresh sensor noise every cycle: nothing of the pass repeats, unlike the shipped SPS at rest.
The target (≤ 1 % at rest) includes the process' whole wake-up cost. Also printed: the SPS
passes per simulated second (must be 1 / 12 ms: the pass counter never skips).

    .venv/bin/python bench/snapshot_cpu.py [--quick] [--seconds 10] [--repeat 3]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import EmuProcess, Row, base_parser, median, print_rows, write_json
from snapshot import NAMES as BENCH_NAMES

from pyopenshowvar import Snapshot, sync

TARGET = 1.0
README = ["$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[]"]


def _cpu_percent(args: list[str], seconds: float, snapshot: Snapshot | None) -> tuple[float, float]:
    """CPU % of one emulator at rest, and its SPS passes per simulated second (NaN: none)."""
    with EmuProcess(*args) as emu:
        time.sleep(min(seconds, 1.5))  # start-up done, the robot settled
        cycles = float("nan")
        if snapshot is not None:
            with sync.Client(emu.host, emu.port, timeout=5.0, keepalive=None) as kvp:
                first = kvp.read_snapshot(snapshot)
        cpu0, wall0 = emu.cpu_seconds(), time.perf_counter()
        time.sleep(seconds)
        cpu, wall = emu.cpu_seconds() - cpu0, time.perf_counter() - wall0
        if snapshot is not None:
            with sync.Client(emu.host, emu.port, timeout=5.0, keepalive=None) as kvp:
                last = kvp.read_snapshot(snapshot)
            # passes per second of wall time over the idle stretch: 1 / 12 ms in real time
            cycles = (last.cycle - first.cycle) / wall
    return 100.0 * cpu / wall, cycles


def run(quick: bool, seconds: float, repeat: int) -> tuple[list[Row], dict[str, Any]]:
    rows: list[Row] = []
    extra: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        scenarios: list[tuple[str, list[str], Snapshot | None]] = [
            ("reference: shipped SPS, no snapshot", [], None)
        ]
        for name, variables, label in (
            ("CELL", README, "README's snapshot (3 variables)"),
            ("BENCH", BENCH_NAMES, "20-variable snapshot"),
        ):
            snap = Snapshot(name, variables)
            dat, sub = snap.write_krl(Path(tmp, name))
            scenarios.append((label, ["--config", str(dat), "--sps", str(sub)], snap))
        for label, args, snap in scenarios:
            runs, rates = [], []
            for _ in range(repeat):
                pct, rate = _cpu_percent(args, seconds, snap)
                runs.append(pct)
                rates.append(rate)
            note = "runs: " + " / ".join(f"{x:.1f} %" for x in runs)
            if snap is not None:
                note += f"; SPS passes per second: {median(rates):.1f} (one per 12 ms: 83.3)"
            rows.append(
                Row(
                    f"CPU at rest, {label}",
                    median(runs),
                    "%",
                    target=("ours", "<=", TARGET) if snap is not None else None,
                    runs=runs,
                    note=note,
                )
            )
            extra[label] = {"runs": runs, "passes_per_s": rates}
    return rows, extra


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--seconds", type=float, default=10.0, help="wall seconds per measurement")
    args = ap.parse_args()
    seconds = 0.5 if args.quick else args.seconds
    repeat = args.repeat or (1 if args.quick else 3)
    rows, extra = run(args.quick, seconds, repeat)
    print_rows("Snapshot SPS at rest (% of one core, real time, the whole emulator process)", rows)
    write_json(args.json, "snapshot_cpu", rows, extra)


if __name__ == "__main__":
    main()
