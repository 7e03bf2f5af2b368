"""The controller's dynamic model: accelerations adapted to the load, as KSS does.

A KRC plans with the axis limits of its machine data and, knowing the load data (``$LOAD``)
and its arm's masses, also with the torque a motion needs: KSS lowers the accelerations of a
motion so that no motor is asked for more than it has (KUKA's acceleration adaptation,
``$ADAP_ACC``). Without this a 6 kg payload made the planner ask up to 1.8× an axis' max
torque, which the drives cannot give (bench/plant_settle.py).

:class:`ControllerDynamics` is the *controller's* model, never the plant's: the kinematic
model it plans with (D-H, link masses and centres of mass, max torques) plus the machine data
it lacks (``kr6r900sixx_machine.toml``: link inertia, motor inertia, a torque reserve for
friction and the servo), with the current ``$LOAD``, simulated by MuJoCo only for its inverse
dynamics. Along a motion the torque is affine in the path acceleration s̈ and the squared
path speed ṡ² (``τ = A(s)·s̈ + B(s)·ṡ² + G(s)``), so:

* a PTP (``q = q0 + Δq·s``) gets the largest constant s̈ (and, if the velocity terms would
  leave no room, a lower ṡ) with ``|A·s̈| + |B·ṡ² + G| ≤ T`` at samples along its path, for
  either sign of s̈ (braking, an override ramp or a hold may come anywhere);
* a LIN gets torque rows in its phase-plane limits (:class:`~.path.PathLimits`), so its
  time-optimal profile keeps every motor within ``T``;

with ``T = (1 − reserve)·max torque``. An arm that cannot hold itself (gravity alone above
``T``) is left to the drives: planning cannot help there.
"""

from __future__ import annotations

import logging
import math
import tomllib
from collections.abc import Generator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pyopenshowvar.kinematics import RobotModel

from .profiles import FloatArray

__all__ = ["MACHINE_DATA", "ControllerDynamics", "MachineData", "load_machine_data"]

log = logging.getLogger(__name__)

#: Machine data files by robot model name.
MACHINE_DATA = {"KUKA KR 6 R900 sixx": Path(__file__).with_name("kr6r900sixx_machine.toml")}
#: The slowest a PTP is made by the adaptation: 1 % of its acceleration (it always arrives).
MIN_SCALE = 0.01
#: Nodes of a LIN whose dynamics are computed per slice of planning.
NODE_CHUNK = 25
_BIG = 1e30


@dataclass(frozen=True, eq=False)
class MachineData:
    """What the controller knows of its arm beyond the kinematic model (SI units)."""

    inertia: FloatArray
    motor_inertia: FloatArray
    torque_reserve: float


def load_machine_data(path: str | Path) -> MachineData:
    """Read a machine data file; raises ``ValueError`` for a missing or bad entry."""
    with open(path, "rb") as fh:
        data = tomllib.load(fh)
    try:
        axes = data["axis"]
        inertia = np.array([ax["inertia"] for ax in axes], dtype=np.float64)
        motor = np.array([ax["motor_inertia"] for ax in axes], dtype=np.float64)
        reserve = float(data["torque_reserve"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: missing or malformed entry {exc}") from None
    if inertia.shape != (6, 3) or motor.shape != (6,) or not 0.0 <= reserve < 1.0:
        raise ValueError(f"{path}: 6 axes with 3 inertia moments each, reserve in [0, 1)")
    return MachineData(inertia, motor, reserve)


class ControllerDynamics:
    """Inverse dynamics of the controller's nominal model with the current ``$LOAD``."""

    def __init__(self, model: RobotModel, machine: MachineData) -> None:
        from ..plant.params import make_bodies  # the same rigid-body description, own numbers

        self.model = model
        self.limit = np.asarray(model.max_torque * (1.0 - machine.torque_reserve))
        dh = np.column_stack([model.a, model.alpha, model.d, model.offset])
        self._bodies = make_bodies(
            dh, model.sign, model.flange, mass=model.link_mass,
            com_base=model.link_origin + model.link_com, inertia=machine.inertia,
            armature=machine.motor_inertia, max_torque=model.max_torque,
        )  # fmt: skip
        self._load: object = None
        self._mj: Any = None
        self._data: Any = None
        self.use_load(None)

    @classmethod
    def for_model(
        cls, model: RobotModel, machine: MachineData | None = None
    ) -> ControllerDynamics | None:
        """The model of ``model`` if machine data exist for it (``machine``, else its file by
        model name) and it has torque limits."""
        path = MACHINE_DATA.get(model.name)
        if (path is None and machine is None) or not np.all(np.isfinite(model.max_torque)):
            log.debug("no dynamic model for %s: accelerations are not adapted", model.name)
            return None
        try:  # the ideal plant runs without the [emulator] extra; so does its planner
            import mujoco  # noqa: F401
        except ImportError:
            log.warning("mujoco is not installed: accelerations are not adapted to $LOAD")
            return None
        if machine is None:
            assert path is not None
            machine = load_machine_data(path)
        return cls(model, machine)

    def use_load(self, value: object) -> None:
        """Plan with the ``$LOAD`` value ``value`` (rebuilt only when it changed)."""
        if self._mj is not None and value is self._load:
            return
        import mujoco

        from ..plant.mjcf import build_mjcf, payload_of

        self._load = value
        try:
            xml = build_mjcf(self._bodies, timestep=0.002, payload=payload_of(value))
            self._mj = mujoco.MjModel.from_xml_string(xml)
        except ValueError as exc:  # a $LOAD no rigid body can have: plan without it
            log.warning("$LOAD %r cannot be modelled (%s); planning without it", value, exc)
            if self._mj is None:
                raise
        self._data = mujoco.MjData(self._mj)

    def diag_inertia(self, q: FloatArray) -> FloatArray:
        """The diagonal of the mass matrix at the axes ``q`` (deg), kg·m² (motor inertia
        included): what each axis alone feels."""
        import mujoco

        m, d = self._mj, self._data
        d.qpos[:] = np.radians(q)
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        return np.asarray(np.diag(full), dtype=np.float64)

    def terms(self, q: FloatArray, qp: FloatArray, qpp: FloatArray) -> tuple[FloatArray, ...]:
        """``(A, B, G)`` at the axes ``q`` (deg) of a path with derivatives ``qp``, ``qpp``
        (deg per unit s, per unit s²): the torque there is ``A·s̈ + B·ṡ² + G`` (Nm)."""
        import mujoco

        m, d = self._mj, self._data
        d.qpos[:] = np.radians(q)
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        mujoco.mj_inverse(m, d)
        g = d.qfrc_inverse.copy()
        d.qacc[:] = np.radians(qp)
        mujoco.mj_inverse(m, d)
        a = d.qfrc_inverse - g
        d.qvel[:] = np.radians(qp)
        d.qacc[:] = np.radians(qpp)
        mujoco.mj_inverse(m, d)
        return a, d.qfrc_inverse - g, g

    # --- PTP --------------------------------------------------------------------------------
    def ptp_limits(
        self, q0: FloatArray, delta: FloatArray, v: float, a: float
    ) -> tuple[float, float]:
        """The path speed and acceleration limits ``(ṡ_max, s̈_max)`` of the PTP from ``q0`` by
        ``delta`` (deg) lowered from ``(v, a)`` until every motor stays within its share."""
        lead = float(np.max(np.abs(delta)))
        if lead <= 1e-9 or math.isinf(a):
            return v, a
        samples = int(min(max(math.ceil(lead / 10.0) + 1, 3), 37))
        zero = np.zeros(6)
        rows = [self.terms(q0 + delta * s, delta, zero) for s in np.linspace(0.0, 1.0, samples)]
        acc = np.abs(np.array([r[0] for r in rows]))
        vel, grav = np.array([r[1] for r in rows]), np.array([r[2] for r in rows])
        top = np.broadcast_to(self.limit, grav.shape)
        holds = np.abs(grav) < top  # where gravity alone is beyond T, planning cannot help
        room = np.where(holds, top - np.abs(grav), 0.0)
        # the velocity terms may take at most half of the room gravity leaves
        with np.errstate(divide="ignore", invalid="ignore"):
            cap = (np.abs(grav) + room / 2 - np.sign(vel) * grav) / np.abs(vel)
        cap = np.where(holds & (np.abs(vel) > 1e-12), cap, math.inf)
        x = min(v * v, float(np.min(cap)))
        worst = np.maximum(np.abs(grav), np.abs(grav + vel * x))
        with np.errstate(divide="ignore", invalid="ignore"):
            a_cap = np.where(holds & (acc > 1e-12), (top - worst) / acc, math.inf)
        a_new = min(a, max(float(np.min(a_cap)), MIN_SCALE * a))
        return math.sqrt(x), a_new

    # --- LIN --------------------------------------------------------------------------------
    def path_rows(
        self, q: FloatArray, qp: FloatArray, qpp: FloatArray
    ) -> Generator[None, None, tuple[FloatArray, FloatArray, FloatArray, FloatArray]]:
        """Torque rows of a path's nodes (axes ``q``, derivatives ``qp``, ``qpp``, deg):
        ``(α, β, γ, x_cap)`` with ``α + β·ṡ² ≤ s̈ ≤ γ + β·ṡ²`` per node and axis and ṡ² below
        ``x_cap`` per node, yielding every :data:`NODE_CHUNK` nodes."""
        n = len(q)
        a, b, g = np.empty((n, 6)), np.empty((n, 6)), np.empty((n, 6))
        for k in range(n):
            a[k], b[k], g[k] = self.terms(q[k], qp[k], qpp[k])
            if (k + 1) % NODE_CHUNK == 0:
                yield
        top = np.broadcast_to(self.limit, g.shape)
        holds = np.abs(g) < top
        moving = holds & (np.abs(a) > 1e-9)
        with np.errstate(divide="ignore", invalid="ignore"):
            lo = np.where(a > 0, -top - g, top - g) / a
            hi = np.where(a > 0, top - g, -top - g) / a
            beta = -b / a
            # an axis the path does not accelerate: only the velocity terms count
            cap = (top - np.sign(b) * g) / np.abs(b)
        alp = np.where(moving, lo, -_BIG)
        gam = np.where(moving, hi, _BIG)
        beta = np.where(moving, beta, 0.0)
        cap = np.where(holds & ~moving & (np.abs(b) > 1e-12), cap, np.inf)
        return alp, beta, gam, np.min(cap, axis=1)
