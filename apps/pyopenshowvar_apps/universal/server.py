"""The control server of the universal architecture: input → solver → trajectory → arm.

Thesis Fig. 2.13: a client-server architecture; the input device is a client, the server maps
its fixed DOFs to the arm's variable DOFs with an interchangeable solver, and the arm (a
simulation, an external simulator, a real robot) reports θ_a and θ̇_a back. One
:meth:`ControlServer.tick`, at ``rate_hz``:

1. θ_a, θ̇_a from the :class:`~.backend.ArmBackend`;
2. the device's latest :class:`~.inputs.InputSample`; run-time switches (arm, solver, mode)
   it carries are applied first;
3. **safety**: a device that disconnected, or whose last sample is older than ``deadline``,
   stops the arm (velocity command zero, the reference held where the arm is): nothing moves
   unless a device that is still there asks for it. In position mode the return to the start
   on release therefore happens only while the device is connected and sending;
4. position mode: ``x_ds = k_p·s + x_w`` (eq. 2.7), ``θ_d = solver.position(x_ds, θ_a)``;
   velocity mode: ``ẋ_ds = k_v·s`` (eq. 2.8), ``θ̇_d = solver.velocity(θ_a, ẋ_ds, Δt)``;
5. the :class:`~pyopenshowvar.universal.Trajectory` and the per-joint
   :class:`~pyopenshowvar.universal.TrackingPID` (Fig. 2.15) turn them into a joint velocity
   command within the arm's limits, sent to the backend.

``x_w`` is the tip's position when the mode, solver or arm was last (re)selected, so a
released device in position mode brings the tip back there. Every tick is recorded
(:attr:`ControlServer.ticks`, bounded) for the status line, the 3D view and the benchmarks.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pyopenshowvar.arms import load_arm
from pyopenshowvar.universal import BUDGET, SOLVERS, Solver, make_solver, solver_names
from pyopenshowvar.universal.mapping import MODES, InputMapping
from pyopenshowvar.universal.tracking import TrackingPID, Trajectory, joint_limits

from .backend import ArmBackend, BackendError, FloatArray, JointState
from .inputs import InputDevice, InputSample

__all__ = ["ControlServer", "Tick"]

log = logging.getLogger(__name__)

#: Ticks kept for the status, the view and the benchmarks.
HISTORY = 4096


@dataclass(frozen=True)
class Tick:
    """One control cycle, as recorded."""

    t: float
    dt: float
    alive: bool
    mode: str
    solver: str
    signal: FloatArray
    q: FloatArray
    qdot: FloatArray
    tip: FloatArray
    #: Position mode: x_ds; velocity mode: x_a + ẋ_ds·Δt (mm). NaN while stopped.
    target: FloatArray
    #: θ_d (position) or θ̇_d (velocity) from the solver; NaN while stopped.
    setpoint: FloatArray
    command: FloatArray
    solve_ms: float = math.nan
    solver_error_mm: float = math.nan


@dataclass
class _Pending:
    items: list[tuple[str, str]] = field(default_factory=list)


class ControlServer:
    """See the module docstring. ``arms`` is the cycle ``arm next`` walks through."""

    def __init__(
        self,
        backend: ArmBackend,
        device: InputDevice,
        *,
        solver: str = "dls",
        mode: str = "velocity",
        rate_hz: float = 50.0,
        budget: float = BUDGET,
        k_p: float | None = None,
        k_v: float | None = None,
        deadline: float = 0.25,
        arms: Sequence[str] = (),
        solver_options: dict[str, Any] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if mode not in MODES:
            raise ValueError(f"mode must be position or velocity, not {mode!r}")
        if not 1.0 <= rate_hz <= 500.0:
            raise ValueError(f"rate must be 1..500 Hz, got {rate_hz:g}")
        self.backend, self.device = backend, device
        self.solver_name, self.mode = solver, str(mode)
        self.period, self.budget = 1.0 / rate_hz, budget
        self.k_p, self.k_v, self.deadline = k_p, k_v, deadline
        self.arms = list(arms)
        self.solver_options = dict(solver_options or {})
        self.clock = clock
        self.ticks: collections.deque[Tick] = collections.deque(maxlen=HISTORY)
        self.message = ""
        self.quit = False
        self._pending = _Pending()
        self._last_t: float | None = None
        self._stopped = True
        self.state: JointState | None = None

    # --------------------------------------------------------------------------- set-up
    async def start(self) -> None:
        """Start the arm and the device and set everything up for the current arm."""
        state = await self.backend.start()
        await self.device.start()
        self._configure(state)

    def _configure(self, state: JointState) -> None:
        arm = self.backend.arm
        self.solver: Solver = make_solver(
            self.solver_name, arm, budget=self.budget, **self.solver_options
        )
        self.state = state
        self.box = self.solver.workspace
        self.mapping = InputMapping.for_workspace(
            self.box, self.solver.fk(state.q), k_p=self.k_p, k_v=self.k_v
        )
        self.speed, accel = joint_limits(arm)
        caps = self.backend.speed_caps()
        if caps is not None:
            self.speed = np.fmin(self.speed, caps)
        self.trajectory = Trajectory(arm, state.q, speed=self.speed, accel=accel)
        self.pid = TrackingPID(self.speed)
        self._last_t = None

    def request(self, key: str, value: str) -> None:
        """Ask for a switch (``arm``, ``solver``, ``mode``; ``next``/``toggle``) or ``quit``;
        applied at the start of the next tick."""
        self._pending.items.append((key, value))

    async def _apply(self, commands: Sequence[tuple[str, str]]) -> None:
        for key, value in commands:
            try:
                await self._switch(key, value)
            except (ValueError, BackendError) as exc:
                self.message = str(exc)
                log.warning("switch %s=%s refused: %s", key, value, exc)

    async def _switch(self, key: str, value: str) -> None:
        assert self.state is not None
        if key == "quit":
            self.quit = True
            return
        await self.backend.stop()
        if key == "mode":
            mode = {"position": "velocity", "velocity": "position"}[self.mode]
            new = mode if value == "toggle" else value
            if new not in MODES:
                raise ValueError(f"mode must be position or velocity, not {value!r}")
            self.mode = new
        elif key == "solver":
            names = solver_names(self.backend.arm)
            name = names[(names.index(self.solver_name) + 1) % len(names)] if (
                value == "next" and self.solver_name in names) else value  # fmt: skip
            if name == "next":
                name = names[0]
            make_solver(name, self.backend.arm, budget=self.budget)  # raises if not for this arm
            self.solver_name = name
        elif key == "arm":
            arms = self.arms or [self.backend.arm.key]
            current = self.backend.arm.key
            name = arms[(arms.index(current) + 1) % len(arms)] if (
                value == "next" and current in arms) else value  # fmt: skip
            arm = load_arm(name)
            self.state = await self.backend.set_arm(arm)
            if self.solver_name not in solver_names(arm):
                self.message = f"{self.solver_name} does not apply to {arm.key}: using dls"
                self.solver_name = "dls"
        else:
            raise ValueError(f"unknown switch {key!r}")
        self.state = await self.backend.feedback()
        self._configure(self.state)
        self._stopped = True
        log.info("now %s, %s, %s mode", self.backend.arm.key, self.solver_name, self.mode)

    # ----------------------------------------------------------------------------- loop
    async def tick(self) -> Tick:
        """One control cycle (see the module docstring)."""
        now = self.clock()
        if self._pending.items:
            items, self._pending.items = self._pending.items, []
            await self._apply(items)
        state = await self.backend.feedback()
        self.state = state
        sample = self.device.poll(now)
        if sample is not None and sample.commands:
            await self._apply(sample.commands)
            state = self.state
        dt = self.period if self._last_t is None else now - self._last_t
        dt = min(max(dt, 0.2 * self.period), 3.0 * self.period)
        self._last_t = now
        tip = self.solver.fk(state.q)
        n = len(state.q)
        nan3, nan_n = np.full(3, np.nan), np.full(n, np.nan)
        if not self._alive(sample, now):
            if not self._stopped:
                await self.backend.stop()
                self.trajectory.hold(state.q)
                self.pid.reset()
                self._stopped = True
            tick = Tick(now, dt, False, self.mode, self.solver_name, np.zeros(3), state.q,
                        state.qdot, tip, nan3, nan_n, np.zeros(n))  # fmt: skip
            self.ticks.append(tick)
            return tick
        assert sample is not None
        if self._stopped:
            self.trajectory.hold(state.q)
            self.pid.reset()
            self._stopped = False
        s = InputMapping.signal(sample.signal)
        if self.mode == "position":
            target = self.mapping.position(s)
            setpoint = self.solver.position(target, state.q)
            self.trajectory.to_position(setpoint, dt)
        else:
            xdot = self.mapping.velocity(s)
            target = tip + xdot * dt
            setpoint = self.solver.velocity(state.q, xdot, dt)
            self.trajectory.with_velocity(setpoint, dt)
        info = self.solver.last
        u = self.pid.update(self.trajectory.ref, self.trajectory.ref_dot, state.q, state.qdot, dt)
        await self.backend.command(u, dt)
        tick = Tick(now, dt, True, self.mode, self.solver_name, s, state.q, state.qdot, tip,
                    target, setpoint, u, 1e3 * info.time_s, info.error_mm)  # fmt: skip
        self.ticks.append(tick)
        return tick

    def _alive(self, sample: InputSample | None, now: float) -> bool:
        return sample is not None and sample.connected and now - sample.t <= self.deadline

    async def run(self, duration: float | None = None) -> None:
        """Tick at the rate until ``duration`` s, a quit command or cancellation; the arm is
        stopped on the way out, whatever the reason."""
        start = self.clock()
        next_at = start
        try:
            while not self.quit and (duration is None or self.clock() - start < duration):
                await self.tick()
                next_at = max(next_at + self.period, self.clock())
                await asyncio.sleep(max(0.0, next_at - self.clock()))
        finally:
            with contextlib.suppress(Exception):
                await asyncio.shield(self.backend.stop())

    async def close(self) -> None:
        """Stop the arm, release the device and the backend."""
        try:
            await self.backend.stop()
        finally:
            await self.device.close()
            await self.backend.close()

    # --------------------------------------------------------------------------- status
    def status(self) -> dict[str, Any]:
        """Plain data for the status line and the 3D view."""
        arm = self.backend.arm
        last = self.ticks[-1] if self.ticks else None
        recent = [t for t in self.ticks if last is not None and last.t - t.t <= 1.0]
        rate = (len(recent) - 1) / (recent[-1].t - recent[0].t) if len(recent) > 2 else 0.0
        out: dict[str, Any] = {
            "arm": arm.key or arm.name, "title": arm.name, "dof": arm.dof,
            "backend": self.backend.name, "solver": self.solver_name, "mode": self.mode,
            "solvers": solver_names(arm), "all_solvers": list(SOLVERS), "arms": self.arms,
            "switchable": self.backend.switchable, "rate_hz": round(rate, 1),
            "message": self.message, "scale_mm": self.box.scale,
        }  # fmt: skip
        if last is not None:
            out.update(
                alive=last.alive,
                q=[round(float(v), 3) for v in last.q],
                tip=[round(float(v), 2) for v in last.tip],
                target=None if not last.alive else [round(float(v), 2) for v in last.target],
                solve_ms=_rounded(last.solve_ms, 2),
                error_mm=_rounded(last.solver_error_mm, 3),
                frames=arm_frames(arm, last.q),
            )
        return out


def _rounded(v: float, digits: int) -> float | None:
    return None if math.isnan(v) else round(v, digits)


def arm_frames(arm: Any, q: FloatArray) -> list[list[float]]:
    """The base frame, every link frame and the flange, each as x, y, z axes and origin (mm):
    what the web pad's 3D view draws its skeleton from."""
    frames = arm.link_frames(q)
    mats = [np.asarray(arm.base), *frames, frames[-1] @ arm.flange]
    return [[round(float(v), 3) for v in np.concatenate([m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3]])]
            for m in mats]  # fmt: skip
