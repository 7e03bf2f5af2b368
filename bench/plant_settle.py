"""The dynamic plant with payload: does the arm settle, and does the planner respect the motors?

Part 1, **settling** (the plant's physics, in process, ticked by hand, no sensor noise so that
every non-zero reading at rest is the plant's own motion): for random poses × payloads
(0, 4.5 and 6 kg, each with a random centre of mass within 100 mm of the flange and random
inertia), a 50 % PTP from HOME to the pose, then up to 2 s for the plant to come to rest
(the servo converged, the physics no longer stepped). Over the next 1 s: the worst
``|$VEL_AXIS_ACT|`` (% of max speed), the peak-to-peak of ``$AXIS_ACT`` (deg), the worst
``|$TORQUE_AXIS_ACT − static torque|`` (Nm; the static torque is MuJoCo's gravity + load at
the set-point) and the CPU the ticks cost (% of one core at real time, no reader).

Part 2, **planning** (the controller's set-points against the plant's motors): random PTP,
LIN ($VEL.CP 2 m/s), C_PTP chains (three targets, $APO.CPTP 50 %, all planned before the
first starts) and C_PTP chains whose next targets are planned while the robot runs (as a
follower program does; random $APO.CPTP 10–100 %) and C_LIN chains (three LINs of up to
±20° per axis, random $APO.CDIS 5–100 mm) with payloads 0, 4.5 and 6 kg. For every IPO cycle,
from the standing position before the first one on, the torque the plant's motors need to
follow the set-points (the plant's inverse dynamics at the cycle's mean acceleration + its
friction) over the plant's max torque, and the set-point acceleration over the axis' limit;
the worst of each.
Plus the case the issue names: HOME, A3 alone at full acceleration with 6 kg.

    .venv/bin/python bench/plant_settle.py [--quick] [--poses 40] [--moves 20] [--json PATH]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import Row, base_parser, machine_info, print_rows, write_json

from kukavarproxy_emu.motion import MotionRefused
from kukavarproxy_emu.plant.dynamic import DynamicPlant
from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.store import VariableStore
from pyopenshowvar.kinematics import KR6R900SIXX, forward

M = KR6R900SIXX
HOME = np.array([0.0, -90.0, 90.0, 0.0, 0.0, 0.0])
MASSES = (0.0, 4.5, 6.0)
IPO = 0.012


def random_load(rng: np.random.Generator, mass: float) -> str:
    """A $LOAD of ``mass`` kg: centre of mass within 100 mm of the flange, inertia of a
    compact body of that mass (0.2–1.0 × m·(50 mm)² per axis)."""
    if mass <= 0.0:
        return "{M 0.0}"
    x, y = rng.uniform(-50.0, 50.0, 2)
    z = rng.uniform(0.0, 100.0)
    j = rng.uniform(0.2, 1.0, 3) * mass * 0.05**2
    return (
        f"{{M {mass}, CM {{X {x:.1f}, Y {y:.1f}, Z {z:.1f}, A 0.0, B 0.0, C 0.0}}, "
        f"J {{X {j[0]:.5f}, Y {j[1]:.5f}, Z {j[2]:.5f}}}}}"
    )


def random_pose(rng: np.random.Generator) -> np.ndarray:
    """Axes uniformly within 90 % of the software limits."""
    lo, hi = M.lower * 0.9, M.upper * 0.9
    return np.asarray(rng.uniform(lo, hi), dtype=np.float64)


def quiet_robot(store: VariableStore, seed: int) -> Robot:
    return Robot(
        store, program="none", sps=None, plant="dynamic", seed=seed, noise=0.0, torque_noise=0.0
    )


def static_torque(plant: DynamicPlant) -> np.ndarray:
    m, _ = plant.mujoco
    data = mujoco.MjData(m)
    data.qpos[:] = np.radians(plant._q_set_deg)
    mujoco.mj_inverse(m, data)
    return np.asarray(data.qfrc_inverse * M.torque_sign)


def settle_case(pose: np.ndarray, load: str, seed: int) -> dict[str, float]:
    store = VariableStore()
    store.write("$LOAD", load)
    for i in range(1, 7):
        store.write(f"$VEL_AXIS[{i}]", "50")
    robot = quiet_robot(store, seed)
    plant = robot.plant
    assert isinstance(plant, DynamicPlant)
    robot.kernel.ptp(pose)
    for _ in range(2000):
        robot.tick()
        if not robot.kernel.moving:
            break
    rest_after = float("inf")
    for n in range(1, 168):  # 2 s
        robot.tick()
        if plant.resting:
            rest_after = n * IPO
            break
    cycles = 84  # 1 s
    cpu0 = time.process_time()
    for _ in range(cycles):
        robot.tick()
    cpu = time.process_time() - cpu0
    vel, q, tau = [], [], []
    static = static_torque(plant)
    for _ in range(cycles):
        robot.tick()
        vel.append(np.array(store.get("$VEL_AXIS_ACT")[:6], dtype=float))  # type: ignore[index]
        axes = store.get("$AXIS_ACT")
        q.append([float(axes[f"A{i}"]) for i in range(1, 7)])  # type: ignore[index]
        tau.append(np.array(store.get("$TORQUE_AXIS_ACT")[:6], dtype=float))  # type: ignore[index]
    return {
        "settled": float(rest_after <= 2.0),
        "rest_after": rest_after,
        "vel": float(np.max(np.abs(vel))),
        "jitter": float(np.max(np.ptp(np.array(q), axis=0))),
        "torque": float(np.max(np.abs(np.array(tau) - static))),
        "cpu": 100.0 * cpu / (cycles * IPO),
    }


# --- part 2: what the planner asks of the motors ---------------------------------------------
def plant_friction(plant: DynamicPlant, qd: np.ndarray) -> np.ndarray:
    """The plant's joint friction at speeds ``qd`` (rad/s); also for the code before the
    Stribeck law (Coulomb tanh + viscous), so the script measures both versions."""
    b, p = plant.bodies, plant.params
    if hasattr(b, "static"):
        from kukavarproxy_emu.plant.drives import friction

        return friction(b, p.friction_smoothing, p.stribeck_velocity, qd)[0]
    return np.asarray(b.coulomb * np.tanh(qd / p.friction_smoothing) + b.viscous * qd)


class Needs:
    """Worst torque and acceleration ratios of set-point traces against the plant's motors."""

    def __init__(self, plant: DynamicPlant) -> None:
        self.plant = plant
        m, _ = plant.mujoco
        self.m, self.data = m, mujoco.MjData(m)
        self.limit = plant.torque_limit
        self.torque = 0.0
        self.accel = 0.0
        self.where = ""

    def trace(self, qs: list[np.ndarray], what: str) -> None:
        q = np.radians(np.array(qs))
        if len(q) < 3:
            return
        v = np.diff(q, axis=0) / IPO  # mean speed of each cycle
        a = np.diff(v, axis=0) / IPO  # mean acceleration around each set-point
        vm = 0.5 * (v[1:] + v[:-1])
        for k in range(len(a)):
            self.data.qpos[:], self.data.qvel[:], self.data.qacc[:] = q[k + 1], vm[k], a[k]
            mujoco.mj_inverse(self.m, self.data)
            fric = plant_friction(self.plant, vm[k])
            ratio = float(np.max(np.abs(self.data.qfrc_inverse + fric) / self.limit))
            if ratio > self.torque:
                self.torque, self.where = ratio, what
        acc = np.degrees(np.abs(a)) / M.max_accel
        self.accel = max(self.accel, float(np.max(acc)))


def planner_case(mass: float, moves: int, seed: int) -> tuple[Needs, ...]:
    """(PTP, LIN, C_PTP, C_PTP planned while running, C_LIN) worst needs over ``moves``
    random moves of each kind."""
    rng = np.random.default_rng(seed)
    out = []
    for kind in ("PTP", "LIN", "C_PTP", "C_PTP live", "C_LIN"):
        needs: Needs | None = None
        for k in range(moves):
            store = VariableStore()
            store.write("$LOAD", random_load(rng, mass))
            # the ideal plant runs the same kernel; the needs are the dynamic plant's model
            robot = Robot(store, program="none", sps=None, plant="ideal", seed=k)
            if needs is None:
                ref = Robot(VariableStore(), program="none", sps=None, plant="dynamic", seed=1)
                ref.store.write("$LOAD", store.read("$LOAD"))
                ref.tick()
                assert isinstance(ref.plant, DynamicPlant)
                needs = Needs(ref.plant)
            else:
                needs.plant.store.write("$LOAD", store.read("$LOAD"))
                needs.plant.step(needs.plant._q_set_deg)
                needs.m, _ = needs.plant.mujoco
                needs.data = mujoco.MjData(needs.m)
            kernel = robot.kernel
            start = random_pose(rng)
            try:
                kernel.ptp(start)
                while kernel.moving:
                    robot.tick()
                # from the standing position on: the first cycle's acceleration counts too
                kernel.trace = [(kernel.time, kernel.q.copy(), kernel.qd.copy())]
                if kind == "PTP":
                    kernel.ptp(random_pose(rng))
                elif kind == "C_PTP":
                    store.write("$APO.CPTP", "50")
                    for _ in range(2):
                        kernel.ptp(random_pose(rng), approx=True)
                    kernel.ptp(random_pose(rng))
                elif kind == "C_PTP live":
                    live_chain(robot, rng)
                elif kind == "C_LIN":
                    store.write("$APO.CDIS", f"{rng.uniform(5.0, 100.0):.1f}")
                    q = start
                    for i in range(3):
                        q = np.clip(q + rng.uniform(-20.0, 20.0, 6), M.lower * 0.9, M.upper * 0.9)
                        kernel.lin(forward(M, q), approx=i < 2)
                else:
                    end = start + rng.uniform(-30.0, 30.0, 6)
                    end = np.clip(end, M.lower * 0.9, M.upper * 0.9)
                    kernel.lin(forward(M, end))
            except MotionRefused:
                continue
            while kernel.moving:
                robot.tick()
            for _ in range(2):
                robot.tick()
            assert kernel.trace is not None and needs is not None
            needs.trace([s[1] for s in kernel.trace], f"{kind} {mass:g} kg")
        assert needs is not None
        out.append(needs)
    return tuple(out)


def live_chain(robot: Robot, rng: np.random.Generator) -> None:
    """Four approximated PTPs, the next three planned at random cycles while the robot runs
    (within its first 0.7 s), as a program whose advance run gets each target late does."""
    kernel = robot.kernel
    robot.store.write("$APO.CPTP", str(int(rng.uniform(10, 100))))
    targets = [random_pose(rng) for _ in range(4)]
    plan_at = sorted(int(c) for c in rng.integers(1, 60, 3))
    kernel.ptp(targets[0], approx=True)
    for n in range(6000):
        for i, at in enumerate(plan_at, start=1):
            if n == at:
                try:
                    kernel.ptp(targets[i], approx=i < 3)
                except MotionRefused:
                    pass
        if n > plan_at[-1] and not kernel.moving:
            return
        robot.tick()


def home_a3(mass: float) -> float:
    """Torque ratio of A3 alone at full acceleration from HOME with ``mass`` at 50 mm."""
    store = VariableStore()
    store.write("$LOAD", f"{{M {mass}, CM {{X 0.0, Y 0.0, Z 50.0}}, J {{X 0.01, Y 0.01, Z 0.01}}}}")
    robot = Robot(store, program="none", sps=None, plant="dynamic", seed=1, noise=0.0)
    assert isinstance(robot.plant, DynamicPlant)
    needs = Needs(robot.plant)
    robot.kernel.trace = []
    robot.kernel.ptp(HOME + np.array([0.0, 0.0, -60.0, 0.0, 0.0, 0.0]))
    while robot.kernel.moving:
        robot.tick()
    robot.tick()
    assert robot.kernel.trace is not None
    needs.trace([s[1] for s in robot.kernel.trace], "HOME A3")
    return needs.torque


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--poses", type=int, default=40, help="random poses per payload")
    ap.add_argument("--moves", type=int, default=20, help="random moves per kind and payload")
    args = ap.parse_args()
    poses = 1 if args.quick else args.poses
    moves = 1 if args.quick else args.moves
    # --quick (the smoke test: every step runs, no figure counts) takes the heaviest payload
    # alone, the one that exercises the whole $LOAD path
    masses = MASSES[-1:] if args.quick else MASSES
    rng = np.random.default_rng(2026)
    rows: list[Row] = []
    for mass in masses:
        cases = [
            settle_case(random_pose(rng), random_load(rng, mass), seed=i) for i in range(poses)
        ]
        settled = sum(c["settled"] for c in cases)
        cpu = [c["cpu"] for c in cases]
        label = f"{mass:g} kg"
        rows += [
            Row(f"{label}: poses settled within 2 s (of {poses})", settled, "poses"),
            Row(f"{label}: worst |$VEL_AXIS_ACT| 1-2 s after rest", max(c["vel"] for c in cases),
                "% of max"),
            Row(f"{label}: worst $AXIS_ACT peak-to-peak at rest", max(c["jitter"] for c in cases),
                "deg"),
            Row(f"{label}: worst |torque - static torque| at rest", max(c["torque"] for c in cases),
                "Nm"),
            Row(f"{label}: CPU of the ticks at rest, mean / worst pose", float(np.mean(cpu)),
                "% core", note=f"worst pose {max(cpu):.1f} % of a core"),
        ]  # fmt: skip
    for mass in masses:
        label = f"{mass:g} kg"
        kinds = ("PTP", "LIN", "C_PTP", "C_PTP planned while running", "C_LIN")
        needs = planner_case(mass, moves, seed=int(mass * 10) + 7)
        rows += [
            Row(f"{label}: worst needed torque / max torque, {kind}", n.torque, "ratio")
            for kind, n in zip(kinds, needs, strict=True)
        ]
        rows += [
            Row(f"{label}: worst set-point accel / limit, {kind}", n.accel, "ratio")
            for kind, n in zip(kinds, needs, strict=True)
        ]
    rows.append(Row("6 kg at HOME, A3 alone at full acceleration: torque / max", home_a3(6.0),
                    "ratio"))  # fmt: skip
    print_rows("Dynamic plant with payload: settling and the planner's demands", rows)
    write_json(args.json, "plant_settle", rows, {"machine": machine_info()})


if __name__ == "__main__":
    main()
