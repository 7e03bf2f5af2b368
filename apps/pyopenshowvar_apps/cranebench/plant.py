"""The benchmark's crane: rigid-body dynamics (MuJoCo) driven by the hydraulics of
:mod:`.hydraulics` — a plant of its own, never the solvers' kinematics.

The solvers see only the arm description (the thesis' D-H table, ``knuckle_boom_crane``). The
plant is a separate MuJoCo model written here from the crane's dimensions: a slewing column
(2.62 m), a boom (7.01 m) and a jib (3.46 m), each a solid steel-like body with the masses of
:class:`PlantParams`, the payload a rigid mass at the jib's tip (the thesis' figures show no
pendulum sway, and its D-H chain ends at the tip). Its own frames decide where the tip is;
a test checks they agree with the D-H description (the same crane described twice).

Each joint is driven by a MuJoCo velocity actuator whose gain is the oil column's damping in
joint space (``c_h·r(q)²``) and whose force range is the relief valve's torque range at the
current angle; both follow the lever geometry (updated at the controller's 50 Hz), so the
joint torque is exactly the cylinder force times its lever arm. The valves' first-order lag
is MuJoCo's ``filter`` actuator dynamics on the flow the spool command asks for (the joint
speed ``Q/(A·r)``, piston or annulus area by the command's sign). A moving ship enters as the
effective gravity in the crane's base frame, ``g_eff = Rᵀ(g − a)`` (see
:meth:`CranePlant.set_gravity`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .hydraulics import Hydraulics

__all__ = ["CranePlant", "PlantParams"]

FloatArray = npt.NDArray[np.float64]
G = 9.81


@dataclass(frozen=True)
class PlantParams:
    """The plant's own numbers: lengths (m), masses (kg), joint friction, time step (s)."""

    column: float = 2.62
    boom: float = 7.01
    jib: float = 3.46
    column_mass: float = 6000.0
    boom_mass: float = 4500.0
    jib_mass: float = 1800.0
    friction: tuple[float, float, float] = (5.0e3, 2.0e3, 1.0e3)  # N·m·s/rad, bearings
    timestep: float = 0.002
    #: the plant's mechanical end stops (deg): the jib cylinder's geometry leaves a few
    #: degrees less than the description's −150…20
    lower: tuple[float, float, float] = (-180.0, -10.0, -148.0)
    upper: tuple[float, float, float] = (180.0, 80.0, 18.0)
    hydraulics: Hydraulics = field(default_factory=Hydraulics)


def _mjcf(p: PlantParams, payload: float) -> str:
    h = p.hydraulics
    taus = (h.slew.valve.tau, h.boom.valve.tau, h.jib.valve.tau)
    # boom and jib pitch about −y, so a positive angle raises them (the D-H description's
    # sense); the slew turns about +z
    return f"""
<mujoco model="knuckle_boom_crane_plant">
  <compiler angle="degree"/>
  <option timestep="{p.timestep}" integrator="implicitfast" gravity="0 0 -{G}"/>
  <worldbody>
    <body name="column">
      <joint name="slew" type="hinge" axis="0 0 1" damping="{p.friction[0]}"/>
      <geom type="cylinder" fromto="0 0 0 0 0 {p.column}" size="0.5" mass="{p.column_mass}"/>
      <body name="boom" pos="0 0 {p.column}">
        <joint name="boom" type="hinge" axis="0 -1 0" damping="{p.friction[1]}"
               limited="true" range="{p.lower[1]} {p.upper[1]}"/>
        <geom type="box" pos="{p.boom / 2} 0 0" size="{p.boom / 2} 0.3 0.35" mass="{p.boom_mass}"/>
        <body name="jib" pos="{p.boom} 0 0">
          <joint name="jib" type="hinge" axis="0 -1 0" damping="{p.friction[2]}"
                 limited="true" range="{p.lower[2]} {p.upper[2]}"/>
          <geom type="box" pos="{p.jib / 2} 0 0" size="{p.jib / 2} 0.2 0.25" mass="{p.jib_mass}"/>
          <body name="payload" pos="{p.jib} 0 0">
            <geom type="sphere" size="0.4" mass="{max(payload, 1e-3)}" contype="0" conaffinity="0"/>
            <site name="tip"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <general joint="slew" dyntype="filter" dynprm="{taus[0]}" gainprm="1"
             biastype="affine" biasprm="0 0 -1" forcelimited="true" forcerange="-1 1"/>
    <general joint="boom" dyntype="filter" dynprm="{taus[1]}" gainprm="1"
             biastype="affine" biasprm="0 0 -1" forcelimited="true" forcerange="-1 1"/>
    <general joint="jib" dyntype="filter" dynprm="{taus[2]}" gainprm="1"
             biastype="affine" biasprm="0 0 -1" forcelimited="true" forcerange="-1 1"/>
  </actuator>
</mujoco>"""


class CranePlant:
    """The simulated crane (angles in degrees at the API, as the arm description's)."""

    def __init__(self, params: PlantParams, payload_kg: float, q0_deg: npt.ArrayLike) -> None:
        import mujoco

        self._mj = mujoco
        self.params = params
        self.hyd = params.hydraulics
        self.model = mujoco.MjModel.from_xml_string(_mjcf(params, payload_kg))
        self.data = mujoco.MjData(self.model)
        self.data.qpos[:] = np.radians(np.asarray(q0_deg, dtype=np.float64))
        mujoco.mj_forward(self.model, self.data)
        self._tip = self.model.site("tip").id
        self.t = 0.0

    @property
    def dt(self) -> float:
        return float(self.model.opt.timestep)

    @property
    def q(self) -> FloatArray:
        """Joint angles (deg)."""
        return np.asarray(np.degrees(np.array(self.data.qpos)), dtype=np.float64)

    @property
    def qdot(self) -> FloatArray:
        """Joint speeds (deg/s)."""
        return np.asarray(np.degrees(np.array(self.data.qvel)), dtype=np.float64)

    @property
    def torque(self) -> FloatArray:
        """The drives' joint torques (N·m) of the last step."""
        return np.array(self.data.actuator_force)

    def rod_forces(self) -> FloatArray:
        """Boom and jib cylinder forces (N) of the last step."""
        return self.hyd.rod_forces(self.torque, np.array(self.data.qpos))

    def tip(self) -> FloatArray:
        """The payload's position (mm) in the crane's base frame, by the plant's own frames."""
        return np.array(self.data.site_xpos[self._tip]) * 1000.0

    def set_gravity(self, g_base: FloatArray) -> None:
        """A moving base: the effective gravity in the crane's base frame (m/s²),
        g_eff = Rᵀ(g − a) for the base's attitude R and acceleration a; the base's rotation
        rates (Euler, centrifugal and Coriolis terms) are left out: a ship turns at a few
        hundredths of a radian per second."""
        self.model.opt.gravity[:] = np.asarray(g_base, dtype=np.float64)

    def step(self, command: FloatArray, duration: float) -> None:
        """Run the valves and the dynamics for ``duration`` s with spool commands
        ``command`` (each in [−1, 1], held)."""
        mj, m, d = self._mj, self.model, self.data
        n = max(1, round(duration / self.dt))
        target = np.clip(np.asarray(command, dtype=np.float64), -1.0, 1.0)
        # the lever geometry changes little within one call (≤ 20 ms): gains, relief limits
        # and the flow-to-speed factors are set once per call, then MuJoCo steps on its own
        q = np.array(d.qpos)
        kv = self.hyd.joint_damping(q)
        m.actuator_gainprm[:, 0] = kv
        m.actuator_biasprm[:, 2] = -kv
        m.actuator_forcerange[:] = self.hyd.torque_ranges(q)
        d.ctrl[:] = self.hyd.joint_speeds(target, q)
        mj.mj_step(m, d, nstep=n)
        self.t += n * self.dt
        if not np.all(np.isfinite(d.qpos)):
            raise FloatingPointError("the crane plant diverged")
