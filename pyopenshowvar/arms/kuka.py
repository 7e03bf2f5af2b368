"""The KUKA six-axis family: closed-form IK models for any arm of that layout, both ways.

:func:`from_robot_model` turns a :class:`~pyopenshowvar.kinematics.RobotModel` (the KR 6
R900 sixx) into an :class:`~.model.Arm` that keeps the model as its ``kuka`` attribute, so
the KR 6 keeps its exact closed form, S/T bits and statics.

:func:`derive_robot_model` goes the other way for any 6R chain (a URDF of a KR 10, KR 16,
KR 210, KR 560 ...): it measures the arm in its all-zero pose, where a KUKA arm is stretched
out along +x with axes A1 ∥ z, A2, A3, A5 ∥ y and A4, A6 ∥ x, reads off the six lengths of
the KR 6's D-H table (a1, d1, a2, a3, d4, d6) and the axis signs, and keeps the result only
if its forward kinematics matches the chain at random poses to 1e-8 mm. So the closed form
of :mod:`pyopenshowvar.kinematics.inverse` is used exactly when it is right.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..kinematics.forward import fk_matrix
from ..kinematics.frames import FloatArray
from ..kinematics.model import RobotModel
from .dh import DHRow, dh_chain
from .model import Arm, Inertial, Joint, Source

__all__ = ["derive_robot_model", "from_robot_model", "with_closed_form"]

log = logging.getLogger(__name__)

# The KR 6 R900 sixx's table shape: (alpha deg, theta offset deg) per row, and the KUKA
# positive axis directions at the all-zero pose (A1 -Z, A2 +Y, A3 +Y, A4 -X, A5 +Y, A6 -X).
_ALPHA = (-90.0, 0.0, -90.0, 90.0, -90.0, 0.0)
_THETA = (0.0, 0.0, -90.0, 0.0, 0.0, 180.0)
_KUKA_AXES = np.array([[0, 0, -1], [0, 1, 0], [0, 1, 0], [-1, 0, 0], [0, 1, 0], [-1, 0, 0.0]])
_KR6_SIGNS = (-1.0, 1.0, 1.0, -1.0, 1.0, -1.0)
#: Placeholder for unknown speeds/accelerations in a derived model (RobotModel needs > 0).
UNKNOWN_RATE = 1e6


def from_robot_model(
    model: RobotModel,
    *,
    key: str = "",
    model_name: str = "",
    family: str = "",
    source: Source | None = None,
) -> Arm:
    """The arm of a kinematics :class:`RobotModel` (standard D-H), keeping it for the
    closed form. Link masses become inertials at the model's centres of mass (tensors unknown)."""
    rows = [
        DHRow("revolute", model.a[i], math.radians(model.alpha[i]), model.d[i],
              math.radians(model.offset[i]), model.sign[i])
        for i in range(6)
    ]  # fmt: skip
    chain, tail, _ = dh_chain(rows, "standard")
    arm0 = Arm(
        model.name,
        tuple(
            Joint(f"A{i + 1}", "revolute", o, a, model.lower[i], model.upper[i])
            for i, (o, a) in enumerate(chain)
        ),
    )
    # link frames at the all-zero pose, to put the model's absolute COMs into link frames
    frames0 = arm0.link_frames(np.zeros(6))
    joints = []
    for i, (o, a) in enumerate(chain):
        inertial = None
        if model.link_mass[i] > 0.0:
            com_abs = np.append(model.link_origin[i] + model.link_com[i], 1.0)
            inertial = Inertial(
                float(model.link_mass[i]), (np.linalg.inv(frames0[i]) @ com_abs)[:3]
            )
        torque = float(model.max_torque[i])
        joints.append(
            Joint(
                f"A{i + 1}", "revolute", o, a, float(model.lower[i]), float(model.upper[i]),
                float(model.max_speed[i]), float(model.max_accel[i]),
                torque if math.isfinite(torque) else math.nan, inertial,
            )
        )  # fmt: skip
    return Arm(
        model.name,
        tuple(joints),
        flange=tail @ model.flange,
        home=model.home,
        source=source or Source(),
        key=key,
        family=family,
        model_name=model_name,
        kuka=model,
    )


def _rate(v: float) -> float:
    return v if math.isfinite(v) else UNKNOWN_RATE


def _kuka_dh(arm: Arm, frames: FloatArray, flange: FloatArray) -> FloatArray | None:
    """The KUKA D-H table (a, α, d, θ, sign per axis) of an arm whose link ``frames`` and
    ``flange`` at the zero pose have the KUKA layout; None when they do not."""
    w = np.einsum("kij,kj->ki", frames[:, :3, :3], np.stack([j.axis for j in arm.joints]))
    o = frames[:, :3, 3] - arm.base[:3, 3]
    dots = np.einsum("ki,ki->k", w, _KUKA_AXES)
    eps = 1e-9 * max(1.0, float(np.max(np.abs(o))))
    if np.any(np.abs(np.abs(dots) - 1.0) > 1e-9):
        return None
    # lines of axes 2, 3, 5 run along y (their x, z matter); axes 4, 6 along x (y, z matter)
    a1, d1 = o[1, 0], o[1, 2]
    a2 = o[2, 0] - o[1, 0]
    a3 = o[3, 2] - o[2, 2]
    d4 = o[4, 0] - o[2, 0]
    d6 = flange[0, 3] - arm.base[0, 3] - o[4, 0]
    z_wrist = o[3, 2]
    aligned = (
        abs(o[0, 0]) < eps
        and abs(o[0, 1]) < eps
        and abs(o[2, 2] - o[1, 2]) < eps
        and abs(o[4, 2] - z_wrist) < eps
        and abs(o[5, 2] - z_wrist) < eps
        and abs(o[3, 1]) < eps
        and abs(o[5, 1]) < eps
    )
    if not aligned:
        return None
    signs = [s * float(np.sign(d)) for s, d in zip(_KR6_SIGNS, dots, strict=True)]
    dh = np.array(
        [
            [a1, _ALPHA[0], d1, _THETA[0], signs[0]],
            [a2, _ALPHA[1], 0.0, _THETA[1], signs[1]],
            [a3, _ALPHA[2], 0.0, _THETA[2], signs[2]],
            [0.0, _ALPHA[3], d4, _THETA[3], signs[3]],
            [0.0, _ALPHA[4], 0.0, _THETA[4], signs[4]],
            [0.0, _ALPHA[5], d6, _THETA[5], signs[5]],
        ]
    )
    return dh


def _link_masses(arm: Arm, frames: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Link masses and centres of mass (base frame, zero pose) of the arm's joints."""
    masses = np.zeros(6)
    coms = np.zeros((6, 3))
    for i, j in enumerate(arm.joints):
        if j.inertial is not None:
            masses[i] = j.inertial.mass
            coms[i] = frames[i, :3, :3] @ j.inertial.com + frames[i, :3, 3]
    return masses, coms


def derive_robot_model(arm: Arm, *, samples: int = 64, tol_mm: float = 1e-8) -> RobotModel | None:
    """The closed-form model of a KUKA-layout 6R arm, or None if the arm is not one."""
    if arm.dof != 6 or not all(arm.revolute):
        return None
    if not np.allclose(arm.base, np.eye(4)):
        return None  # the closed form's frame 0 is $ROBROOT = the chain's base frame
    frames = arm.link_frames(np.zeros(6))
    flange = arm.fk(np.zeros(6))
    dh = _kuka_dh(arm, frames, flange)
    if dh is None:
        return None
    masses, coms = _link_masses(arm, frames)
    probe = RobotModel(
        name=arm.name,
        dh=dh,
        lower=arm.lower,
        upper=arm.upper,
        max_speed=np.array([_rate(v) for v in arm.max_speed]),
        max_accel=np.array([_rate(v) for v in arm.max_accel]),
        link_mass=masses,
        link_com=coms,
        home=arm.home,  # type: ignore[arg-type]
        max_torque=np.where(np.isfinite(arm.max_effort), arm.max_effort, np.inf),
    )
    flange_fix = np.linalg.inv(fk_matrix(probe, np.zeros(6))) @ flange
    model = RobotModel(
        name=probe.name,
        dh=probe.dh,
        lower=probe.lower,
        upper=probe.upper,
        max_speed=probe.max_speed,
        max_accel=probe.max_accel,
        link_mass=probe.link_mass,
        link_com=probe.link_com,
        flange=_clean(flange_fix),
        home=probe.home,
        max_torque=probe.max_torque,
    )
    rng = np.random.default_rng(0)
    q = rng.uniform(arm.lower, arm.upper, size=(samples, 6))
    err = np.abs(fk_matrix(model, q) - arm.fk(q))
    if float(np.max(err[..., :3, 3])) > tol_mm or float(np.max(err[..., :3, :3])) > 1e-11:
        log.debug("%s: KUKA-layout guess does not reproduce the chain", arm.name)
        return None
    return model


def with_closed_form(arm: Arm) -> Arm:
    """The arm with its ``kuka`` model set when it has the KUKA layout (else unchanged)."""
    from dataclasses import replace

    model = derive_robot_model(arm)
    return arm if model is None else replace(arm, kuka=model)


def _clean(t: FloatArray) -> FloatArray:
    """Round-off (1e-16) out of a transform that should be exact."""
    return np.where(np.abs(t) < 1e-12, 0.0, t)
