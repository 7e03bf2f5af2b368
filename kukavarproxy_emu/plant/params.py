"""Parameters of the dynamic plant: the model file, the rigid bodies it describes, calibration error.

:func:`load_params` reads ``kr6r900sixx_dynamics.toml`` (every number there names its source).
:func:`bodies_of` joins it with the kinematic model (D-H geometry, link masses and centres of
mass) into :class:`Bodies`, the physical robot the simulation is built from.
:func:`with_calibration_error` draws a physical robot that differs from the nominal one by the
model file's ``[calibration]`` amounts, so code using the nominal model meets real mismatch.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import numpy.typing as npt

from pyopenshowvar.kinematics import RobotModel

__all__ = [
    "DEFAULT_PARAMS_FILE",
    "Bodies",
    "Calibration",
    "PlantParams",
    "bodies_of",
    "dh_matrix",
    "load_params",
    "with_calibration_error",
]

FloatArray = npt.NDArray[np.float64]
DEFAULT_PARAMS_FILE = Path(__file__).with_name("kr6r900sixx_dynamics.toml")


@dataclass(frozen=True)
class Calibration:
    """Standard deviations of the calibration error (see the model file's ``[calibration]``)."""

    length_mm: float
    angle_deg: float
    mass_fraction: float
    com_mm: float
    inertia_fraction: float
    friction_fraction: float


@dataclass(frozen=True, eq=False)
class PlantParams:
    """The model file: per-axis arrays are shape (6,), inertia (6, 3); SI units."""

    inertia: FloatArray
    rotor: FloatArray
    gear: FloatArray
    coulomb: FloatArray
    viscous: FloatArray
    friction_smoothing: float
    position_gain: float
    velocity_bandwidth: float
    integral_corner: float
    acceleration_feedforward: bool
    substeps: int
    encoder_noise_deg: float
    torque_noise_fraction: float
    calibration: Calibration

    @property
    def armature(self) -> FloatArray:
        """Motor inertia reflected to the joint, kg·m²."""
        return np.asarray(self.rotor * self.gear**2, dtype=np.float64)


def load_params(path: str | Path = DEFAULT_PARAMS_FILE) -> PlantParams:
    """Read a dynamics model file; raises ``ValueError`` for a missing or bad entry."""
    with open(path, "rb") as fh:
        data = tomllib.load(fh)
    try:
        axes = data["axis"]
        if len(axes) != 6:
            raise ValueError(f"{path}: needs 6 [[axis]] tables, found {len(axes)}")

        def col(key: str) -> FloatArray:
            return np.array([ax[key] for ax in axes], dtype=np.float64)

        servo, noise, cal = data["servo"], data["noise"], data["calibration"]
        params = PlantParams(
            inertia=np.array([ax["inertia"] for ax in axes], dtype=np.float64),
            rotor=col("rotor"),
            gear=col("gear"),
            coulomb=col("coulomb"),
            viscous=col("viscous"),
            friction_smoothing=float(data["friction"]["smoothing"]),
            position_gain=float(servo["position_gain"]),
            velocity_bandwidth=float(servo["velocity_bandwidth"]),
            integral_corner=float(servo["integral_corner"]),
            acceleration_feedforward=bool(servo["acceleration_feedforward"]),
            substeps=int(servo["substeps"]),
            encoder_noise_deg=float(noise["encoder_deg"]),
            torque_noise_fraction=float(noise["torque_fraction"]),
            calibration=Calibration(**{k: float(v) for k, v in cal.items()}),
        )
    except (KeyError, TypeError) as exc:
        raise ValueError(f"{path}: missing or malformed entry {exc}") from None
    arrays = (params.rotor, params.gear, params.coulomb, params.viscous)
    if params.inertia.shape != (6, 3) or any(a.shape != (6,) for a in arrays):
        raise ValueError(f"{path}: inertia needs 3 values and every axis entry one")
    if np.any(params.inertia <= 0) or np.any(params.gear <= 0) or np.any(params.rotor < 0):
        raise ValueError(f"{path}: inertia and gear must be > 0, rotor >= 0")
    if np.any(params.coulomb < 0) or np.any(params.viscous < 0) or params.substeps < 1:
        raise ValueError(f"{path}: friction must be >= 0 and substeps >= 1")
    return params


def dh_matrix(a: float, alpha: float, d: float, theta: float) -> FloatArray:
    """Standard D-H link transform ``Rz(θ)·Tz(d)·Tx(a)·Rx(α)`` (mm, degrees)."""
    ct, st = np.cos(np.radians(theta)), np.sin(np.radians(theta))
    ca, sa = np.cos(np.radians(alpha)), np.sin(np.radians(alpha))
    return np.array(
        [[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st], [0.0, sa, ca, d],
         [0.0, 0.0, 0.0, 1.0]]
    )  # fmt: skip


@dataclass(frozen=True, eq=False)
class Bodies:
    """The physical robot.

    Standard D-H rows (mm, deg) and KUKA axis signs; ``flange`` the last D-H frame → KUKA
    flange transform; per link: mass (kg), centre of mass ``com`` (mm) and principal inertia
    moments (kg·m²) about the axes ``inertia_axes`` (3×3 columns), both in the link's body
    frame (the D-H frame carrying its joint axis, see :mod:`.mjcf`); friction per axis.
    """

    a: FloatArray
    alpha: FloatArray
    d: FloatArray
    offset: FloatArray
    sign: FloatArray
    flange: FloatArray
    mass: FloatArray
    com: FloatArray
    inertia: FloatArray
    inertia_axes: FloatArray
    coulomb: FloatArray
    viscous: FloatArray

    def joint_frames(self) -> FloatArray:
        """Body frame of each link in the all-zero pose, base frame: ``(6, 4, 4)``, mm.

        Link j's body frame is the D-H frame j-1 (its z axis is joint j's axis).
        """
        frames = np.empty((6, 4, 4))
        acc = np.eye(4)
        for j in range(6):
            frames[j] = acc
            acc = acc @ dh_matrix(self.a[j], self.alpha[j], self.d[j], self.offset[j])
        return frames


def bodies_of(model: RobotModel, params: PlantParams) -> Bodies:
    """The nominal physical robot of ``model`` with the model file's inertia and friction.

    The kinematic model gives each centre of mass in the base frame at the all-zero pose and
    the model file gives inertia along the base axes there; both move into the link frames.
    """
    bodies = Bodies(
        a=model.a.copy(),
        alpha=model.alpha.copy(),
        d=model.d.copy(),
        offset=model.offset.copy(),
        sign=model.sign.copy(),
        flange=model.flange.copy(),
        mass=model.link_mass.copy(),
        com=np.zeros((6, 3)),
        inertia=params.inertia.copy(),
        inertia_axes=np.zeros((6, 3, 3)),
        coulomb=params.coulomb.copy(),
        viscous=params.viscous.copy(),
    )
    frames = bodies.joint_frames()
    com_base = model.link_origin + model.link_com
    rot = frames[:, :3, :3]
    com = np.einsum("jki,jk->ji", rot, com_base - frames[:, :3, 3])  # Rᵀ (c − o)
    axes = np.transpose(rot, (0, 2, 1))  # base axes seen from the link frame: Rᵀ
    return replace(bodies, com=com, inertia_axes=axes)


def with_calibration_error(bodies: Bodies, cal: Calibration, seed: int) -> Bodies:
    """A physical robot drawn around ``bodies`` (same ``seed``, same robot).

    Lengths and angles are normal with the given standard deviations; masses, inertia and
    friction are scaled by ``1 + N(0, fraction)`` clipped to ±3 σ so none turns negative.
    """
    rng = np.random.default_rng(seed)

    def scale(x: FloatArray, frac: float, shape: tuple[int, ...] = (6,)) -> FloatArray:
        factor = 1.0 + np.clip(rng.normal(0.0, frac, shape), -3 * frac, 3 * frac)
        return np.asarray(x * factor, dtype=np.float64)

    return replace(
        bodies,
        a=bodies.a + rng.normal(0.0, cal.length_mm, 6),
        d=bodies.d + rng.normal(0.0, cal.length_mm, 6),
        alpha=bodies.alpha + rng.normal(0.0, cal.angle_deg, 6),
        offset=bodies.offset + rng.normal(0.0, cal.angle_deg, 6),
        mass=scale(bodies.mass, cal.mass_fraction),
        com=bodies.com + rng.normal(0.0, cal.com_mm, (6, 3)),  # moves with its link
        # one factor per link: the three moments keep satisfying the triangle inequality
        inertia=scale(bodies.inertia, cal.inertia_fraction, (6, 1)),
        coulomb=scale(bodies.coulomb, cal.friction_fraction),
        viscous=scale(bodies.viscous, cal.friction_fraction),
    )
