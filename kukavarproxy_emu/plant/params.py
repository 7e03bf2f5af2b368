"""Parameters of the dynamic plant: the model file, the rigid bodies it describes, calibration error.

:func:`load_params` reads the plant's own model file (``kr6r900sixx_dynamics.toml``; every
number there names its source) into :class:`PlantParams`, whose :attr:`~PlantParams.bodies`
are the physical robot the simulation is built from (geometry, masses, centres of mass,
inertia, motor inertia, friction, motor torque limits). :func:`make_bodies` builds
:class:`Bodies` from per-link data given in the base frame at the all-zero pose (the file's
and URDF's convention), so the controller's nominal model can be built the same way from its
own numbers. :func:`with_calibration_error` draws a physical robot that differs from the
nominal one by the file's ``[calibration]`` amounts.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .frames import FloatArray, dh_matrix, frame_matrix

__all__ = [
    "DEFAULT_PARAMS_FILE",
    "Bodies",
    "Calibration",
    "PlantParams",
    "load_params",
    "make_bodies",
    "params_of",
    "with_calibration_error",
]

DEFAULT_PARAMS_FILE = Path(__file__).with_name("kr6r900sixx_dynamics.toml")
_LINK_KEYS = (
    "dh", "sign", "origin", "mass", "com", "inertia", "rotor", "gear", "coulomb", "static",
    "viscous", "max_torque",
)  # fmt: skip


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
class Bodies:
    """A robot as rigid bodies.

    Standard D-H rows (mm, deg) and KUKA axis signs; ``flange`` the last D-H frame → KUKA
    flange transform; per link: mass (kg), centre of mass ``com`` (mm) and principal inertia
    moments (kg·m²) about the axes ``inertia_axes`` (3×3 columns), both in the link's body
    frame (the D-H frame carrying its joint axis, see :mod:`.mjcf`); per axis the armature
    (motor inertia at the joint, kg·m²), friction (Coulomb and static Nm, viscous Nm·s/rad)
    and the motor's torque limit (Nm).
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
    armature: FloatArray
    coulomb: FloatArray
    static: FloatArray
    viscous: FloatArray
    max_torque: FloatArray

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


def make_bodies(
    dh: FloatArray,
    sign: FloatArray,
    flange: FloatArray,
    *,
    mass: FloatArray,
    com_base: FloatArray,
    inertia: FloatArray,
    armature: FloatArray,
    max_torque: FloatArray,
    coulomb: FloatArray | None = None,
    static: FloatArray | None = None,
    viscous: FloatArray | None = None,
    principal_axes: FloatArray | None = None,
) -> Bodies:
    """:class:`Bodies` from per-link data in the base frame at the all-zero pose.

    ``dh`` rows are ``(a, alpha, d, theta offset)``; ``com_base`` the centres of mass (mm) and
    ``inertia`` the principal moments along the base axes (or along ``principal_axes``, per
    link a 3×3 of column vectors in the base frame), all at the all-zero pose; they move into
    the link body frames here. Friction defaults to none.
    """
    zeros = np.zeros(6)
    bodies = Bodies(
        a=np.array(dh[:, 0], dtype=np.float64),
        alpha=np.array(dh[:, 1], dtype=np.float64),
        d=np.array(dh[:, 2], dtype=np.float64),
        offset=np.array(dh[:, 3], dtype=np.float64),
        sign=np.array(sign, dtype=np.float64),
        flange=np.array(flange, dtype=np.float64),
        mass=np.array(mass, dtype=np.float64),
        com=np.zeros((6, 3)),
        inertia=np.array(inertia, dtype=np.float64),
        inertia_axes=np.zeros((6, 3, 3)),
        armature=np.array(armature, dtype=np.float64),
        coulomb=zeros.copy() if coulomb is None else np.array(coulomb, dtype=np.float64),
        static=zeros.copy() if static is None else np.array(static, dtype=np.float64),
        viscous=zeros.copy() if viscous is None else np.array(viscous, dtype=np.float64),
        max_torque=np.array(max_torque, dtype=np.float64),
    )
    frames = bodies.joint_frames()
    rot = frames[:, :3, :3]
    com = np.einsum("jki,jk->ji", rot, np.asarray(com_base) - frames[:, :3, 3])  # Rᵀ (c − o)
    axes = np.transpose(rot, (0, 2, 1))  # base axes seen from the link frame: Rᵀ
    if principal_axes is not None:
        axes = axes @ np.asarray(principal_axes, dtype=np.float64)  # Rᵀ·P
    return replace(bodies, com=com, inertia_axes=axes)


@dataclass(frozen=True, eq=False)
class PlantParams:
    """The model file: the physical robot (:attr:`bodies`), servo, friction curve, noise,
    calibration error; SI units."""

    name: str
    bodies: Bodies
    friction_smoothing: float
    stribeck_velocity: float
    position_gain: float
    velocity_bandwidth: float
    integral_corner: float
    acceleration_feedforward: bool
    substeps: int
    following_error_deg: float
    encoder_noise_deg: float
    torque_noise_fraction: float
    calibration: Calibration

    @property
    def armature(self) -> FloatArray:
        """Motor inertia reflected to the joint, kg·m² (of the nominal bodies)."""
        return self.bodies.armature


def _frame(xyzabc: list[float]) -> FloatArray:
    return frame_matrix(tuple(float(v) for v in xyzabc))


def _bodies_of(links: list[dict[str, Any]], flange: list[float], path: object) -> Bodies:
    if len(links) != 6:
        raise ValueError(f"{path}: needs 6 [[link]] tables, found {len(links)}")
    missing = [k for k in _LINK_KEYS if any(k not in link for link in links)]
    if missing:
        raise ValueError(f"{path}: every [[link]] needs {', '.join(missing)}")

    def col(key: str, shape: tuple[int, ...] = (6,)) -> FloatArray:
        arr = np.array([link[key] for link in links], dtype=np.float64)
        if arr.shape != shape or not np.all(np.isfinite(arr)):
            raise ValueError(f"{path}: [[link]] {key} needs {shape[1:] or 'one'} finite value(s)")
        return arr

    mass, rotor, gear = col("mass"), col("rotor"), col("gear")
    inertia, axes = _inertia_of(links, path)
    sign, max_torque = col("sign"), col("max_torque")
    coulomb, static, viscous = col("coulomb"), col("static"), col("viscous")
    if np.any(mass < 0) or np.any(inertia <= 0) or np.any(gear <= 0) or np.any(rotor < 0):
        raise ValueError(f"{path}: mass and rotor must be >= 0, inertia and gear > 0")
    if min(coulomb.min(), static.min(), viscous.min()) < 0 or np.any(max_torque <= 0):
        raise ValueError(f"{path}: friction must be >= 0 and max_torque > 0")
    if not np.all(np.isin(sign, (-1.0, 1.0))):
        raise ValueError(f"{path}: sign must be +1 or -1")
    return make_bodies(
        col("dh", (6, 4)), sign, _frame(flange),
        mass=mass, com_base=col("origin", (6, 3)) + col("com", (6, 3)), inertia=inertia,
        armature=rotor * gear**2, max_torque=max_torque, coulomb=coulomb, static=static,
        viscous=viscous, principal_axes=axes,
    )  # fmt: skip


def _inertia_of(links: list[dict[str, Any]], path: object) -> tuple[FloatArray, FloatArray]:
    """Per link the principal moments (kg·m²) and their axes (columns, base frame).

    ``inertia`` is 3 principal moments along the base axes, or a full tensor about the centre
    of mass in base axes, ``[ixx, ixy, ixz, iyy, iyz, izz]`` (what a URDF's inertial becomes
    at the all-zero pose), diagonalised here.
    """
    moments, axes = np.zeros((6, 3)), np.zeros((6, 3, 3))
    for j, link in enumerate(links):
        row = np.array(link["inertia"], dtype=np.float64).ravel()
        if not np.all(np.isfinite(row)) or row.shape not in ((3,), (6,)):
            raise ValueError(f"{path}: [[link]] inertia needs 3 or 6 finite values")
        if row.shape == (3,):
            moments[j], axes[j] = row, np.eye(3)
            continue
        xx, xy, xz, yy, yz, zz = row
        moments[j], axes[j] = np.linalg.eigh(np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]))
    return moments, axes


def load_params(path: str | Path = DEFAULT_PARAMS_FILE) -> PlantParams:
    """Read a plant model file; raises ``ValueError`` for a missing or bad entry."""
    with open(path, "rb") as fh:
        return params_of(tomllib.load(fh), path)


def params_of(data: dict[str, Any], path: str | Path = "<plant model>") -> PlantParams:
    """:class:`PlantParams` of a parsed plant model file (``path`` names it in errors)."""
    try:
        servo, noise, cal = data["servo"], data["noise"], data["calibration"]
        fric = data["friction"]
        params = PlantParams(
            name=str(data.get("name", Path(path).stem)),
            bodies=_bodies_of(data["link"], data.get("flange", [0.0] * 6), path),
            friction_smoothing=float(fric["smoothing"]),
            stribeck_velocity=float(fric["stribeck"]),
            position_gain=float(servo["position_gain"]),
            velocity_bandwidth=float(servo["velocity_bandwidth"]),
            integral_corner=float(servo["integral_corner"]),
            acceleration_feedforward=bool(servo["acceleration_feedforward"]),
            substeps=int(servo["substeps"]),
            following_error_deg=float(servo["following_error_deg"]),
            encoder_noise_deg=float(noise["encoder_deg"]),
            torque_noise_fraction=float(noise["torque_fraction"]),
            calibration=Calibration(**{k: float(v) for k, v in cal.items()}),
        )
    except (KeyError, TypeError) as exc:
        raise ValueError(f"{path}: missing or malformed entry {exc}") from None
    if params.substeps < 1 or params.friction_smoothing <= 0 or params.stribeck_velocity <= 0:
        raise ValueError(f"{path}: substeps must be >= 1, friction speeds > 0")
    if params.following_error_deg <= 0:
        raise ValueError(f"{path}: following_error_deg must be > 0")
    return params


def with_calibration_error(bodies: Bodies, cal: Calibration, seed: int) -> Bodies:
    """A physical robot drawn around ``bodies`` (same ``seed``, same robot).

    Lengths and angles are normal with the given standard deviations; masses, inertia and
    friction are scaled by ``1 + N(0, fraction)`` clipped to ±3 σ so none turns negative.
    """
    rng = np.random.default_rng(seed)

    def scale(x: FloatArray, frac: float, shape: tuple[int, ...] = (6,)) -> FloatArray:
        factor = 1.0 + np.clip(rng.normal(0.0, frac, shape), -3 * frac, 3 * frac)
        return np.asarray(x * factor, dtype=np.float64)

    a = bodies.a + rng.normal(0.0, cal.length_mm, 6)
    d = bodies.d + rng.normal(0.0, cal.length_mm, 6)
    alpha = bodies.alpha + rng.normal(0.0, cal.angle_deg, 6)
    offset = bodies.offset + rng.normal(0.0, cal.angle_deg, 6)
    mass = scale(bodies.mass, cal.mass_fraction)
    com = bodies.com + rng.normal(0.0, cal.com_mm, (6, 3))  # moves with its link
    # one factor per link: the three moments keep satisfying the triangle inequality
    inertia = scale(bodies.inertia, cal.inertia_fraction, (6, 1))
    coulomb = scale(bodies.coulomb, cal.friction_fraction)
    viscous = scale(bodies.viscous, cal.friction_fraction)
    # the breakaway friction keeps its ratio to the Coulomb friction (the curve's shape)
    ratio = np.divide(coulomb, bodies.coulomb, out=np.ones(6), where=bodies.coulomb > 0)
    return replace(
        bodies, a=a, d=d, alpha=alpha, offset=offset, mass=mass, com=com, inertia=inertia,
        coulomb=coulomb, viscous=viscous, static=bodies.static * ratio,
    )  # fmt: skip
