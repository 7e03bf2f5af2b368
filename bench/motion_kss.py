"""Motion fidelity: axis limits, approximation distances and planning cost of the motion kernel.

Runs the simulated robot in process, ticked by hand (exact simulated time), and reads every
figure off the IPO set-points the kernel produced:

* worst axis speed and acceleration over their limits on a fast LIN ($VEL.CP 2 m/s) whose wrist
  passes A5 = 0.43° and 2° (a vertical line through HOME's flange position, flange yawed);
* where C_DIS (20, 60 mm) and C_PTP (20 %, 50 %) blending starts: distance to the corner (mm)
  and remaining travel of the leading axis (deg);
* peak axis acceleration over its limit in a C_PTP blend through an A2 reversal and across a
  $OV_PRO step 100 → 10 → 100 %;
* the worst CPU time one IPO cycle spends while the KRL advance run plans a 500 mm LIN, and the
  worst event-loop hold (wall time) while a running emulator plans it.

    .venv/bin/python bench/motion_kss.py [--quick]   (--quick: only the 2° LIN)
"""

from __future__ import annotations

import asyncio
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import Row, base_parser, machine_info, print_rows, write_json

from kukavarproxy_emu import Emulator, EmulatorConfig
from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.store import VariableStore
from pyopenshowvar.kinematics import KR6R900SIXX, forward, inverse, matrix_to_frame, pose_to_matrix
from pyopenshowvar.krl import E6Axis

M = KR6R900SIXX
IPO = 0.012
HOME = np.array([0.0, -90.0, 90.0, 0.0, 0.0, 0.0])


def robot_at(q0: np.ndarray, program: str = "none") -> Robot:
    store = VariableStore()
    store.set_system("$AXIS_ACT", E6Axis.from_numpy(np.concatenate([q0, np.zeros(6)])))
    robot = Robot(store, program=program)
    robot._begin()
    robot.kernel.trace = []
    return robot


def run(robot: Robot) -> list[int]:
    active = []
    for _ in range(6000):
        robot.tick()
        active.append(len(robot.kernel.active))
        if not robot.kernel.moving:
            break
    return active


def ratios(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    q = np.array([q for _t, q, _qd in robot.kernel.trace])
    qd = np.diff(q, axis=0) / IPO
    qdd = np.diff(qd, axis=0) / IPO
    return np.max(np.abs(qd), axis=0) / M.max_speed, np.max(np.abs(qdd), axis=0) / M.max_accel


def singular_lin(yaw: float) -> tuple[float, float, float]:
    """(min |A5|, worst speed ratio, worst acceleration ratio) of the near-singular LIN."""
    rot = pose_to_matrix(np.array([0.0, 0.0, 0.0, yaw, 90.0, 0.0]))

    def pose(z: float) -> np.ndarray:
        m = rot.copy()
        m[:3, 3] = [525.0, 0.0, z]
        return np.asarray(matrix_to_frame(m))

    q0 = inverse(M, pose(740.0), current=np.array([0.0, -90.0, 90.0, 0.0, -20.0, 0.0]))
    robot = robot_at(q0)
    robot.store.write("$VEL", "{CP 2.0}")
    robot.kernel.lin(pose(1040.0))
    run(robot)
    q = np.array([q for _t, q, _qd in robot.kernel.trace])
    speed, accel = ratios(robot)
    return float(np.min(np.abs(q[:, 4]))), float(speed.max()), float(accel.max())


def blend_distance(robot: Robot, length: float) -> tuple[float, tuple[float, float]]:
    """Where the planned blend starts (distance to go along the first segment) and the two
    set-points of the trace that bracket it, run to the end."""
    first = robot.kernel.pending[0]
    assert first.blend_at is not None, "no blend planned"
    exact = (1.0 - first.profile.s_at(first.blend_at)) * length
    return exact, (0.0, 0.0)


def cdis_start(cdis: float) -> tuple[float, float, float]:
    q0 = np.array([0.0, -80.0, 80.0, 0.0, 30.0, 0.0])
    robot = robot_at(q0)
    robot.store.write("$APO", f"{{CDIS {cdis}}}")
    robot.store.write("$VEL", "{CP 0.5}")
    corner = forward(M, q0) + np.array([0.0, 200.0, 0.0, 0.0, 0.0, 0.0])
    robot.kernel.lin(corner, approx=True)
    robot.kernel.lin(corner + np.array([0.0, 0.0, -200.0, 0.0, 0.0, 0.0]))
    exact, _ = blend_distance(robot, 200.0)
    active = run(robot)
    first = active.index(2)
    to_go = [
        float(np.linalg.norm(forward(M, robot.kernel.trace[i][1])[:3] - corner[:3]))
        for i in (first - 1, first)
    ]
    return exact, to_go[0], to_go[1]


def cptp_start(cptp: int) -> tuple[float, float, float]:
    robot = robot_at(HOME)
    robot.store.write("$APO", f"{{CPTP {cptp}}}")
    robot.kernel.ptp(HOME + np.array([60.0, 0, 0, 0, 0, 0]), approx=True)
    robot.kernel.ptp(HOME + np.array([60.0, 0, 0, 0, 60.0, 0]))
    exact, _ = blend_distance(robot, 60.0)
    active = run(robot)
    first = active.index(2)
    return exact, *(60.0 - float(robot.kernel.trace[i][1][0]) for i in (first - 1, first))


def reversal_accel() -> float:
    robot = robot_at(HOME)
    robot.kernel.ptp(HOME + np.array([0, 40.0, 0, 0, 0, 0]), approx=True)
    robot.kernel.ptp(HOME + np.array([30.0, 0, 0, 0, 0, 0]))
    run(robot)
    return float(ratios(robot)[1].max())


def override_accel() -> float:
    robot = robot_at(HOME)
    robot.kernel.ptp(HOME + np.array([160.0, 30.0, 60.0, 0, 0, 0]))
    for ov, ticks in (("10", 30), ("100", 40)):
        for _ in range(ticks if ov == "10" else 10):
            robot.tick()
        robot.store.write("$OV_PRO", ov)
    run(robot)
    return float(ratios(robot)[1].max())


def planning_hold() -> tuple[float, float]:
    """(worst CPU ms of one cycle, wall ms the LIN took to plan) for a 500 mm LIN."""
    q0 = np.array([0.0, -80.0, 80.0, 0.0, 30.0, 0.0])
    robot = robot_at(q0, program="cart_path")
    store = robot.store
    goal = forward(M, q0) + np.array([0.0, 300.0, -400.0, 0.0, 0.0, 0.0])
    text = ", ".join(f"{k} {v!r}" for k, v in zip("XYZABC", goal.tolist(), strict=True))
    store.write("MYPOSARRAY[1]", "{" + text + "}")
    store.write("PATH_COUNT", "1")
    store.write("PATH_START", "TRUE")
    worst, cycles = 0.0, 0
    while not np.any(robot.kernel.qd) and cycles < 1000:
        cpu = time.thread_time()
        robot.tick()
        worst = max(worst, time.thread_time() - cpu)
        cycles += 1
    return worst * 1e3, cycles * IPO * 1e3


async def _loop_hold() -> float:
    """Worst event-loop hold (ms of wall time) while a running emulator plans the 500 mm LIN."""
    q0 = np.array([0.0, -80.0, 80.0, 0.0, 30.0, 0.0])
    store = VariableStore()
    store.set_system("$AXIS_ACT", E6Axis.from_numpy(np.concatenate([q0, np.zeros(6)])))
    config = EmulatorConfig(port=0, program="cart_path", discovery=False)
    async with Emulator(config, store=store) as emu:
        await asyncio.sleep(0.1)
        goal = forward(M, q0) + np.array([0.0, 300.0, -400.0, 0.0, 0.0, 0.0])
        text = ", ".join(f"{k} {v!r}" for k, v in zip("XYZABC", goal.tolist(), strict=True))
        emu.store.write("MYPOSARRAY[1]", "{" + text + "}")
        emu.store.write("PATH_COUNT", "1")
        emu.store.write("PATH_START", "TRUE")
        worst, end = 0.0, time.perf_counter() + 0.6
        while time.perf_counter() < end:
            start = time.perf_counter()
            await asyncio.sleep(0)
            worst = max(worst, time.perf_counter() - start)
    return worst * 1e3


def main() -> None:
    ap = base_parser(__doc__)
    args = ap.parse_args()
    rows: list[Row] = []
    for yaw in (1.7,) if args.quick else (0.365, 1.7):
        a5, speed, accel = singular_lin(yaw)
        rows.append(
            Row(
                f"LIN through A5 = {a5:.2f} deg: worst axis speed / max",
                speed,
                "",
                target=("ours", "<=", 1.000001),
                note=f"worst axis acceleration / max {accel:.3f}",
            )
        )
    for cdis in (20.0, 60.0):
        exact, before, after = cdis_start(cdis)
        rows.append(
            Row(
                f"C_DIS {cdis:g} mm (200 mm LINs): blend starts at",
                exact,
                "mm",
                note=f"to the corner; the set-points around it: {before:.2f} / {after:.2f} mm",
            )
        )
    for cptp in (20, 50):
        expected = min(cptp / 100 * 90.0, 30.0)
        exact, before, after = cptp_start(cptp)
        rows.append(
            Row(
                f"C_PTP {cptp} % (60 deg move): blend starts at",
                exact,
                "deg",
                note=f"to go on A1; rule: {expected:g} deg ($APO_DIS_PTP 90 deg × CPTP, at most "
                f"half); the set-points around it: {before:.2f} / {after:.2f} deg",
            )
        )
    rows.append(
        Row(
            "A2 reversal blend: peak axis accel / max",
            reversal_accel(),
            "",
            target=("ours", "<=", 1.000001),
        )
    )
    rows.append(
        Row(
            "$OV_PRO 100→10→100: peak axis accel / max",
            override_accel(),
            "",
            target=("ours", "<=", 1.000001),
        )
    )
    worst, wall = planning_hold()
    rows.append(
        Row(
            "500 mm LIN planning: worst cycle CPU",
            worst,
            "ms",
            target=("ours", "<=", 10.0),
            note=f"planned over {wall:.0f} ms of simulated time",
        )
    )
    rows.append(
        Row(
            "500 mm LIN planning: worst event-loop hold",
            asyncio.run(_loop_hold()),
            "ms",
            target=("ours", "<=", 10.0),
            note="wall time, emulator running in real time (a busy machine adds its waits)",
        )
    )
    print_rows("Motion kernel (KSS fidelity)", rows)
    write_json(args.json, "motion_kss", rows, {"machine": machine_info()})


if __name__ == "__main__":
    main()
