"""The dynamic plant: MuJoCo rigid-body arm + joint servos + friction + sensors.

Every IPO cycle :meth:`DynamicPlant.step` receives the kernel's set-point. The drives
(:mod:`.drives`) fine-interpolate it linearly over the cycle and a cascaded servo per axis
computes the motor torque each physics step, saturated at the motor's limit. MuJoCo integrates
the arm under that torque, gravity, the Stribeck joint friction, the payload ($LOAD, a welded
body), the external wrench ``EMU_WRENCH`` and contact with :class:`~.contact.Obstacle`
objects. What the controller publishes is what its sensors see: encoder positions (+ seeded
noise), the motor torques (+ seeded noise), velocities.

**Following-error monitoring.** An axis that falls more than the model file's
``following_error_deg`` behind its set-point cannot follow (a wrench or load beyond its motor):
the brakes close at once (the arm is held where it is, the motor torque drops to 0) and
:attr:`DynamicPlant.on_fault` reports ``Ackn. max. following error exceeded An`` so the
controller stops. :meth:`DynamicPlant.release` opens the brakes again when the message is
acknowledged.

**At rest** (set-point constant, servo converged) the physics is not stepped: the state is
snapped onto the set-point and the motor torque is the exact static torque (gravity + load +
external) from MuJoCo; only the noise changes per cycle. **Publication is lazy**: each cycle
marks the motion variables stale in the store and the first read of any of them fills all of
them from this cycle's state (noise drawn from ``(seed, cycle)``, so values do not depend on
when they are read). A robot nobody reads costs almost nothing at rest.

Ground truth for experiments (never published through a variable): :attr:`DynamicPlant.truth`.
The readings are :mod:`.sensors`.
"""

from __future__ import annotations

import logging
import secrets
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from pyopenshowvar.kinematics import RobotModel
from pyopenshowvar.krl import Struct

from ..store import VariableStore
from .contact import Obstacle, contact_force
from .drives import Drives
from .frames import FloatArray, frame_matrix
from .mjcf import Payload, build_mjcf, payload_of
from .params import Bodies, PlantParams, load_params, with_calibration_error
from .sensors import MOTION_VARIABLES, Sensors

__all__ = ["MOTION_VARIABLES", "DynamicPlant", "StepRecord", "Truth"]

log = logging.getLogger(__name__)


def _mujoco_warning(message: str) -> None:
    log.warning("MuJoCo: %s", message.strip())


# MuJoCo's default prints warnings and appends them to MUJOCO_LOG.TXT in the working directory;
# an emulator must not write files where it happens to run: route them to logging instead.
if mujoco.get_mju_user_warning() is None:
    mujoco.set_mju_user_warning(_mujoco_warning)

#: Converged: position error (rad) and speed (rad/s) below these at a constant set-point.
SETTLE_POS = 1e-6
SETTLE_VEL = 1e-5
_WRENCH = ("FX", "FY", "FZ", "MX", "MY", "MZ")


@dataclass(frozen=True, eq=False)
class Truth:
    """The physical state at the end of an IPO cycle (ground truth, not a sensor reading).

    ``q`` axis angles (deg) as a noise-free encoder reads them (with ``calibration_error`` the
    joints' true zero differs by the mastering error, which is part of the physical geometry), ``flange`` / ``tcp`` 4×4 poses in
    ``$ROBROOT`` (mm) of the *physical* robot (with ``calibration_error`` not the nominal FK),
    ``contact`` the wrench the TCP exerts on the obstacles (N, Nm; EMU_WRENCH convention),
    ``wrench`` the EMU_WRENCH applied, ``torque`` the motor torques without sensor noise (Nm;
    their mean over the cycle while moving).
    """

    time: float
    q: FloatArray
    flange: FloatArray
    tcp: FloatArray
    contact: FloatArray
    wrench: FloatArray
    torque: FloatArray


@dataclass(frozen=True, eq=False)
class StepRecord:
    """The last physics step of a cycle (SI units, rad): state before it, the acceleration
    MuJoCo integrated, the motor torque and the other generalised forces applied (friction,
    external wrench, contact). M(q)·qacc + bias(q, qd) = motor + other holds exactly."""

    q: FloatArray
    qd: FloatArray
    qacc: FloatArray
    motor: FloatArray
    other: FloatArray


class DynamicPlant(Sensors):
    """The physical arm behind one emulated controller (``params``: its model file; default
    the KR 6 R900 sixx's)."""

    kind = "dynamic"

    def __init__(
        self,
        store: VariableStore,
        model: RobotModel,
        *,
        ipo: float = 0.012,
        params: PlantParams | None = None,
        calibration_seed: int | None = None,
        encoder_noise: float | None = None,
        torque_noise: float | None = None,
        seed: int | None = None,
        obstacles: Sequence[Obstacle] = (),
    ) -> None:
        self.store = store
        self.model = model
        self.ipo = ipo
        self.params = params if params is not None else load_params()
        p = self.params
        bodies = p.bodies
        if calibration_seed is not None:
            bodies = with_calibration_error(bodies, p.calibration, calibration_seed)
        #: The physical robot simulated (differs from ``model`` with a calibration error).
        self.bodies: Bodies = bodies
        self.calibration_seed = calibration_seed
        #: Encoder noise (deg) and torque noise (Nm per axis), standard deviations.
        self.encoder_noise = p.encoder_noise_deg if encoder_noise is None else encoder_noise
        frac = p.torque_noise_fraction
        self.torque_noise = (
            model.max_torque * frac if torque_noise is None else np.full(6, float(torque_noise))
        )
        if self.encoder_noise < 0 or np.any(self.torque_noise < 0):
            raise ValueError("noise levels must be >= 0")
        self._noisy = bool(self.encoder_noise or np.any(self.torque_noise))
        self.seed = seed if seed is not None else secrets.randbits(63)
        self.obstacles: tuple[Obstacle, ...] = tuple(obstacles)
        self.substeps = p.substeps
        self.h = ipo / p.substeps
        self.time = 0.0
        self.ticks = 0
        self.steps = 0  # physics steps taken (the rest path takes none)
        #: The motors' torque limits (Nm): the drives saturate there.
        self.torque_limit = bodies.max_torque.copy()
        self.drives = Drives(p, bodies, self.h)
        self._following_limit = np.radians(p.following_error_deg)
        #: Called with a message when an axis cannot follow (the brakes have closed).
        self.on_fault: Callable[[str], None] | None = None
        #: True while the brakes hold the arm after a fault (drives off).
        self.braked = False
        self._full_m = np.zeros((6, 6))
        self._payload: Payload | None = None
        self._tool = np.eye(4)
        self._wrench = np.zeros(6)
        self._has_wrench = "EMU_WRENCH" in store.names()
        self._inputs: tuple[object, ...] = (None, None, None)
        self._input_versions: tuple[int, ...] = (-1, -1, -1)
        self._q_seen: object = None  # the set-point array object of the last still cycle
        self._init_sensors()
        q0_deg = self._axes(store.get("$AXIS_ACT"))
        q0 = np.radians(q0_deg)
        self._build(payload_of(store.get("$LOAD")))
        self._q_set = q0.copy()
        self._q_set_deg = q0_deg  # at rest the encoders read exactly this (no noise)
        self._qd_ref = np.zeros(6)
        #: Motor torque (Nm, +KUKA axis): its mean over the last cycle while moving, the exact
        #: static torque at rest (see _simulate for why the mean).
        self.torque = np.zeros(6)
        self.contact = np.zeros(3)  # force of the obstacles on the TCP (N)
        self._tcp_prev = np.zeros(3)
        self._tcp_speed = 0.0
        self.resting = False
        self.last_step: StepRecord | None = None
        self._obstacles_used = self.obstacles
        self._inputs_changed()  # the start-up $TOOL and EMU_WRENCH
        self._settle()
        self._defer()  # the model's readings (not the store's start-up table) from the first read

    # --- model --------------------------------------------------------------------------------
    def _build(self, payload: Payload | None) -> None:
        """(Re)compile the MuJoCo model for ``payload``, keeping the joint state."""
        old = getattr(self, "_data", None)
        xml = build_mjcf(self.bodies, timestep=self.h, payload=payload)
        self._mj = mujoco.MjModel.from_xml_string(xml)
        self._data = mujoco.MjData(self._mj)
        if old is not None:
            self._data.qpos[:] = old.qpos
            self._data.qvel[:] = old.qvel
        self._payload = payload
        self._tcp_site = mujoco.mj_name2id(self._mj, mujoco.mjtObj.mjOBJ_SITE, "tcp")
        self._flange_site = mujoco.mj_name2id(self._mj, mujoco.mjtObj.mjOBJ_SITE, "flange")
        self._link6 = mujoco.mj_name2id(self._mj, mujoco.mjtObj.mjOBJ_BODY, "link6")
        self._flange_local = self._site_local(self._flange_site)
        self._set_tool(self._tool)
        mujoco.mj_forward(self._mj, self._data)

    def _site_local(self, site: int) -> FloatArray:
        t = np.eye(4)
        mat = np.zeros(9)
        mujoco.mju_quat2Mat(mat, self._mj.site_quat[site])
        t[:3, :3] = mat.reshape(3, 3)
        t[:3, 3] = self._mj.site_pos[site] * 1000.0
        return t

    def _set_tool(self, tool: FloatArray) -> None:
        self._tool = tool
        tcp = self._flange_local @ tool
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, tcp[:3, :3].flatten())
        self._mj.site_pos[self._tcp_site] = tcp[:3, 3] / 1000.0
        self._mj.site_quat[self._tcp_site] = quat

    @property
    def mujoco(self) -> tuple[object, object]:
        """The MuJoCo ``(MjModel, MjData)`` simulated (read it; stepping it breaks the plant)."""
        return self._mj, self._data

    @property
    def payload(self) -> Payload | None:
        """The payload body currently simulated (from ``$LOAD``)."""
        return self._payload

    def set_obstacles(self, obstacles: Sequence[Obstacle]) -> None:
        """Replace the objects in the cell (takes effect on the next cycle; thread-safe by
        replacing one tuple)."""
        self.obstacles = tuple(obstacles)

    # --- inputs from the store -----------------------------------------------------------------
    @staticmethod
    def _axes(value: object) -> FloatArray:
        assert isinstance(value, Struct)
        return np.array([float(value[f"A{i}"]) for i in range(1, 7)])  # type: ignore[arg-type]

    def _read_wrench(self) -> FloatArray:
        if not self._has_wrench:
            return np.zeros(6)
        w = self.store.get("EMU_WRENCH")
        if not isinstance(w, Struct):
            return np.zeros(6)
        return np.array([float(w.get(k) or 0.0) for k in _WRENCH])  # type: ignore[arg-type]

    def _read_frame(self, name: str) -> FloatArray:
        f = self.store.get(name)
        if not isinstance(f, Struct):
            return np.zeros(6)
        return np.array([float(f.get(k) or 0.0) for k in "XYZABC"])  # type: ignore[arg-type]

    def _inputs_changed(self) -> bool:
        """Read $LOAD, $TOOL, EMU_WRENCH; apply changes; True when any changed.

        The store hands out the same value object until the variable is written, so an
        unchanged input costs one lookup and an identity test (the rest path runs this every
        cycle)."""
        store = self.store
        versions = (store.version("$LOAD"), store.version("$TOOL"), store.version("EMU_WRENCH"))
        if versions == self._input_versions:
            return self.obstacles is not self._obstacles_used
        self._input_versions = versions
        load, tool = store.get("$LOAD"), store.get("$TOOL")
        wrench = store.get("EMU_WRENCH") if self._has_wrench else None
        seen = (load, tool, wrench)
        if all(a is b for a, b in zip(seen, self._inputs, strict=True)):
            return self.obstacles is not self._obstacles_used
        self._inputs = seen
        changed = self.obstacles is not self._obstacles_used
        payload = payload_of(load)
        if payload != self._payload:
            try:
                self._build(payload)  # the servo gains follow M(q) with the load, each cycle
            except ValueError as exc:  # MuJoCo refused the model: keep the previous one
                log.warning(
                    "$LOAD %s cannot be simulated (%s); keeping the previous load", payload, exc
                )
                self._payload = payload  # do not retry every cycle
            changed = True
        tool_m = frame_matrix(self._read_frame("$TOOL"))
        if not np.array_equal(tool_m, self._tool):
            self._set_tool(tool_m)
            changed = True
        w = self._read_wrench()
        if not np.array_equal(w, self._wrench):
            self._wrench = w
            changed = True
        return changed

    # --- the cycle ----------------------------------------------------------------------------
    def step(self, q_set_deg: FloatArray) -> None:
        """One IPO cycle towards the set-point ``q_set_deg`` (A1..A6, deg)."""
        changed = self._inputs_changed()
        if changed:
            self._idle_speed = None  # the model or its inputs changed: the TCP speed too
        if self.braked or (self.resting and not changed and q_set_deg is self._q_seen):
            # the brakes hold the arm; or the kernel hands over the very same array while it
            # stands still: at rest
            self._idle()
            return
        q_set = np.radians(q_set_deg)
        still = np.array_equal(q_set, self._q_set)
        if self.resting and still and not changed:
            self._q_seen = q_set_deg
            self._idle()
            return
        self._q_seen = None
        self.resting = False
        self._idle_speed = None
        qd_ref = (q_set - self._q_set) / self.ipo
        qdd_ref = (qd_ref - self._qd_ref) / self.ipo
        self._simulate(self._q_set, q_set, qd_ref, qdd_ref)
        self._q_set, self._qd_ref = q_set, qd_ref
        self._q_set_deg = np.array(q_set_deg, dtype=np.float64)
        self.time += self.ipo
        self.ticks += 1
        d = self._data
        error = np.abs(q_set - d.qpos)
        if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
            # absurd inputs (a wrench or load of 1e30) blew the state up: a KRC's drives would
            # trip; here the arm is put back on its set-point so the emulator keeps serving
            log.warning("plant state not finite (absurd wrench or load?); reset to the set-point")
            self.braked = False
            self._settle()
        elif self.braked:
            pass  # the monitoring stopped the arm during this cycle
        elif (
            still
            and not np.any(qd_ref)
            and np.max(error) < SETTLE_POS
            and np.max(np.abs(d.qvel)) < SETTLE_VEL
        ):
            self._settle()
        self.truth = self._truth()
        self._defer()

    def _idle(self) -> None:
        self.time += self.ipo
        self.ticks += 1
        cycle = self._cycle
        if cycle is not None and cycle.speed is not None:
            # an idle cycle leaves MuJoCo's state alone: the TCP speed stays what it was
            self._idle_speed = cycle.speed
        self._cycle = None  # a later first reading freezes this cycle's inputs
        if self._noisy:
            self._defer()

    def _simulate(
        self, q0: FloatArray, q1: FloatArray, qd_ref: FloatArray, qdd_ref: FloatArray
    ) -> None:
        m, d, n, h = self._mj, self._data, self.substeps, self.h
        self._obstacles_used = obstacles = self.obstacles
        drives = self.drives
        drives.schedule(m, d)
        wrench = self._wrench
        ext_fixed = self._external(-wrench[:3], -wrench[3:]) if np.any(wrench) else np.zeros(6)
        tcp_xpos = d.site_xpos[self._tcp_site]
        contact = np.zeros(3)
        # the drives' linear fine interpolation: the reference at each step's start
        refs = q0 + (q1 - q0) * (np.arange(n) / n)[:, None]
        ref_list = refs.tolist()
        qd_r, qdd_r = qd_ref.tolist(), qdd_ref.tolist()
        tau_sum = [0.0] * 6
        tau = fric = qd = [0.0] * 6
        q_last = d.qpos.copy()
        failed = -1
        ext = ext_fixed
        for k in range(n):
            ext = ext_fixed
            if obstacles:
                tcp = tcp_xpos * 1000.0
                contact = contact_force(obstacles, tcp, (tcp - self._tcp_prev) / h)
                if np.any(contact):
                    ext = ext + self._external(contact, np.zeros(3))
                self._tcp_prev = tcp
            if k == n - 1:
                q_last = d.qpos.copy()
            tau, fric, qd = drives.step(m, d, ref_list[k], qd_r, qdd_r, ext.tolist())
            tau_sum = [a + b for a, b in zip(tau_sum, tau, strict=True)]
            # following-error monitoring, every servo step: the reference at the step's end
            ref_end = refs[k + 1] if k + 1 < n else q1
            error = np.abs(ref_end - d.qpos)
            if np.any(error > self._following_limit) and np.all(np.isfinite(d.qpos)):
                failed = int(np.argmax(error / self._following_limit))
                # the brakes close the moment the error reaches the limit: the arm is held
                # there (an idealisation; a step may have carried it a little further)
                lim = self._following_limit
                d.qpos[:] = ref_end + np.clip(d.qpos - ref_end, -lim, lim)
                break
        self._tcp_prev = tcp_xpos * 1000.0
        m.dof_damping[:] = 0.0  # the drives' per-step damping: readers see the rigid model
        # The drive reports the mean motor torque over the IPO cycle, not a sample of its last
        # 2 ms step: the velocity loop corrects the linearly fine-interpolated set-point within
        # the first few ms of each cycle, so the end-of-cycle sample carries almost none of the
        # inertial torque M·q̈ (measured: ~3 % of it on a 20 % PTP) and aliases the servo's
        # ripple. The mean is what the motion over the cycle needs: with the measured speeds
        # at both ends, Δq̇/IPO is exactly its mean acceleration.
        self.torque = np.array(tau_sum) / n
        self.steps += n
        tau_a, qd_a = np.array(tau), np.array(qd)
        self.last_step = StepRecord(q_last, qd_a, (d.qvel - qd_a) / h, tau_a, ext - np.array(fric))
        self.contact = contact
        mujoco.mj_forward(m, d)  # positions and sites of the final state
        if obstacles:
            self.contact = contact_force(obstacles, tcp_xpos * 1000.0, np.zeros(3))
        if failed >= 0:
            self._fault(failed)

    # --- faults ---------------------------------------------------------------------------------
    def _fault(self, axis: int) -> None:
        """An axis cannot follow: close the brakes (hold the arm where it is, drives off) and
        tell the controller."""
        d = self._data
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        mujoco.mj_forward(self._mj, d)
        self.braked = True
        self.resting = False
        self.torque = np.zeros(6)
        self.drives.integral = np.zeros(6)
        message = f"Ackn. max. following error exceeded A{axis + 1}"
        log.warning("plant: %s; brakes closed", message)
        if self.on_fault is not None:
            self.on_fault(message)

    @property
    def position(self) -> FloatArray:
        """Where the encoders say the axes are, without noise (deg)."""
        return self._q_set_deg.copy() if self.resting else np.degrees(self._data.qpos)

    def release(self) -> FloatArray:
        """Open the brakes and switch the drives on where the arm stands (the message was
        acknowledged); returns that position (deg), the controller's new set-point. The servo
        starts with the static holding torque, so the arm does not sag."""
        self.braked = False
        self._inputs_changed()  # the holding torque under today's load and wrench
        self._q_set = self._data.qpos.copy()
        self._q_set_deg = np.degrees(self._q_set)
        self._settle()
        self._defer()
        return self._q_set_deg.copy()

    def _external(self, force: FloatArray, torque: FloatArray) -> FloatArray:
        """Generalised force of a wrench on link 6 at the TCP (N, Nm, world axes)."""
        out = np.zeros(6)
        point = self._data.site_xpos[self._tcp_site].copy()
        mujoco.mj_applyFT(
            self._mj, self._data, force.astype(np.float64), torque.astype(np.float64),
            point, self._link6, out,
        )  # fmt: skip
        return out

    def _settle(self) -> None:
        """Snap onto the set-point at rest with the exact static torque (the cheap path)."""
        m, d = self._mj, self._data
        self._idle_speed = None  # the state changes here
        d.qpos[:] = self._q_set
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        mujoco.mj_forward(m, d)
        self._obstacles_used = self.obstacles
        static = d.qfrc_bias.copy()  # gravity (+ load) holding torque at rest
        if np.any(self._wrench):
            static -= self._external(-self._wrench[:3], -self._wrench[3:])
        self.contact = np.zeros(3)
        if self.obstacles:
            tcp = d.site_xpos[self._tcp_site] * 1000.0
            self.contact = contact_force(self.obstacles, tcp, np.zeros(3))
            if np.any(self.contact):
                static -= self._external(self.contact, np.zeros(3))
        self._tcp_prev = d.site_xpos[self._tcp_site] * 1000.0
        self.torque = np.clip(static, -self.torque_limit, self.torque_limit)
        self.drives.integral = self.torque.copy()
        self._qd_ref = np.zeros(6)
        # a holding torque beyond a motor's limit cannot rest: the physics shows what happens
        self.resting = bool(np.all(np.abs(static) <= self.torque_limit))
        self.truth = self._truth()

    def _truth(self) -> Truth:
        d = self._data
        flange = np.eye(4)
        flange[:3, :3] = d.site_xmat[self._flange_site].reshape(3, 3)
        flange[:3, 3] = d.site_xpos[self._flange_site] * 1000.0
        tcp = flange @ self._tool
        return Truth(
            time=self.time,
            q=self._q_set_deg.copy() if self.resting else np.degrees(d.qpos),
            flange=flange,
            tcp=tcp,
            contact=np.concatenate([-self.contact, np.zeros(3)]),
            wrench=self._wrench.copy(),
            torque=self.torque * self.model.torque_sign,
        )
