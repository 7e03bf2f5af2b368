"""The controller's sensors on the dynamic plant: what a KRC4 measures and publishes.

:class:`Sensors` is mixed into :class:`~.dynamic.DynamicPlant` (state lives there). Each IPO
cycle the plant marks the motion variables stale (:meth:`VariableStore.defer`), in groups;
the first read of a variable fills its group from this cycle's state: encoder axes with seeded
noise; the nominal forward kinematics the controller computes from them; axis speeds and motor
torques with seeded noise; the TCP speed (:meth:`Sensors.publish` writes all). See
docs/emulator-robot.md ("Which variable is what").

What a cycle's readings depend on (the axes, speeds and torques of the state, the set-point,
the tool, the cycle's number for the noise) is frozen in a :class:`_Cycle` when first needed;
the plant changes its state only in a step, which defers the readings again. A group's
*capture* (:meth:`VariableStore.capture`) keeps that frozen cycle (and ``$BASE`` as it is
now) and computes the very values the fill would have set, later, when someone reads them:
a compiled SPS pass copying the readings of a resting robot keeps the capture instead of
computing readings nobody may look at.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from functools import partial
from typing import Any

import mujoco
import numpy as np

from pyopenshowvar.kinematics import RobotModel
from pyopenshowvar.kinematics.single import SinglePoseFK
from pyopenshowvar.krl import E6Axis, E6Pos

from ..store import VariableStore
from ..store_lazy import Maker
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
_FROZEN = (*sorted(_AXES), *sorted(_POSES), *sorted(_DRIVES))
#: Cycles of sensor noise drawn at once.
NOISE_BLOCK = 256
_ZEROS = [0.0] * 6  # E1..E6 of the per-axis arrays
#: The axis speeds of a resting plant (its state's speeds are zeroed when it settles).
_REST_SPEEDS = np.zeros(6)
_REST_SPEEDS.flags.writeable = False
_AXIS_KEYS = E6Axis.MEMBERS
_POS_KEYS = ("X", "Y", "Z", "A", "B", "C")


class _Cycle:
    """What one cycle's readings depend on, frozen (arrays the plant replaces, never changes
    in place, are kept by reference); ``measured`` is filled at the first reading."""

    __slots__ = ("measured", "q", "q_set_deg", "qd", "speed", "ticks", "tool", "torque")

    def __init__(
        self,
        ticks: int,
        q: FloatArray,
        qd: FloatArray,
        torque: FloatArray,
        q_set_deg: FloatArray,
        tool: FloatArray,
    ) -> None:
        self.ticks, self.q, self.qd, self.torque = ticks, q, qd, torque
        self.q_set_deg, self.tool = q_set_deg, tool
        self.measured: tuple[FloatArray, FloatArray, FloatArray, list[float]] | None = None
        self.speed: float | None = None


class _Frozen(Mapping[str, object]):
    """The axes, poses and drive readings of one frozen cycle (what a capture's maker
    gives), each group computed at the first look at one of its names."""

    def __init__(self, sensors: Sensors, cycle: _Cycle, base: FloatArray | None) -> None:
        self._sensors, self._cycle, self._base = sensors, cycle, base
        self._values: dict[str, object] = {}

    def __getitem__(self, name: str) -> object:
        values = self._values
        if name not in values:
            sensors, cycle = self._sensors, self._cycle
            if name in _AXES:
                values.update(sensors._axes_values(cycle))
            elif name in _POSES:
                values.update(sensors._pose_values(cycle, self._base))
            elif name in _DRIVES:
                values.update(sensors._drive_values(cycle))
            else:
                raise KeyError(name)
        return values[name]

    def __iter__(self) -> Iterator[str]:
        return iter(_FROZEN)

    def __len__(self) -> int:
        return len(_FROZEN)


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
        self._base_version = -1
        # one pose per cycle: plain-float FK (numpy's per-call overhead is most of a 4x4 chain)
        self._fk = SinglePoseFK(self.model)
        self._fk_frames: tuple[object, object] = (None, None)
        #: This cycle's frozen inputs (None: not needed yet in this cycle).
        self._cycle: _Cycle | None = None
        #: The TCP speed while the plant idles (None: compute it from MuJoCo's state).
        self._idle_speed: float | None = None
        # one capture for the three groups computed from the frozen cycle (a pass copying
        # several of them captures once): the same bound method object each cycle
        self._capture = self._capture_readings

    def _read_frame(self, name: str) -> FloatArray:
        raise NotImplementedError  # provided by the plant

    def _defer(self) -> None:
        self._cycle = None  # a new cycle: its inputs are frozen when first needed
        store, capture = self.store, self._capture
        store.defer(_AXES, self._publish_axes, capture)
        store.defer(_POSES, self._publish_poses, capture)
        store.defer(_DRIVES, self._publish_drives, capture)
        store.defer(_SPEED, self._publish_speed, self._capture_speed)

    def _now(self) -> _Cycle:
        """This cycle's inputs, frozen at the first need (see the module)."""
        cycle = self._cycle
        if cycle is None:
            d = self._data
            if self.resting:
                # the state was snapped onto the set-point at rest (the speeds zeroed): report
                # it without a rad/deg trip (no numpy call: a resting robot's SPS may freeze
                # a cycle every 12 ms)
                q, qd = self._q_set_deg, _REST_SPEEDS
            else:
                q, qd = np.degrees(d.qpos), np.degrees(d.qvel)
            cycle = self._cycle = _Cycle(
                self.ticks, q, qd, self.torque, self._q_set_deg, self._tool
            )
            cycle.speed = self._idle_speed
        return cycle

    def _measure(self, cycle: _Cycle) -> tuple[FloatArray, FloatArray, FloatArray, list[float]]:
        """The sensor readings of ``cycle`` (and the axes as floats), computed once."""
        measured = cycle.measured
        if measured is None:
            noise = self._noise_sample(cycle.ticks)
            q = cycle.q + noise[:6] * self.encoder_noise if self.encoder_noise else cycle.q.copy()
            tau = cycle.torque * self.model.torque_sign
            if np.any(self.torque_noise):
                tau = tau + noise[6:] * self.torque_noise
            measured = cycle.measured = (q, cycle.qd, tau, q.tolist())
        return measured

    def measure(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """This cycle's sensor readings: axes (deg), axis speeds (deg/s), torques (Nm)."""
        q, qd, tau, _ = self._measure(self._now())
        return q, qd, tau

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
        store = self.store
        version = store.version("$BASE")
        if version == self._base_version:
            return self._base  # not written since: the same value
        self._base_version = version
        base = store.get("$BASE")
        if base is not self._base_seen:
            frame = self._read_frame("$BASE")
            self._base_seen = base
            self._base = frame_matrix(frame) if np.any(frame) else None
        return self._base

    def _status_turn(self, q_set_deg: FloatArray) -> tuple[int, int]:
        """S and T of the set-point: the configuration the controller commands (a measured
        axis jittering around 0° by encoder noise does not flip a turn bit)."""
        key = q_set_deg.tobytes()
        if key != self._st_key:
            self._st_key, self._st = key, self._fk.status_turn(q_set_deg.tolist())
        return self._st

    def publish(self) -> None:
        """Write all of this cycle's readings into the store (the store calls the groups'
        parts below on the first read of one of their variables)."""
        self._publish_axes()
        self._publish_poses()
        self._publish_drives()
        self._publish_speed()

    def _put(self, values: dict[str, Any]) -> None:
        store = self.store
        for name, value in values.items():
            store.set_system(name, value, trusted=True)

    # The values are built directly (floats in canonical member order) and swapped in as
    # trusted: a robot read every cycle pays this once per cycle, and the store formats each
    # variable's text only when it is read. A fill makes them now; a capture freezes the same
    # inputs and makes them when its maker is called.
    def _axes_values(self, cycle: _Cycle) -> dict[str, Any]:
        qs = self._measure(cycle)[3]
        axes = E6Axis._new("E6AXIS", dict(zip(_AXIS_KEYS, qs + _ZEROS, strict=True)))
        return {"$AXIS_ACT": axes, "$AXIS_ACT_MEAS": axes}

    def _publish_axes(self) -> None:
        self._put(self._axes_values(self._now()))

    def _pose_values(self, cycle: _Cycle, base: FloatArray | None) -> dict[str, Any]:
        qs = self._measure(cycle)[3]
        s, t = self._status_turn(cycle.q_set_deg)
        if self._fk_frames[0] is not cycle.tool or self._fk_frames[1] is not base:
            self._fk.set_frames(cycle.tool, base)
            self._fk_frames = (cycle.tool, base)
        pose: dict[str, float | int] = dict(zip(_POS_KEYS, self._fk.frame(qs), strict=True))
        pose["S"], pose["T"] = s, t
        pose.update(zip(E6Pos.EXTERNAL, _ZEROS, strict=True))
        pos = E6Pos._new("E6POS", pose)  # type: ignore[arg-type]
        return {"$POS_ACT": pos, "$POS_ACT_MES": pos}

    def _publish_poses(self) -> None:
        self._put(self._pose_values(self._now(), self._base_matrix()))

    def _drive_values(self, cycle: _Cycle) -> dict[str, Any]:
        _, qd, tau, _ = self._measure(cycle)
        speed = (qd / self.model.max_speed * 100.0).tolist()
        return {"$VEL_AXIS_ACT": speed + _ZEROS, "$TORQUE_AXIS_ACT": tau.tolist() + _ZEROS}

    def _publish_drives(self) -> None:
        self._put(self._drive_values(self._now()))

    def _capture_readings(self) -> Maker:
        return partial(_Frozen, self, self._now(), self._base_matrix())

    def _speed_values(self, cycle: _Cycle) -> dict[str, Any]:
        # the TCP speed comes from MuJoCo's live state: computed at the first need of the
        # cycle (a capture needs it now, before a step changes the state)
        if cycle.speed is None:
            v = np.zeros(6)
            mujoco.mj_objectVelocity(
                self._mj, self._data, mujoco.mjtObj.mjOBJ_SITE, self._tcp_site, v, 0
            )
            cycle.speed = float(np.linalg.norm(v[3:]))
        return {"$VEL_ACT": cycle.speed}

    def _publish_speed(self) -> None:
        self._put(self._speed_values(self._now()))

    def _capture_speed(self) -> Maker:
        cycle = self._now()
        self._speed_values(cycle)
        return partial(self._speed_values, cycle)
