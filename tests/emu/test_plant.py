"""The dynamic plant (issue 17): rigid-body dynamics, servos, noise, calibration error, contact.

Dynamics are checked against an independent recursive Newton–Euler (newton_euler.py, its own
chain and recursion; roboticstoolbox's ``rne`` too where it is installed) to 1e-6 Nm.
"""

from __future__ import annotations

import asyncio
from typing import Any

import mujoco
import numpy as np
import pytest
from newton_euler import inverse_dynamics, tcp_jacobian

from kukavarproxy_emu import EmulatorConfig
from kukavarproxy_emu.__main__ import build_parser, config_from_args
from kukavarproxy_emu.plant import Obstacle
from kukavarproxy_emu.plant.dynamic import DynamicPlant
from kukavarproxy_emu.plant.frames import dh_matrix, frame_matrix
from kukavarproxy_emu.plant.mjcf import payload_of
from kukavarproxy_emu.robot_task import Robot
from kukavarproxy_emu.store import VariableStore
from pyopenshowvar import Client
from pyopenshowvar.kinematics import KR6R900SIXX, fk_matrix
from pyopenshowvar.krl import Struct

HOME = np.array([0.0, -90.0, 90.0, 0.0, 0.0, 0.0])
LOAD = "{M 4.5, CM {X 30.0, Y -20.0, Z 60.0, A 20.0, B 10.0, C 0.0}, J {X 0.02, Y 0.03, Z 0.01}}"


def quiet_robot(**kw: Any) -> Robot:
    """A dynamic robot without sensor noise, driven tick by tick (no clock, no program)."""
    store = kw.pop("store", None) or VariableStore()
    kw.setdefault("noise", 0.0)
    kw.setdefault("torque_noise", 0.0)
    return Robot(store, program="none", sps=None, plant="dynamic", seed=1, **kw)


def plant_of(robot: Robot) -> DynamicPlant:
    assert isinstance(robot.plant, DynamicPlant)
    return robot.plant


def friction(plant: DynamicPlant, qd: np.ndarray) -> np.ndarray:
    """The model file's friction law (docs/emulator-robot.md): a regularised Stribeck curve."""
    b, p = plant.bodies, plant.params
    dry = b.coulomb + (b.static - b.coulomb) * np.exp(-np.square(qd / p.stribeck_velocity))
    return np.asarray(dry * np.tanh(qd / p.friction_smoothing) + b.viscous * qd)


def friction_in_step(plant: DynamicPlant, qd: np.ndarray, qacc: np.ndarray) -> np.ndarray:
    """The friction a physics step applies: the law at the step's end speed, linearised about
    its start (the slope by a central difference here; a falling branch stays explicit)."""
    eps = 1e-7
    slope = (friction(plant, qd + eps) - friction(plant, qd - eps)) / (2 * eps)
    return friction(plant, qd) + np.maximum(slope, 0.0) * plant.h * qacc


def run_until_rest(robot: Robot, limit: int = 400) -> int:
    plant = plant_of(robot)
    for n in range(1, limit + 1):
        robot.tick()
        if not robot.kernel.moving and plant.resting:
            return n
    raise AssertionError("the plant did not come to rest")


def torques(store: VariableStore) -> np.ndarray:
    values = store.get("$TORQUE_AXIS_ACT")
    assert isinstance(values, list)
    return np.array(values[:6], dtype=float)


def axes(store: VariableStore, name: str = "$AXIS_ACT") -> np.ndarray:
    value = store.get(name)
    assert isinstance(value, Struct)
    return np.array([float(value[f"A{i}"]) for i in range(1, 7)])  # type: ignore[arg-type]


# --- the model against an independent computation --------------------------------------------
@pytest.mark.parametrize("calibration", [None, 7])
def test_mujoco_inverse_dynamics_matches_newton_euler(calibration: int | None) -> None:
    store = VariableStore()
    store.write("$LOAD", LOAD)
    plant = plant_of(quiet_robot(store=store, calibration_error=calibration))
    m, _ = plant.mujoco
    data = mujoco.MjData(m)
    rng = np.random.default_rng(3)
    lo, hi = np.radians(KR6R900SIXX.lower), np.radians(KR6R900SIXX.upper)
    for _ in range(12):
        q, qd, qdd = rng.uniform(lo, hi), rng.uniform(-4, 4, 6), rng.uniform(-30, 30, 6)
        data.qpos[:], data.qvel[:], data.qacc[:] = q, qd, qdd
        mujoco.mj_inverse(m, data)
        ref = inverse_dynamics(
            plant.bodies, q, qd, qdd, armature=plant.bodies.armature, payload=plant.payload
        )
        np.testing.assert_allclose(data.qfrc_inverse, ref, rtol=0, atol=1e-6)


def test_matches_roboticstoolbox_rne() -> None:
    rtb = pytest.importorskip("roboticstoolbox")  # the bench extras; CI runs the test above
    plant = plant_of(quiet_robot())
    b = plant.bodies
    links = []
    for j in range(6):
        # rtb's link j carries its centre of mass and inertia in D-H frame j, which is our
        # body frame j moved by Rz(offset_j)·Tz(d)·Tx(a)·Rx(α): express ours there
        to_dh = np.linalg.inv(frame_matrix((0, 0, 0, b.offset[j], 0, 0)) @ dh_matrix(
            b.a[j], b.alpha[j], b.d[j], 0.0
        ))  # fmt: skip
        r = to_dh[:3, :3]
        com = r @ (b.com[j] / 1000.0) + to_dh[:3, 3] / 1000.0
        inertia = r @ b.inertia_axes[j] @ np.diag(b.inertia[j]) @ b.inertia_axes[j].T @ r.T
        links.append(
            rtb.RevoluteDH(
                a=b.a[j] / 1000, d=b.d[j] / 1000, alpha=np.radians(b.alpha[j]),
                offset=np.radians(b.offset[j]), m=b.mass[j], r=com, I=inertia, G=1.0,
                Jm=plant.bodies.armature[j],
            )
        )  # fmt: skip
    robot = rtb.DHRobot(links, gravity=[0, 0, -9.81])
    rng = np.random.default_rng(5)
    m, _ = plant.mujoco
    data = mujoco.MjData(m)
    for _ in range(8):
        q, qd, qdd = rng.uniform(-2, 2, 6), rng.uniform(-3, 3, 6), rng.uniform(-20, 20, 6)
        data.qpos[:], data.qvel[:], data.qacc[:] = q, qd, qdd
        mujoco.mj_inverse(m, data)
        # rtb's joint angle is θ = sign·q: torques and velocities flip with the sign
        s = b.sign
        tau = robot.rne(s * q, s * qd, s * qdd) * s
        np.testing.assert_allclose(data.qfrc_inverse, tau, rtol=0, atol=1e-6)


def test_every_physics_step_obeys_the_equations_of_motion() -> None:
    """Motor torque = M(q)q̈ + C(q,q̇)q̇ + g(q) + payload + friction, step by step while moving."""
    store = VariableStore()
    store.write("$LOAD", LOAD)
    robot = quiet_robot(store=store)
    plant = plant_of(robot)
    robot.kernel.ptp(np.array([60.0, -50.0, 70.0, 90.0, 50.0, 120.0]))
    checked = 0
    while robot.kernel.moving:
        robot.tick()
        rec = plant.last_step
        assert rec is not None
        ref = inverse_dynamics(
            plant.bodies, rec.q, rec.qd, rec.qacc, armature=plant.bodies.armature,
            payload=plant.payload,
        )  # fmt: skip
        applied = friction_in_step(plant, rec.qd, rec.qacc)
        np.testing.assert_allclose(rec.motor, ref + applied, rtol=0, atol=1e-6)
        np.testing.assert_allclose(rec.other, -applied, rtol=0, atol=1e-6)
        checked += 1
    assert checked > 20
    # the published torque is that motor torque (sign convention: +KUKA axis, model.torque_sign)
    np.testing.assert_allclose(torques(store), plant.torque * KR6R900SIXX.torque_sign)


def test_published_torque_is_the_cycle_mean_and_carries_the_inertia() -> None:
    """What a client sampling once per IPO cycle can use: the published torque is the motor
    torque averaged over the cycle, so inverse dynamics at the cycle's mean acceleration
    (Δ$VEL_AXIS_ACT / IPO, the measured speeds at both ends) and mid-cycle state explain it.
    A sample of the last 2 ms step would carry only a few % of the inertial torque."""
    store = VariableStore()
    robot = quiet_robot(store=store)
    plant = plant_of(robot)
    for i in range(1, 7):
        store.write(f"$ACC_AXIS[{i}]", "30")
    robot.kernel.ptp(np.array([40.0, -60.0, 60.0, 30.0, 30.0, 40.0]))
    q, qd, tau = [], [], []
    while robot.kernel.moving or not plant.resting:
        robot.tick()
        q.append(np.radians(plant.truth.q))
        vel = np.array(store.get("$VEL_AXIS_ACT")[:6], dtype=float)  # type: ignore[index]
        qd.append(np.radians(vel * KR6R900SIXX.max_speed / 100.0))
        tau.append(torques(store))
    residual, inertial = [], []
    ipo = plant.ipo
    for k in range(1, len(q)):
        mid, mean_qd = (q[k] + q[k - 1]) / 2, (q[k] - q[k - 1]) / ipo
        mean_qdd = (qd[k] - qd[k - 1]) / ipo
        arm = plant.bodies.armature
        full = inverse_dynamics(plant.bodies, mid, mean_qd, mean_qdd, armature=arm)
        still = inverse_dynamics(plant.bodies, mid, mean_qd, np.zeros(6), armature=arm)
        residual.append(tau[k] - full - friction(plant, mean_qd))
        inertial.append(full - still)
    res_rms = np.sqrt(np.mean(np.square(residual), axis=0))
    inertial_rms = np.sqrt(np.mean(np.square(inertial), axis=0))
    assert inertial_rms[1] > 3.0  # Nm on A2: the move really accelerates the arm
    assert np.all(res_rms[:2] < 0.05 * inertial_rms[:2]), (res_rms, inertial_rms)


def test_torques_at_rest_are_the_models_with_load_and_wrench() -> None:
    store = VariableStore()
    robot = quiet_robot(store=store)
    plant = plant_of(robot)
    # start-up: the model's holding torques, not the reference's rounded table
    assert store.read("$TORQUE_AXIS_ACT[2]") != "-24.7800"
    gravity = inverse_dynamics(plant.bodies, np.radians(HOME), np.zeros(6), np.zeros(6))
    np.testing.assert_allclose(torques(store), gravity, rtol=0, atol=1e-6)
    store.write("$LOAD", LOAD)
    store.write("$TOOL", "{X 10.0, Y 20.0, Z 150.0, A 0.0, B 30.0, C 0.0}")
    wrench = np.array([15.0, -10.0, 30.0, 1.0, -2.0, 0.5])
    robot.apply_wrench(wrench)
    run_until_rest(robot)
    tool = frame_matrix((10.0, 20.0, 150.0, 0.0, 30.0, 0.0))
    expected = inverse_dynamics(
        plant.bodies, np.radians(HOME), np.zeros(6), np.zeros(6),
        payload=payload_of(store.get("$LOAD")), tool=tool, wrench_on_robot=-wrench,
    )  # fmt: skip
    np.testing.assert_allclose(torques(store), expected, rtol=0, atol=1e-6)
    # EMU_WRENCH = what the TCP exerts on the environment: τ = gravity + Jᵀ F (thesis eq. 4.5)
    jac = tcp_jacobian(plant.bodies, np.radians(HOME), tool)
    loaded = inverse_dynamics(
        plant.bodies, np.radians(HOME), np.zeros(6), np.zeros(6), payload=plant.payload
    )
    np.testing.assert_allclose(torques(store), loaded + jac.T @ wrench, rtol=0, atol=1e-6)


def test_ideal_plant_starts_with_the_models_torques() -> None:
    """Both plants publish their model's torques from the first read: the ideal plant's
    start-up torques are the ones it shows after a move away and back, not the store's
    rounded start-up table (-25.5 for A3)."""
    store = VariableStore()
    robot = Robot(store, program="none", sps=None, plant="ideal")
    start = store.read("$TORQUE_AXIS_ACT[]")
    assert not start.startswith("0.0 -24.7800 -25.5000")
    robot.kernel.ptp(HOME + np.array([10.0, 5.0, -5.0, 0.0, 20.0, 0.0]))
    robot.kernel.ptp(HOME)
    while robot.kernel.moving:
        robot.tick()
    for _ in range(3):  # the last cycle's deceleration leaves the inertial term
        robot.tick()
    assert store.read("$TORQUE_AXIS_ACT[]") == start
    assert store.read("$AXIS_ACT").startswith("{E6AXIS: A1 0.0, A2 -90.0000, A3 90.0000")


# --- servo -------------------------------------------------------------------------------------
def test_servo_step_response_and_disturbance_rejection() -> None:
    robot = quiet_robot()
    plant = plant_of(robot)
    # a set-point step (the planner never sends one; the drives ramp it over one IPO cycle
    # with velocity and acceleration feed-forward): 90 % within 3 cycles, bounded overshoot
    target = HOME + np.array([0.0, 0.5, 0.0, 1.0, 0.0, 0.0])
    trace = []
    for _ in range(80):
        plant.step(target)
        trace.append(plant.truth.q.copy())
    response = (np.array(trace) - HOME)[:, [1, 3]] / np.array([0.5, 1.0])
    cycles_to_90 = np.argmax(response >= 0.9, axis=0) + 1
    assert np.all(cycles_to_90 <= 3) and response.max() < 1.3, (cycles_to_90, response.max())
    assert plant.resting  # converged: snapped onto the set-point, physics no longer stepped
    np.testing.assert_array_equal(plant.truth.q, target)
    steps = plant.steps
    for _ in range(20):
        plant.step(target)
    assert plant.steps == steps
    # the feedback loop: a 50 N push deflects the TCP a little and the servo pulls it back
    # with a ~30 ms time constant (position loop ~6 Hz, integral action: no steady error)
    x0 = plant.truth.tcp[:3, 3].copy()
    robot.apply_wrench([-50.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    deflection = []
    for _ in range(60):
        plant.step(target)
        deflection.append(np.linalg.norm(plant.truth.tcp[:3, 3] - x0))
    peak = int(np.argmax(deflection))
    assert 0.01 < deflection[peak] < 1.0, deflection[peak]  # mm
    decayed = next(i for i in range(peak, 60) if deflection[i] < deflection[peak] / np.e)
    assert 0.024 <= (decayed - peak) * 0.012 <= 0.15
    assert plant.resting and deflection[-1] == 0.0


def test_following_error_while_moving_and_exact_convergence_at_rest() -> None:
    store = VariableStore()
    robot = quiet_robot(store=store)
    target = np.array([100.0, -30.0, 60.0, 150.0, 80.0, 300.0])
    robot.kernel.ptp(target)  # 100 % speed and acceleration
    errors = []
    while robot.kernel.moving:
        robot.tick()
        errors.append(axes(store) - robot.q)  # measured $AXIS_ACT minus the IPO set-point
    worst = np.abs(errors).max(axis=0)
    assert np.all(worst > 1e-3) and np.all(worst < 0.5), worst  # deg: a lag, bounded
    run_until_rest(robot)
    np.testing.assert_array_equal(axes(store), target)
    np.testing.assert_array_equal(axes(store, "$AXIS_ACT_MEAS"), target)


# --- noise --------------------------------------------------------------------------------------
def test_noise_is_seeded_per_cycle_whenever_it_is_read() -> None:
    a = Robot(VariableStore(), program="none", sps=None, plant="dynamic", seed=11)
    b = Robot(VariableStore(), program="none", sps=None, plant="dynamic", seed=11)
    c = Robot(VariableStore(), program="none", sps=None, plant="dynamic", seed=12)
    samples = []
    for n in range(300):
        a.tick()
        b.tick()
        c.tick()
        if n % 7 == 0:  # b is read only now and then: its values depend on the cycle only
            assert a.store.read("$AXIS_ACT") == b.store.read("$AXIS_ACT")
            assert a.store.read("$TORQUE_AXIS_ACT[]") == b.store.read("$TORQUE_AXIS_ACT[]")
            assert a.store.read("$AXIS_ACT") != c.store.read("$AXIS_ACT")
        samples.append(np.concatenate([axes(a.store) - HOME, torques(a.store)]))
    plant = plant_of(a)
    std = np.std(samples, axis=0)
    np.testing.assert_allclose(std[:6], plant.encoder_noise, rtol=0.3)
    np.testing.assert_allclose(std[6:], plant.torque_noise, rtol=0.3)
    assert plant.steps == 0  # at rest the noise costs no physics
    pos = a.store.get("$POS_ACT")
    assert isinstance(pos, Struct) and (pos["S"], pos["T"]) == (2, 2)  # the commanded config


# --- calibration error --------------------------------------------------------------------------
def test_calibration_error_is_a_different_physical_robot() -> None:
    nominal = plant_of(quiet_robot())
    one, same, other = (plant_of(quiet_robot(calibration_error=s)) for s in (5, 5, 6))
    np.testing.assert_array_equal(one.bodies.a, same.bodies.a)
    assert not np.array_equal(one.bodies.a, other.bodies.a)
    # the controller reports the nominal pose; the physical flange is elsewhere by ~mm
    np.testing.assert_allclose(nominal.truth.flange, fk_matrix(KR6R900SIXX, HOME), atol=1e-9)
    offset = np.linalg.norm(one.truth.flange[:3, 3] - fk_matrix(KR6R900SIXX, HOME)[:3, 3])
    assert 0.05 < offset < 10.0, offset
    assert np.max(np.abs(one.torque - nominal.torque)) > 0.05  # masses differ: torques too


# --- contact and external wrench ----------------------------------------------------------------
def test_pushing_into_an_obstacle_gives_a_true_contact_force() -> None:
    target = HOME + np.array([0.0, 2.0, 0.0, 0.0, 0.0, 0.0])  # leans the TCP forward
    x_target = fk_matrix(KR6R900SIXX, target)[0, 3]
    face = x_target - 8.0  # the set-point is 8 mm inside the box
    box = Obstacle((face + 100.0, 0.0, 890.0), (100.0, 200.0, 200.0), stiffness=3.0)
    store = VariableStore()
    robot = quiet_robot(store=store, obstacles=[box])
    plant = plant_of(robot)
    assert not np.any(plant.truth.contact)
    robot.kernel.ptp(target)
    run_until_rest(robot)
    force = plant.truth.contact  # what the TCP exerts on the box (EMU_WRENCH convention)
    depth = plant.truth.tcp[0, 3] - face
    assert depth == pytest.approx(8.0, abs=1e-6)
    np.testing.assert_allclose(force, [3.0 * depth, 0, 0, 0, 0, 0], atol=1e-9)
    expected = inverse_dynamics(
        plant.bodies, np.radians(target), np.zeros(6), np.zeros(6), wrench_on_robot=-force
    )
    np.testing.assert_allclose(torques(store), expected, rtol=0, atol=1e-6)
    plant.set_obstacles([])  # taken away: the arm is free again
    robot.tick()
    run_until_rest(robot)
    assert not np.any(plant.truth.contact)


async def test_wrench_over_kvp_and_dynamic_readings_end_to_end(emulator_factory: Any) -> None:
    emu = await emulator_factory(speed=20.0, noise=0.0, torque_noise=0.0)
    plant = emu.robot.plant
    assert isinstance(plant, DynamicPlant)
    async with Client("127.0.0.1", emu.port, timeout=2.0) as kvp:
        await kvp.write("EMU_WRENCH", "{FX 0.0, FY 0.0, FZ -40.0, MX 0.0, MY 0.0, MZ 0.0}")
        jac = tcp_jacobian(plant.bodies, np.radians(HOME))
        gravity = inverse_dynamics(plant.bodies, np.radians(HOME), np.zeros(6), np.zeros(6))
        expected = gravity + jac.T @ np.array([0, 0, -40.0, 0, 0, 0])
        for _ in range(200):
            tau = await kvp.read_joint_torques()
            if np.allclose(tau, expected, atol=1e-4):
                break
            await asyncio.sleep(0.005)
        np.testing.assert_allclose(tau, expected, atol=1e-4)  # float32 text of the KRC4


# --- configuration --------------------------------------------------------------------------------
def test_plant_options_and_bad_values() -> None:
    args = build_parser().parse_args(
        ["--plant", "dynamic", "--calibration-error", "3", "--obstacle", "600,0,800,50,50,50,5"]
    )
    cfg = config_from_args(args)
    assert cfg.plant == "dynamic" and cfg.calibration_error == 3
    assert cfg.obstacles == (Obstacle((600, 0, 800), (50, 50, 50), 5.0),)
    assert EmulatorConfig().plant == "dynamic"
    with pytest.raises(ValueError, match="unknown plant"):
        EmulatorConfig(plant="perfect")
    with pytest.raises(ValueError, match="need plant 'dynamic'"):
        EmulatorConfig(plant="ideal", calibration_error=1)
    with pytest.raises(ValueError, match="noise"):
        EmulatorConfig(noise=-1.0)
    for bad in ("1,2,3", "a,b,c,d,e,f", "0,0,0,1,1,1,500", "0,0,0,0,1,1"):
        with pytest.raises(ValueError):
            Obstacle.parse(bad)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--plant", "perfect"])


def test_deferred_values_are_filled_once_on_first_read() -> None:
    store = VariableStore()
    calls: list[int] = []

    def fill() -> None:
        calls.append(1)
        store.set_system("$VEL_ACT", 1.5)

    store.defer(["$VEL_ACT"], fill)
    assert store.read("$OV_PRO") == "100" and not calls  # other variables do not fill
    assert store.read("$VEL_ACT") == "1.50000" and store.get("$VEL_ACT") == 1.5
    assert calls == [1]


def test_absurd_wrench_and_load_keep_readings_finite_and_recover(
    tmp_path: Any, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.chdir(tmp_path)
    store = VariableStore()
    robot = quiet_robot(store=store)
    robot.apply_wrench([1e30, 0.0, 0.0, 0.0, 0.0, 0.0])
    store.write("$LOAD", "{M 1e9, CM {X 100.0}, J {X 5.0, Y 0.0, Z 0.0}}")  # no such body
    plant = plant_of(robot)
    for _ in range(10):
        robot.tick()
        assert np.all(np.isfinite(torques(store))) and np.all(np.isfinite(axes(store)))
        assert np.all(np.abs(torques(store)) <= plant.torque_limit + 1e-9)  # saturated
    # no motor holds that: the monitoring stopped the robot and the brakes hold the arm
    assert plant.braked and store.get("$STOPMESS") is True
    held = axes(store)
    assert np.max(np.abs(held - HOME)) < 2.0
    robot.apply_wrench([0.0] * 6)
    store.write("$LOAD", "{M 0.0}")
    robot.restart()
    run_until_rest(robot)  # anti-windup: the servo recovers instead of spinning the arm
    np.testing.assert_allclose(axes(store), held, atol=1e-9)
    # MuJoCo's complaints went to logging, not to a MUJOCO_LOG.TXT where the emulator runs
    assert "MuJoCo: Nan" in caplog.text and not list(tmp_path.iterdir())


def test_removing_a_heavy_load_retunes_the_servo_and_stays_stable() -> None:
    store = VariableStore()
    store.write("$LOAD", "{M 6.0, CM {X 0.0, Y 150.0, Z 100.0}, J {X 0.05, Y 0.05, Z 0.05}}")
    robot = quiet_robot(store=store)  # gains tuned for the loaded arm
    store.write("$LOAD", "{M 0.0}")  # the light arm with those gains would oscillate
    target = np.array([30.0, -60.0, 100.0, 90.0, 60.0, 200.0])
    robot.kernel.ptp(target)
    run_until_rest(robot, limit=300)
    np.testing.assert_array_equal(axes(store), target)
    assert plant_of(robot).payload is None
