"""Plant CPU benchmark: % of one core a simulated robot costs, at rest and moving, per plant.

One robot (``kukavarproxy_emu.robot_task.Robot``, no program, no SPS) runs on its real-time IPO
clock (12 ms, ``speed = 1``) in an asyncio loop for ``--seconds`` per scenario; the figure is
process CPU time / wall time. Scenarios: at rest and moving (back-to-back 100 % PTPs between
two poses), each without a reader and with one that reads ``$AXIS_ACT`` and
``$TORQUE_AXIS_ACT[]`` every cycle (in process, so the TCP server's cost is not counted; the
dynamic plant computes its readings only when they are read). The targets are the emulator's:
≤ 1 % of a core per robot at rest and ≤ 5 % moving (50 robots in one process).
``--robot NAME|FILE`` simulates that KUKA arm instead of the KR 6 (its own plant model file,
limits and speeds, as ``kukavarproxy-emu --robot``; the two poses are clipped 5° inside its
limits); ``--plant`` runs one plant only.

    .venv/bin/python bench/plant_cpu.py [--quick] [--seconds 4] [--robot kr16_r2010_2]
        [--plant dynamic] [--json PATH]
"""

from __future__ import annotations

import asyncio
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import Row, base_parser, print_rows, write_json

from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.robots import resolve_robot
from kukavarproxy_emu.store import VariableStore

POSES = (
    np.array([-60.0, -60.0, 80.0, -90.0, -40.0, -120.0]),
    np.array([60.0, -100.0, 110.0, 90.0, 40.0, 120.0]),
)
TARGETS = {"rest": 1.0, "moving": 5.0}


async def cpu_percent(
    plant: str, moving: bool, reader: bool, seconds: float, arm: str = ""
) -> float:
    """CPU % of one robot (the arm ``arm``, "" = the KR 6); ``plant = "clock"``: the IPO clock
    alone (an empty cycle)."""
    spec = resolve_robot(arm)
    store = VariableStore(overrides=spec.sysvar_overrides())
    kind = "ideal" if plant == "clock" else plant
    robot = Robot(
        store, program="none", sps=None, plant=kind, seed=1, model=spec.model,
        machine=spec.machine, plant_params=spec.plant_params,
    )  # fmt: skip
    lo, hi = spec.model.lower + 5.0, spec.model.upper - 5.0
    poses = tuple(np.clip(p, lo, hi) for p in POSES)
    kernel, tick = robot.kernel, robot.tick
    turn = [0]

    def cycle() -> None:
        if plant == "clock":
            return
        if moving and not kernel.moving:
            kernel.ptp(poses[turn[0] % 2])
            turn[0] += 1
        tick()
        if reader:
            store.read("$AXIS_ACT")
            store.read("$TORQUE_AXIS_ACT[]")

    robot.clock.callback = cycle
    robot.start()
    await asyncio.sleep(min(0.3, seconds))  # warm-up: imports, first motion planned
    cpu0, wall0 = time.process_time(), time.perf_counter()
    await asyncio.sleep(seconds)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    await robot.stop()
    return 100.0 * cpu / wall


async def main_async(
    seconds: float, arm: str = "", plants: tuple[str, ...] = ("ideal", "dynamic")
) -> list[Row]:
    base = await cpu_percent("clock", False, False, seconds, arm)
    rows = [
        Row(
            "asyncio loop + 12 ms IPO clock alone (empty cycle)",
            base,
            "%",
            note=(
                "included in every figure below but the robots at rest that coast"
                " (woken once per 8 cycles; docs/emulator-robot.md)"
            ),
        )
    ]
    for state in ("rest", "moving"):
        for plant in plants:
            for reader in (False, True):
                pct = await cpu_percent(plant, state == "moving", reader, seconds, arm)
                who = "a reader every cycle" if reader else "no reader"
                rows.append(
                    Row(
                        f"{plant} plant, {state}, {who}",
                        pct,
                        "%",
                        target=("ours", "<=", TARGETS[state]),
                        note="target per robot, here with this process' whole 12 ms wake-up floor"
                        " (first row); per robot in a cell: bench/cell_cpu.py"
                        if plant == "dynamic" and not reader
                        else "",
                    )
                )
    return rows


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--seconds", type=float, default=4.0, help="wall seconds per scenario")
    ap.add_argument("--robot", default="", help="KUKA arm: catalogue name or file (default KR 6)")
    ap.add_argument("--plant", choices=("ideal", "dynamic", "both"), default="both")
    args = ap.parse_args()
    seconds = 0.2 if args.quick else args.seconds
    plants = ("ideal", "dynamic") if args.plant == "both" else (args.plant,)
    rows = asyncio.run(main_async(seconds, args.robot, plants))
    arm = resolve_robot(args.robot).model.name
    print_rows(f"CPU of one simulated {arm} (% of one core, real time, 12 ms IPO)", rows)
    write_json(args.json, "plant", rows, {"robot": args.robot or "kr6_r900_sixx"})


if __name__ == "__main__":
    main()
