"""The control server of thesis §4.2.3.1 (Figure 4.23-a): control task + actuation task.

**Control task** (one step per new θ_a):

1. the set-point moves with the operator's stick, x_s,new = x_s,old + k·i·Δt (eq. 4.15; the
   thesis' k absorbs a fixed period, ours is in mm/s so the speed does not depend on the loop
   rate);
2. the end-effector's world position x_c from T_c = T_z·T_θ·T_φ·T_A (eq. 4.14): T_z from the PLC's
   heave, T_θ and T_φ from its angles corrected by the accelerometer, T_A = FK(θ_a);
3. a PID per translational axis on x_s − x_c gives the correction δx_d;
4. the platform's motion is the disturbance, and (thesis: "given as a negative input") enters as
   a feed-forward: the robot-base target is (T_z T_θ T_φ · T_mount)⁻¹ · [R_s | x_s + δx_d], with
   the platform pose *predicted* for when the robot will execute it (the measured command
   delay, :class:`~.estimation.LagEstimator`);
5. trajectory smoothing: the target's speed and acceleration are limited (no steps into the
   robot when the compensation is switched on or a sample jumps), and it is kept inside a box
   around the start pose.

**Actuation task**: writes the target to the robot (``HEAVE_TGT``, a FRAME the KRL program
``heave.src`` follows with ``PTP … C_PTP``: the KRC does the inverse kinematics, as in the thesis)
and reads θ_a (``$AXIS_ACT``) back, both pipelined on one KVP connection.

**Platform task**: writes the wave set-points (eq. 4.13) to the PLC and reads its state, 50 Hz.
The accelerometer's lines arrive through :class:`~.accel.AccelReader`. **Operator task**: polls
the input device; its toggle switches the compensation at run time.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pyopenshowvar.kinematics import KR6R900SIXX, fk_matrix, inv_transform, matrix_to_frame

from .estimation import ClockMapper, LagEstimator, PlatformEstimator
from .geometry import FloatArray, PlatformPose, platform_matrix
from .operator import OperatorInput, ScriptedOperator, hands_off
from .waves import WaveGenerator

__all__ = [
    "TARGET_VARIABLE",
    "ControlConfig",
    "ControlLaw",
    "ControlServer",
    "Smoother",
    "VectorPID",
]

log = logging.getLogger(__name__)
MODEL = KR6R900SIXX
#: The global FRAME the KRL program follows, and its ready flag.
TARGET_VARIABLE = "HEAVE_TGT"
READY_VARIABLE = "HEAVE_READY"


@dataclass(frozen=True)
class ControlConfig:
    """Gains and limits of the control server (defaults: the figures in docs/heave.md)."""

    #: eq. 4.15 scale: set-point speed (mm/s) at full stick.
    k: float = 100.0
    kp: float = 0.2
    ki: float = 0.3
    kd: float = 0.0
    #: Largest PID correction (mm).
    pid_limit: float = 20.0
    #: Smoothing limits of the robot target: mm/s, mm/s², deg/s, deg/s².
    max_speed: float = 1000.0
    max_accel: float = 10000.0
    max_rot_speed: float = 90.0
    max_rot_accel: float = 900.0
    #: Reach of the target around the start pose: mm (each axis) and degrees.
    reach: float = 250.0
    reach_deg: float = 15.0
    #: Command delay (s) to predict the platform over; None: measured on line.
    lead: float | None = None
    initial_lead: float = 0.05
    #: The prediction never reaches further ahead than this (s): beyond it a fit is a guess.
    max_lead: float = 0.25
    #: Roll/pitch from "fused" (PLC corrected by the accelerometer), "accel" (the thesis: the
    #: accelerometer alone) or "plc" (the PLC's registers alone): see PlatformEstimator.
    attitude: str = "fused"
    #: The accelerometer board's low-pass cut-off (Hz), to undo its delay.
    accel_cutoff: float = 5.0
    platform_period: float = 0.02
    operator_period: float = 0.02


class VectorPID:
    """PID per component with a clamped output and conditional integration (anti-windup)."""

    def __init__(self, n: int, kp: float, ki: float, kd: float, limit: float) -> None:
        self.kp, self.ki, self.kd, self.limit = kp, ki, kd, limit
        self.integral = np.zeros(n)
        self._last: FloatArray | None = None

    def reset(self) -> None:
        self.integral[:] = 0.0
        self._last = None

    def update(self, error: npt.ArrayLike, dt: float) -> FloatArray:
        e = np.asarray(error, dtype=np.float64)
        dt = max(dt, 1e-6)
        deriv = np.zeros_like(e) if self._last is None else (e - self._last) / dt
        self._last = e
        trial = self.integral + e * dt
        raw = self.kp * e + self.ki * trial + self.kd * deriv
        out = np.clip(raw, -self.limit, self.limit)
        self.integral = np.where(out != raw, self.integral, trial)
        return out


class Smoother:
    """Speed- and acceleration-limited tracking of a target vector (time-optimal braking)."""

    def __init__(
        self, initial: npt.ArrayLike, max_speed: npt.ArrayLike, max_accel: npt.ArrayLike
    ) -> None:
        self.state = np.array(initial, dtype=np.float64)
        self.speed = np.zeros_like(self.state)
        self.vmax = np.broadcast_to(np.asarray(max_speed, float), self.state.shape).copy()
        self.amax = np.broadcast_to(np.asarray(max_accel, float), self.state.shape).copy()

    def update(self, target: npt.ArrayLike, dt: float) -> FloatArray:
        dt = min(max(dt, 1e-4), 0.05)
        e = np.asarray(target, dtype=np.float64) - self.state
        wanted = np.sign(e) * np.minimum(
            np.minimum(self.vmax, np.sqrt(2.0 * self.amax * np.abs(e))), np.abs(e) / dt
        )
        self.speed = self.speed + np.clip(wanted - self.speed, -self.amax * dt, self.amax * dt)
        self.state = self.state + self.speed * dt
        return self.state.copy()


def _wrap180(deg: FloatArray) -> FloatArray:
    return (deg + 180.0) % 360.0 - 180.0


class ControlLaw:
    """One control step at a time (no I/O): see the module docstring, steps 1–5."""

    def __init__(
        self, config: ControlConfig, theta0: npt.ArrayLike, mount: FloatArray | None = None
    ) -> None:
        self.config = config
        self.mount = np.eye(4) if mount is None else np.asarray(mount, float)
        base_flange = fk_matrix(MODEL, np.asarray(theta0, float))
        world = platform_matrix(PlatformPose()) @ self.mount @ base_flange
        self.x_s = world[:3, 3].copy()
        self.x_s0 = self.x_s.copy()
        self.R_s = world[:3, :3].copy()
        self.base0 = np.asarray(matrix_to_frame(base_flange), float)
        self.pid = VectorPID(3, config.kp, config.ki, config.kd, config.pid_limit)
        limits_v = [config.max_speed] * 3 + [config.max_rot_speed] * 3
        limits_a = [config.max_accel] * 3 + [config.max_rot_accel] * 3
        self.smoother = Smoother(self.base0, limits_v, limits_a)
        self.compensate = False
        self.x_c = self.x_s.copy()
        self.delta = np.zeros(3)

    def world_flange(self, pose: PlatformPose, theta: npt.ArrayLike) -> FloatArray:
        """T_c = T_z T_θ T_φ · T_mount · T_A (eq. 4.14)."""
        return platform_matrix(pose) @ self.mount @ fk_matrix(MODEL, np.asarray(theta, float))

    def step(
        self,
        dt: float,
        theta_a: npt.ArrayLike,
        pose_now: PlatformPose,
        pose_pred: PlatformPose,
        stick: npt.ArrayLike,
    ) -> FloatArray:
        """The next robot-base target X, Y, Z, A, B, C (mm, deg)."""
        cfg = self.config
        step = cfg.k * np.clip(np.asarray(stick, float), -1.0, 1.0) * dt  # eq. 4.15
        self.x_s = np.clip(self.x_s + step, self.x_s0 - cfg.reach, self.x_s0 + cfg.reach)
        self.x_c = self.world_flange(pose_now, theta_a)[:3, 3]
        if self.compensate:
            self.delta = self.pid.update(self.x_s - self.x_c, dt)
            desired = np.eye(4)
            desired[:3, :3] = self.R_s
            desired[:3, 3] = self.x_s + self.delta
            base = inv_transform(platform_matrix(pose_pred) @ self.mount) @ desired
            raw = np.asarray(matrix_to_frame(base), float)
        else:
            self.pid.reset()
            self.delta = np.zeros(3)
            raw = self.base0.copy()
            raw[:3] += self.x_s - self.x_s0  # uncompensated: the stick moves the robot in its base
        prev = self.smoother.state
        raw[3:] = prev[3:] + _wrap180(raw[3:] - prev[3:])  # no 360° detours near ±180°
        target = self.smoother.update(raw, dt)
        lo = np.concatenate([self.base0[:3] - cfg.reach, self.base0[3:] - cfg.reach_deg])
        hi = np.concatenate([self.base0[:3] + cfg.reach, self.base0[3:] + cfg.reach_deg])
        target = np.clip(target, lo, hi)
        self.smoother.state = target.copy()
        return target


def frame_text(pose: npt.ArrayLike) -> str:
    x, y, z, a, b, c = (float(v) for v in np.asarray(pose, float))
    return f"{{X {x:.3f}, Y {y:.3f}, Z {z:.3f}, A {a:.4f}, B {b:.4f}, C {c:.4f}}}"


class ControlServer:
    """The tasks around one :class:`ControlLaw`; ``await start()``, … ``await stop()``."""

    def __init__(
        self,
        kvp: Any,
        platform: Any,
        accel: Any = None,
        *,
        operator: OperatorInput | None = None,
        config: ControlConfig | None = None,
        waves: WaveGenerator | None = None,
        mount: FloatArray | None = None,
        max_rows: int = 200_000,
    ) -> None:
        self.kvp, self.platform, self.accel = kvp, platform, accel
        self.operator = operator or ScriptedOperator(hands_off)
        self.config = config or ControlConfig()
        self.waves = waves
        self.mount = mount
        cfg = self.config
        if cfg.attitude != "plc" and accel is None:
            raise ValueError(f"attitude {cfg.attitude!r} needs the accelerometer stream")
        self.estimator = PlatformEstimator(
            attitude=cfg.attitude, accel_lag=1.0 / (2.0 * math.pi * cfg.accel_cutoff)
        )
        self.lag = LagEstimator(cfg.initial_lead if cfg.lead is None else cfg.lead)
        self.plc_clock, self.accel_clock = ClockMapper(), ClockMapper()
        self.law: ControlLaw | None = None
        self.rows: deque[dict[str, float]] = deque(maxlen=max_rows)
        self.platform_rows: deque[dict[str, float]] = deque(maxlen=max_rows)
        self.wave_t0 = 0.0
        self.stick = np.zeros(3)
        self.quit = asyncio.Event()
        self.error: BaseException | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._first_state = asyncio.Event()
        self._stopping = False

    # --- life cycle ------------------------------------------------------------------------------
    async def wait_robot_ready(self, timeout: float = 15.0) -> FloatArray:
        """Wait for the KRL program's HEAVE_READY, then return θ_a (the start pose)."""
        deadline = time.monotonic() + timeout
        while True:
            if str(await self.kvp.read(READY_VARIABLE)).strip().upper() == "TRUE":
                return np.asarray(await self.kvp.read_joint_angles(), float)
            if time.monotonic() > deadline:
                raise TimeoutError(
                    f"{READY_VARIABLE} did not become TRUE within {timeout} s: is heave.src running?"
                )
            await asyncio.sleep(0.05)

    async def start(self, *, wave_t0: float | None = None) -> None:
        """Start the tasks once the robot program is ready, the platform has answered and (unless
        the attitude is the PLC's alone) the board's samples arrive. A start that fails raises
        the platform's own error (or a TimeoutError naming what did not answer) and leaves no
        task running: nothing keeps driving the platform for a server nobody got to stop."""
        theta0 = await self.wait_robot_ready()
        self.law = ControlLaw(self.config, theta0, self.mount)
        self.wave_t0 = time.monotonic() if wave_t0 is None else wave_t0
        if self.accel is not None:
            self.accel.on_sample = self._on_accel
        loop = asyncio.get_running_loop()
        self._tasks = [loop.create_task(self._guard(self._platform_task()), name="platform")]
        try:
            # a failed first request ends the platform task: its error, not a wait of 5 s
            await self._wait_for(
                lambda: self._first_state.is_set() or self.error is not None,
                5.0,
                "the platform PLC",
            )
            if self.error is not None:
                raise self.error
            if self.config.attitude != "plc":
                await self._wait_for(lambda: self.estimator.ready, 3.0, "the accelerometer stream")
        except BaseException:
            await self._end_tasks(3.0)
            raise
        self._tasks += [
            loop.create_task(self._guard(self._actuation_task(theta0)), name="actuation"),
            loop.create_task(self._guard(self._operator_task()), name="operator"),
        ]

    async def stop(self, timeout: float = 3.0) -> None:
        """End the tasks (see :meth:`_end_tasks`), release the input device and raise the error
        that stopped a task, if one did."""
        await self._end_tasks(timeout)
        self.operator.close()
        if self.error is not None:
            raise self.error

    async def _end_tasks(self, timeout: float) -> None:
        """Let the I/O tasks finish their request in flight (a request cancelled half-way would
        leave its late answer to confuse the next one), then cancel whatever still runs."""
        self._stopping = True
        if self._tasks:
            await asyncio.wait(self._tasks, timeout=timeout)
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._tasks.clear()

    @property
    def compensate(self) -> bool:
        return self.law is not None and self.law.compensate

    def set_compensation(self, on: bool) -> None:
        if self.law is not None:
            self.law.compensate = on
            log.info("compensation %s", "on" if on else "off")

    def _on_accel(self, sample: Any) -> None:
        t = self.accel_clock.to_local(sample.millis / 1000.0, sample.received)
        self.estimator.add_accel(t, sample.roll, sample.pitch)

    async def _guard(self, coro: Any) -> None:
        try:
            await coro
        except asyncio.CancelledError:
            raise
        except BaseException as exc:  # one task failing stops the server
            self.error = exc
            self.quit.set()

    @staticmethod
    async def _wait_for(cond: Any, timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not cond():
            if time.monotonic() > deadline:
                raise TimeoutError(f"no data from {what} within {timeout} s")
            await asyncio.sleep(0.01)

    # --- tasks -------------------------------------------------------------------------------------
    async def _platform_task(self) -> None:
        period = self.config.platform_period
        next_beat = 0.0
        while not self._stopping:
            t0 = time.monotonic()
            if self.waves is not None:
                await self.platform.set_pose(self.waves.pose(t0 - self.wave_t0))
            elif t0 >= next_beat:
                await self.platform.heartbeat()
                next_beat = t0 + 0.25
            state = await self.platform.read_state()
            t = self.plc_clock.to_local(state.time, time.monotonic())
            self.estimator.add_plc(t, state.heave, state.roll, state.pitch)
            self.platform_rows.append(
                {"t": t, "heave": state.heave, "roll": state.roll, "pitch": state.pitch,
                 "status": float(state.status), "beta1": state.beta[0], "beta2": state.beta[1],
                 "beta3": state.beta[2]}
            )  # fmt: skip
            self._first_state.set()
            await asyncio.sleep(max(0.0, period - (time.monotonic() - t0)))

    async def _operator_task(self) -> None:
        while not self._stopping:
            cmd = self.operator.poll(time.monotonic())
            self.stick = cmd.stick
            if cmd.toggle:
                self.set_compensation(not self.compensate)
            if cmd.quit:
                self.quit.set()
            await asyncio.sleep(self.config.operator_period)

    async def _actuation_task(self, theta0: FloatArray) -> None:
        assert self.law is not None
        law, kvp = self.law, self.kvp
        target = law.base0.copy()
        theta_a, t_prev = theta0, time.monotonic()
        while not self._stopping:
            t_send = time.monotonic()
            _, theta = await asyncio.gather(
                kvp.write(TARGET_VARIABLE, frame_text(target)), kvp.read_joint_angles()
            )
            t_a = time.monotonic()
            theta_a = np.asarray(theta, float)
            self.lag.command(t_send, target[:3])
            self.lag.measured(t_a, fk_matrix(MODEL, theta_a)[:3, 3])
            target = self._control_step(t_a, t_a - t_prev, theta_a)
            t_prev = t_a

    def _control_step(self, t: float, dt: float, theta_a: FloatArray) -> FloatArray:
        assert self.law is not None
        law, cfg = self.law, self.config
        # the target holds until the next write, one loop period later: aim at its middle
        measured = self.lag.value + 0.5 * min(dt, 0.05)
        lead = min(cfg.lead if cfg.lead is not None else measured, cfg.max_lead)
        now = self.estimator.pose_at(t, max_ahead=cfg.max_lead)
        pred = self.estimator.pose_at(t + lead, max_ahead=cfg.max_lead)
        target = law.step(dt, theta_a, now, pred, self.stick)
        row = {"t": t, "dt": dt, "comp": float(law.compensate), "lead": lead}
        for name, vec in (("xs", law.x_s), ("xc", law.x_c), ("delta", law.delta)):
            row.update({f"{name}_{a}": float(v) for a, v in zip("xyz", vec, strict=True)})
        row.update({f"tgt_{k}": float(v) for k, v in zip("xyzabc", target, strict=True)})
        row.update({f"theta_{i + 1}": float(v) for i, v in enumerate(theta_a)})
        row.update({"est_z": now.z, "est_phi": now.phi, "est_theta": now.theta})
        self.rows.append(row)
        return target
