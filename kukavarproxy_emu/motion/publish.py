"""Publishing one interpolation cycle: the motion variables the KRC updates every 12 ms.

Split from the kernel so the planning code and the "what does a client read" code stay small.
:class:`Publisher` is mixed into :class:`~kukavarproxy_emu.motion.kernel.MotionKernel`; it
writes ``$AXIS_ACT``, ``$AXIS_ACT_MEAS``, ``$POS_ACT``, ``$POS_ACT_MES``, ``$VEL_AXIS_ACT``,
``$TORQUE_AXIS_ACT`` and ``$VEL_ACT`` in one synchronous step, and skips the write when nothing
observable changed (at rest the store's read cache stays valid and HOME keeps its exact text).

That is the **ideal** plant: the published axes are the set-point and the torque is the
kinematics package's statics. With a plant attached (``plant``, the robot's ``--plant
dynamic``) every cycle hands the set-point to it instead, and the plant publishes what its
sensors measure (:mod:`kukavarproxy_emu.plant`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pyopenshowvar.kinematics import (
    Load,
    RobotModel,
    fk_matrix,
    forward,
    gravity_torques,
    status_turn,
    wrench_to_torques,
)
from pyopenshowvar.krl import E6Axis, E6Pos, Struct

from ..store import VariableStore
from .profiles import FloatArray

if TYPE_CHECKING:
    from ..plant import Plant

__all__ = ["Publisher"]

#: External axes E1..E6 stay at zero (the KR 6 has none).
_E6 = np.zeros(6)


class Publisher:
    """The variable-writing half of the motion kernel (state lives in the kernel)."""

    store: VariableStore
    model: RobotModel
    ipo: float
    noise: float
    inertia: FloatArray
    q: FloatArray
    qd: FloatArray
    qdd: FloatArray
    _rng: np.random.Generator
    _tcp: FloatArray
    _has_wrench: bool
    _published: tuple[object, ...] | None
    #: The physical robot the set-points drive; None: the ideal plant (set-point = measured).
    plant: Plant | None = None

    def _read_frames(self) -> tuple[FloatArray, FloatArray]:
        raise NotImplementedError  # provided by the kernel

    def _tcp_position(self, q: FloatArray) -> FloatArray:
        return np.asarray(fk_matrix(self.model, q)[:3, 3], dtype=np.float64)

    def wrench(self) -> FloatArray:
        """The external wrench EMU_WRENCH (N, Nm; TCP, $ROBROOT axes), zeros if undeclared."""
        if not self._has_wrench:
            return np.zeros(6)
        w = self.store.get("EMU_WRENCH")
        if not isinstance(w, Struct):
            return np.zeros(6)
        return np.array([float(w.get(k) or 0.0) for k in ("FX", "FY", "FZ", "MX", "MY", "MZ")])  # type: ignore[arg-type]

    def _key(self) -> tuple[object, ...]:
        """Everything the published variables depend on."""
        tool, base = self.store.get("$TOOL"), self.store.get("$BASE")
        load, wrench = (
            self.store.get("$LOAD"),
            self.store.get("EMU_WRENCH") if self._has_wrench else None,
        )
        return (self.q.tobytes(), self.qd.tobytes(), self.qdd.tobytes(), tool, base, load, wrench)

    def publish(self, *, force: bool = False) -> None:
        """Write the motion variables, skipping the write when nothing observable changed
        (at rest the store's read cache stays valid and HOME keeps its original text)."""
        if self.plant is not None:
            self.plant.step(self.q)
            return
        key = self._key()
        if not force and key == self._published and not self.noise:
            return
        self._published = key
        tool, base = self._read_frames()
        model, q = self.model, self.q
        q_meas = q + self._rng.normal(0.0, self.noise, 6) if self.noise else q
        torque = self._torque(tool)
        tcp = self._tcp_position(q)
        vel_tcp = float(np.linalg.norm(tcp - self._tcp)) / self.ipo / 1000.0
        self._tcp = tcp
        store = self.store
        store.set_system("$AXIS_ACT", E6Axis.from_numpy(np.concatenate([q, _E6])))
        store.set_system("$AXIS_ACT_MEAS", E6Axis.from_numpy(np.concatenate([q_meas, _E6])))
        pos = self._pos(q, tool, base)
        store.set_system("$POS_ACT", pos)
        # without measurement noise the measured pose is the set-point pose: one FK, not two
        store.set_system("$POS_ACT_MES", pos if q_meas is q else self._pos(q_meas, tool, base))
        store.set_system("$VEL_AXIS_ACT", [*(self.qd / model.max_speed * 100.0), *_E6])
        store.set_system("$TORQUE_AXIS_ACT", [*torque, *_E6])
        store.set_system("$VEL_ACT", vel_tcp)

    def _torque(self, tool: FloatArray) -> FloatArray:
        """The ideal plant's motor torques: statics with $LOAD and EMU_WRENCH, plus the
        diagonal inertia times the commanded acceleration."""
        model, q = self.model, self.q
        torque = gravity_torques(model, q, Load.from_krl(self.store.get("$LOAD")))
        torque = torque + model.torque_sign * self.inertia * np.radians(self.qdd)
        wrench = self.wrench()
        if np.any(wrench):
            torque = torque + wrench_to_torques(model, q, wrench, tool)
        return np.asarray(torque + 0.0)  # + 0.0: no "-0.0" where a torque is zero

    def publish_torque(self) -> None:
        """Write the ideal plant's ``$TORQUE_AXIS_ACT`` for the state as it is (start-up: the
        model's torques, not the static table's rounded ones); the other variables already
        read what the model gives."""
        torque = self._torque(self._read_frames()[0])
        self.store.set_system("$TORQUE_AXIS_ACT", [*torque, *_E6])

    def _pos(self, q: FloatArray, tool: FloatArray, base: FloatArray) -> E6Pos:
        s, t = status_turn(self.model, q)
        xyzabc = forward(self.model, q, tool, base)
        return E6Pos.from_numpy(np.concatenate([xyzabc, _E6]), s=int(s), t=int(t))
