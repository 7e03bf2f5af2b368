"""The controller's sensors on the dynamic plant: what a KRC4 measures and publishes.

:class:`Sensors` is mixed into :class:`~.dynamic.DynamicPlant` (state lives there). Each IPO
cycle the plant marks the motion variables stale (:meth:`VariableStore.defer`), in groups;
the first read of a variable fills its group from this cycle's state: encoder axes with seeded
noise; the nominal forward kinematics the controller computes from them; axis speeds and motor
torques with seeded noise; the TCP speed (:meth:`Sensors.publish` writes all). See
docs/emulator-robot.md ("Which variable is what").
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from pyopenshowvar.kinematics import RobotModel
from pyopenshowvar.kinematics.single import SinglePoseFK
from pyopenshowvar.krl import E6Axis, E6Pos

from ..store import VariableStore
from .frames import FloatArray, frame_matrix

__all__ = ["MOTION_VARIABLES", "NOISE_BLOCK", "Sensors"]

#: The variables a plant publishes (base names).
MOTION_VARIABLES = frozenset((
    "$AXIS_ACT", "$AXIS_ACT_MEAS", "$POS_ACT", "$POS_ACT_MES", "$VEL_AXIS_ACT",
    "$TORQUE_AXIS_ACT", "$VEL_ACT",
))  # fmt: skip
#: The groups filled together when one of their variables is read: a reader of $AXIS_ACT
#: does not pay for the forward kinematics, the torques or the TCP speed.
_AXES = frozenset(("$AXIS_ACT", "$AXIS_ACT_MEAS"))
_POSES = frozenset(("$POS_ACT", "$POS_ACT_MES"))
_DRIVES = frozenset(("$VEL_AXIS_ACT", "$TORQUE_AXIS_ACT"))
_SPEED = frozenset(("$VEL_ACT",))
#: Cycles of sensor noise drawn at once.
NOISE_BLOCK = 256
_ZEROS = [0.0] * 6  # E1..E6 of the per-axis arrays
_AXIS_KEYS = E6Axis.MEMBERS
_POS_KEYS = ("X", "Y", "Z", "A", "B", "C")


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
        # one pose per cycle: plain-float FK (numpy's per-call overhead is most of a 4x4 chain)
        self._fk = SinglePoseFK(self.model)
        self._fk_frames: tuple[object, object] = (None, None)
        self._measured_at = -1
        self._measured: tuple[FloatArray, FloatArray, FloatArray, list[float]]

    def _read_frame(self, name: str) -> FloatArray:
        raise NotImplementedError  # provided by the plant

    def _defer(self) -> None:
        store = self.store
        store.defer(_AXES, self._publish_axes)
        store.defer(_POSES, self._publish_poses)
        store.defer(_DRIVES, self._publish_drives)
        store.defer(_SPEED, self._publish_speed)

    def _readings(self) -> tuple[FloatArray, FloatArray, FloatArray, list[float]]:
        """This cycle's :meth:`measure` (and the axes as floats), computed once per cycle."""
        if self._measured_at != self.ticks:
            q, qd, tau = self.measure()
            self._measured = (q, qd, tau, q.tolist())
            self._measured_at = self.ticks
        return self._measured

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
            self._st_key, self._st = key, self._fk.status_turn(self._q_set_deg.tolist())
        return self._st

    def publish(self) -> None:
        """Write all of this cycle's readings into the store (the store calls the groups'
        parts below on the first read of one of their variables)."""
        self._publish_axes()
        self._publish_poses()
        self._publish_drives()
        self._publish_speed()

    # The values are built directly (floats in canonical member order) and swapped in as
    # trusted: a robot read every cycle pays this once per cycle, and the store formats each
    # variable's text only when it is read.
    def _publish_axes(self) -> None:
        qs = self._readings()[3]
        axes = E6Axis._new("E6AXIS", dict(zip(_AXIS_KEYS, qs + _ZEROS, strict=True)))
        self.store.set_system("$AXIS_ACT", axes, trusted=True)
        self.store.set_system("$AXIS_ACT_MEAS", axes, trusted=True)

    def _publish_poses(self) -> None:
        qs = self._readings()[3]
        s, t = self._status_turn()
        base = self._base_matrix()
        if self._fk_frames[0] is not self._tool or self._fk_frames[1] is not base:
            self._fk.set_frames(self._tool, base)
            self._fk_frames = (self._tool, base)
        pose: dict[str, float | int] = dict(zip(_POS_KEYS, self._fk.frame(qs), strict=True))
        pose["S"], pose["T"] = s, t
        pose.update(zip(E6Pos.EXTERNAL, _ZEROS, strict=True))
        pos = E6Pos._new("E6POS", pose)  # type: ignore[arg-type]
        self.store.set_system("$POS_ACT", pos, trusted=True)
        self.store.set_system("$POS_ACT_MES", pos, trusted=True)

    def _publish_drives(self) -> None:
        _, qd, tau, _ = self._readings()
        speed = (qd / self.model.max_speed * 100.0).tolist()
        self.store.set_system("$VEL_AXIS_ACT", speed + _ZEROS, trusted=True)
        self.store.set_system("$TORQUE_AXIS_ACT", tau.tolist() + _ZEROS, trusted=True)

    def _publish_speed(self) -> None:
        v = np.zeros(6)
        mujoco.mj_objectVelocity(
            self._mj, self._data, mujoco.mjtObj.mjOBJ_SITE, self._tcp_site, v, 0
        )
        self.store.set_system("$VEL_ACT", float(np.linalg.norm(v[3:])), trusted=True)
