"""Arms simulated in-process: MuJoCo where the description has inertials, else kinematic drives.

The thesis shows the controlled arm in a 3D simulation that "sends the actual joint state
back" (§2.2.2). :class:`SimulatedArm` is that arm, advanced in real time (its clock) up to the
moment the server asks for θ_a, in steps of at most 1 ms (MuJoCo) or 2 ms (kinematic):

* **mujoco** — the arm's own description written as URDF (:func:`pyopenshowvar.arms.to_urdf`)
  and loaded by MuJoCo: rigid-body dynamics with gravity, joint limits as hard stops, each
  joint driven by a PI velocity servo as drives have (torque = K·(e + ω_i·∫e), e = u − θ̇,
  K from the joint's inertia at home; the integral holds against gravity), clamped to the
  arm's torque limit where known. Needs every link's inertia tensor (in the
  catalogue: the KR 10, the KR 210 and the youBot).
* **kinematic** — for arms without inertials (the thesis' crane, the SCARA, the KR 6's
  description has masses only): each joint follows the command through a first-order lag
  (:data:`LAG`, a drive's or a valve's response) within its speed and acceleration limits,
  and stops hard at its position limits.

Either way the arm is a plant of its own: its lag, inertia, gravity sag and end stops are
what the server's trajectory and PID have to cope with, measured, not assumed.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any, Literal

import numpy as np

from pyopenshowvar.arms import Arm
from pyopenshowvar.universal.tracking import joint_limits

from .backend import ArmBackend, FloatArray, JointState

__all__ = ["ENGINES", "KinematicPlant", "MujocoPlant", "SimulatedArm", "has_inertials"]

Engine = Literal["auto", "kinematic", "mujoco"]
ENGINES = ("auto", "kinematic", "mujoco")
#: First-order response of a kinematic drive (s).
LAG = 0.05
#: The most simulated time one feedback call catches up (s): beyond it the simulation slips.
MAX_CATCH_UP = 0.25


def has_inertials(arm: Arm) -> bool:
    """Whether every moving link has a mass and an inertia tensor (MuJoCo can simulate it)."""
    return all(j.inertial is not None and j.inertial.inertia is not None for j in arm.joints)


class KinematicPlant:
    """Joints that follow a velocity command with a lag, within speed/accel/position limits."""

    step_s = 0.002

    def __init__(self, arm: Arm, q0: FloatArray) -> None:
        self.speed, self.accel = joint_limits(arm)
        self.lower, self.upper = np.array(arm.lower), np.array(arm.upper)
        self.q = np.clip(np.array(q0, dtype=np.float64), self.lower, self.upper)
        self.qdot = np.zeros_like(self.q)

    def step(self, u: FloatArray, dt: float) -> None:
        wanted = np.clip(u, -self.speed, self.speed)
        dv = (wanted - self.qdot) * min(1.0, dt / LAG)
        self.qdot = self.qdot + np.clip(dv, -self.accel * dt, self.accel * dt)
        nxt = self.q + self.qdot * dt
        wall = (nxt <= self.lower) | (nxt >= self.upper)
        self.q = np.clip(nxt, self.lower, self.upper)
        self.qdot = np.where(wall, 0.0, self.qdot)


class MujocoPlant:
    """The arm in MuJoCo with velocity-servo drives (see the module docstring)."""

    step_s = 0.001
    #: Servo bandwidth (rad/s): gain = joint inertia × this; integral corner ω_i (1/s).
    BANDWIDTH = 150.0
    INTEGRAL = 30.0

    def __init__(self, arm: Arm, q0: FloatArray) -> None:
        import mujoco

        from pyopenshowvar.arms.urdf import to_urdf

        self._mj = mujoco
        self.model = mujoco.MjModel.from_xml_string(to_urdf(arm))
        self.model.opt.timestep = self.step_s
        if self.model.nq != arm.dof:
            raise ValueError(f"{arm.name}: MuJoCo made {self.model.nq} joints of {arm.dof}")
        self.data = mujoco.MjData(self.model)
        self._unit = np.where(arm.revolute, math.degrees(1.0), 1000.0)
        self.data.qpos[:] = np.asarray(q0, dtype=np.float64) / self._unit
        mujoco.mj_forward(self.model, self.data)
        full = np.zeros((arm.dof, arm.dof))
        mujoco.mj_fullM(self.model, self.data, full)
        # geared drives: the motor's inertia through the gearbox (armature) is of the order
        # of the link's; without it the light wrist joints of the youBot couple unstably
        self.model.dof_armature[:] = np.diag(full)
        self.gain = 2.0 * np.diag(full) * self.BANDWIDTH
        effort = np.array(arm.max_effort)
        self.effort = np.where(np.isfinite(effort), effort, np.inf)
        self.integral = np.zeros(arm.dof)

    @property
    def q(self) -> FloatArray:
        return np.asarray(self.data.qpos * self._unit)

    @property
    def qdot(self) -> FloatArray:
        return np.asarray(self.data.qvel * self._unit)

    def step(self, u: FloatArray, dt: float) -> None:
        e = np.asarray(u) / self._unit - self.data.qvel
        trial = self.integral + e * dt
        raw = self.gain * (e + self.INTEGRAL * trial)
        torque = np.clip(raw, -self.effort, self.effort)
        self.integral = np.where(torque == raw, trial, self.integral)  # no wind-up
        self.data.qfrc_applied[:] = torque
        self._mj.mj_step(self.model, self.data)


class SimulatedArm(ArmBackend):
    """An :class:`ArmBackend` simulated in this process (see the module docstring)."""

    switchable = True

    def __init__(
        self,
        arm: Arm,
        *,
        engine: Engine = "auto",
        q0: Any = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(arm)
        if engine not in ENGINES:
            raise ValueError(f"unknown engine {engine!r}: one of {', '.join(ENGINES)}")
        self.engine_choice = engine
        self.clock = clock
        self._q0 = q0
        self.u = np.zeros(arm.dof)
        self.plant: KinematicPlant | MujocoPlant = self._make(arm, q0)
        self.t = clock()
        #: Simulated time lost because the machine fell behind (s).
        self.slipped = 0.0

    def _make(self, arm: Arm, q0: Any) -> KinematicPlant | MujocoPlant:
        start = np.array(arm.home_q if q0 is None else q0, dtype=np.float64)
        use_mujoco = self.engine_choice == "mujoco" or (
            self.engine_choice == "auto" and has_inertials(arm)
        )
        if use_mujoco:
            if not has_inertials(arm):
                raise ValueError(f"{arm.name} has no inertia tensors: MuJoCo cannot simulate it")
            plant: KinematicPlant | MujocoPlant = MujocoPlant(arm, start)
        else:
            plant = KinematicPlant(arm, start)
        self.name = f"simulated {arm.key or arm.name} ({'mujoco' if use_mujoco else 'kinematic'})"
        return plant

    @property
    def engine(self) -> str:
        return "mujoco" if isinstance(self.plant, MujocoPlant) else "kinematic"

    def advance(self) -> None:
        """Step the simulation up to the clock's now."""
        now = self.clock()
        lag = now - self.t
        if lag > MAX_CATCH_UP:
            self.slipped += lag - MAX_CATCH_UP
            lag = MAX_CATCH_UP
        steps = int(lag / self.plant.step_s)
        for _ in range(steps):
            self.plant.step(self.u, self.plant.step_s)
        self.t = now - (lag - steps * self.plant.step_s)

    def state(self) -> JointState:
        return JointState(self.t, self.plant.q.copy(), self.plant.qdot.copy())

    async def start(self) -> JointState:
        self.t = self.clock()
        return self.state()

    async def feedback(self) -> JointState:
        self.advance()
        return self.state()

    async def command(self, u: FloatArray, dt: float) -> None:
        self.u = np.asarray(u, dtype=np.float64).copy()

    async def stop(self) -> None:
        self.u = np.zeros(self.arm.dof)

    async def set_arm(self, arm: Arm) -> JointState:
        self.plant = self._make(arm, None)
        self.arm = arm
        self.u = np.zeros(arm.dof)
        self.t = self.clock()
        return self.state()
