"""The controller's sensors on the dynamic plant: what a KRC4 measures and publishes.

:class:`Sensors` is mixed into :class:`~.dynamic.DynamicPlant` (state lives there). Each IPO
cycle the plant marks the motion variables stale (:meth:`VariableStore.defer`); the first
read of any of them calls :meth:`Sensors.publish`, which writes all of them from this cycle's
state: encoder axes with seeded noise, the nominal forward kinematics the controller computes
from them, axis speeds, motor torques with seeded noise and the TCP speed. See
docs/emulator-robot.md ("Which variable is what").
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from pyopenshowvar.kinematics import RobotModel, fk_matrix, matrix_to_frame, status_turn
from pyopenshowvar.krl import E6Axis, E6Pos

from ..store import VariableStore
from .mjcf import frame_matrix
from .params import FloatArray

__all__ = ["MOTION_VARIABLES", "NOISE_BLOCK", "Sensors"]

#: The variables a plant publishes (base names).
MOTION_VARIABLES = (
    "$AXIS_ACT", "$AXIS_ACT_MEAS", "$POS_ACT", "$POS_ACT_MES", "$VEL_AXIS_ACT",
    "$TORQUE_AXIS_ACT", "$VEL_ACT",
)  # fmt: skip
#: Cycles of sensor noise drawn at once.
NOISE_BLOCK = 256
_E6 = np.zeros(6)
_ZEROS = [0.0] * 6  # E1..E6 of the per-axis arrays


class Sensors:
    """The reading half of the dynamic plant."""

    store: VariableStore
    model: RobotModel
    seed: int
    ticks: int
    resting: bool
    encoder_noise: float
    torque_noise: FloatArray
    torque: FloatArray
    _mj: Any
    _data: Any
    _tcp_site: int
    _tool: FloatArray
    _q_set: FloatArray
    _q_set_deg: FloatArray

    def _init_sensors(self) -> None:
        self._st_key, self._st = b"", (0, 0)
        self._noise_block = -1
        self._noise = np.zeros((NOISE_BLOCK, 12))
        self._base_seen: object = None
        self._base: FloatArray | None = None

    def _read_frame(self, name: str) -> FloatArray:
        raise NotImplementedError  # provided by the plant

    def _defer(self) -> None:
        self.store.defer(MOTION_VARIABLES, self.publish)

    def measure(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """This cycle's sensor readings: axes (deg), axis speeds (deg/s), torques (Nm)."""
        noise = self._noise_sample(self.ticks)
        d = self._data
        # at rest the state was snapped onto the set-point: report it without a rad/deg trip
        q = self._q_set_deg.copy() if self.resting else np.degrees(d.qpos)
        if self.encoder_noise:
            q = q + noise[:6] * self.encoder_noise
        tau = self.torque * self.model.torque_sign
        if np.any(self.torque_noise):
            tau = tau + noise[6:] * self.torque_noise
        return q, np.degrees(d.qvel), tau

    def _noise_sample(self, cycle: int) -> FloatArray:
        """Standard normal noise of one cycle: a function of ``(seed, cycle)`` only, drawn in
        blocks of ``NOISE_BLOCK`` cycles (one generator per block, not per reading)."""
        block, row = divmod(cycle, NOISE_BLOCK)
        if block != self._noise_block:
            rng = np.random.default_rng((self.seed, block))
            self._noise = rng.standard_normal((NOISE_BLOCK, 12))
            self._noise_block = block
        return np.asarray(self._noise[row])

    def _base_matrix(self) -> FloatArray | None:
        """$BASE as a 4×4 transform (None for $NULLFRAME), converted when it changes."""
        base = self.store.get("$BASE")
        if base is not self._base_seen:
            frame = self._read_frame("$BASE")
            self._base_seen = base
            self._base = frame_matrix(frame) if np.any(frame) else None
        return self._base

    def _status_turn(self) -> tuple[int, int]:
        """S and T of the set-point: the configuration the controller commands (a measured
        axis jittering around 0° by encoder noise does not flip a turn bit)."""
        key = self._q_set.tobytes()
        if key != self._st_key:
            s, t = status_turn(self.model, np.degrees(self._q_set))
            self._st_key, self._st = key, (int(s), int(t))
        return self._st

    def publish(self) -> None:
        """Write this cycle's readings into the store (called by the store on the first read)."""
        q, qd, tau = self.measure()
        store, model = self.store, self.model
        axes = E6Axis.from_numpy(np.concatenate([q, _E6]))
        store.set_system("$AXIS_ACT", axes, trusted=True)
        store.set_system("$AXIS_ACT_MEAS", axes, trusted=True)
        s, t = self._status_turn()
        xyzabc = matrix_to_frame(fk_matrix(model, q, self._tool, self._base_matrix()))
        pos = E6Pos.from_numpy(np.concatenate([xyzabc, _E6]), s=int(s), t=int(t))
        store.set_system("$POS_ACT", pos, trusted=True)
        store.set_system("$POS_ACT_MES", pos, trusted=True)
        store.set_system(
            "$VEL_AXIS_ACT", [float(v) for v in qd / model.max_speed * 100.0] + _ZEROS, trusted=True
        )
        store.set_system("$TORQUE_AXIS_ACT", [float(v) for v in tau] + _ZEROS, trusted=True)
        v = np.zeros(6)
        mujoco.mj_objectVelocity(
            self._mj, self._data, mujoco.mjtObj.mjOBJ_SITE, self._tcp_site, v, 0
        )
        store.set_system("$VEL_ACT", float(np.linalg.norm(v[3:])), trusted=True)
