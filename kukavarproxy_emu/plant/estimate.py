"""A plant model file for any KUKA six-axis arm: its description's numbers, estimates for the rest.

The KR 6's physical robot has a hand-written model file (``kr6r900sixx_dynamics.toml``). For
the other KUKA arms of the catalogue the files beside it (``<name>_dynamics.toml``) were
written by this module, once, from the arm's description (``python -m
kukavarproxy_emu.plant.estimate kr16_r2010_2 > ...``) and are read as they are since: the
physical robot keeps numbers of its own, which can be edited without touching the client
library's description. An arm file given to ``kukavarproxy-emu --robot FILE`` gets its model
generated the same way when the emulator starts (nothing to keep in step by hand).

Every number says where it comes from in the file's comments:

* geometry (D-H rows, axis signs, flange), axis speeds and max torques: the description;
* link masses, centres of mass and inertia tensors: the description's inertials (URDF
  ``<inertial>``) where it has them. Where it has none (KR 16 R2010-2, KR 560 R3100-2) they
  are **estimated** from the KR 210 R2700-2, the KUKA arm of the same layout whose source has
  full inertials: lengths scale by ``k_L`` (the arm's a2 + d4 over the KR 210's), masses by
  ``k_m = (A2 max torque ratio) / k_L`` (the A2 drive is sized for the arm's weight at its
  reach, so the static A2 load keeps the KR 210's share of its rating), centres of mass by
  ``k_L`` from their joints, inertia by ``k_m·k_L²``;
* motor inertia, gear ratio, friction and the servo: the estimates the KR 6's file documents,
  scaled per axis (gear = 4500 rpm over the axis speed; rotor inertia proportional to the
  motor torque, max torque / gear, with the KR 6's motors as the reference; Coulomb friction
  3 % of max torque, breakaway 1.3 × Coulomb, viscous 3 % of max torque at max speed).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .frames import FloatArray, dh_matrix

if TYPE_CHECKING:
    from pyopenshowvar.arms import Arm

__all__ = ["ESTIMATE_REFERENCE", "LinkEstimate", "estimate_links", "plant_file_text"]

#: The arm whose inertials stand in for an arm without any (see the module docstring).
ESTIMATE_REFERENCE = "kr210_r2700_2"
#: Max motor speed (rpm) of the KR 6's $VEL_AXIS_MA, used for every arm's gear ratio.
MOTOR_RPM = 4500.0
#: Rotor inertia per Nm of motor torque (kg·m²/Nm): the KR 6 file's 0.5 kg·cm² A1 motor at
#: 334.8 Nm / 75, and its 0.15 kg·cm² wrist motor at 43.3 Nm / 70.87.
ROTOR_PER_NM = (0.5e-4 / (334.8 / 75.0), 0.15e-4 / (43.3 / 70.87))
COULOMB_SHARE, STATIC_RATIO, VISCOUS_SHARE = 0.03, 1.3, 0.03

_SERVO_AND_REST = """
[servo]
# The KR 6 file's cascaded servo (estimates, see kr6r900sixx_dynamics.toml): the gains are
# scheduled on the inertia each axis sees, so the same bandwidths suit any arm size.
position_gain = 40.0
velocity_bandwidth = 250.0
integral_corner = 50.0
acceleration_feedforward = true
substeps = 6
following_error_deg = 1.0

[friction]
# Stribeck curve of the KR 6 file; per-axis amounts in [[link]] (3 % rule, see the header).
smoothing = 0.05
stribeck = 0.1

[noise]
encoder_deg = 2e-5
torque_fraction = 0.001

[calibration]
# The KR 6 file's amounts (an arm mastered but not absolutely accurate); estimates.
length_mm = 0.2
angle_deg = 0.02
mass_fraction = 0.05
com_mm = 5.0
inertia_fraction = 0.10
friction_fraction = 0.20
"""


@dataclass(frozen=True, eq=False)
class LinkEstimate:
    """One link of the physical robot: mass (kg), centre of mass (mm, base frame at the
    all-zero pose), inertia tensor about it (kg·m², base axes) and where they come from."""

    mass: float
    com: FloatArray
    tensor: FloatArray
    how: str


def _inertials_at_zero(arm: Arm) -> list[LinkEstimate] | None:
    """The description's own inertials in the base frame, or None if any link lacks one."""
    frames = arm.link_frames(np.zeros(arm.dof))
    out = []
    for i, joint in enumerate(arm.joints):
        ine = joint.inertial
        if ine is None or ine.inertia is None or ine.mass <= 0.0:
            return None
        rot = frames[i, :3, :3]
        com = rot @ ine.com + frames[i, :3, 3]
        out.append(LinkEstimate(ine.mass, com, rot @ ine.inertia @ rot.T, "description"))
    return out


def _reach(arm: Arm) -> float:
    assert arm.kuka is not None
    return float(abs(arm.kuka.a[1]) + abs(arm.kuka.d[3]))


def estimate_links(arm: Arm) -> list[LinkEstimate]:
    """Per link the masses and inertia of the physical robot (see the module docstring)."""
    own = _inertials_at_zero(arm)
    if own is not None:
        return own
    from pyopenshowvar.arms import load_arm

    ref = load_arm(ESTIMATE_REFERENCE)
    ref_links = _inertials_at_zero(ref)
    assert ref_links is not None and ref.kuka is not None and arm.kuka is not None
    k_l = _reach(arm) / _reach(ref)
    tau, tau_ref = float(arm.max_effort[1]), float(ref.max_effort[1])
    k_m = (tau / tau_ref) / k_l if math.isfinite(tau) else k_l**3
    origins = arm.link_frames(np.zeros(6))[:, :3, 3]
    ref_origins = ref.link_frames(np.zeros(6))[:, :3, 3]
    how = f"{ESTIMATE_REFERENCE} scaled: k_L = {k_l:.4f}, k_m = {k_m:.4f}"
    return [
        LinkEstimate(
            r.mass * k_m, origins[i] + (r.com - ref_origins[i]) * k_l, r.tensor * k_m * k_l**2, how
        )
        for i, r in enumerate(ref_links)
    ]


def _num(v: float) -> str:
    return repr(round(float(v), 10) + 0.0)


def _row(values: Sequence[float] | FloatArray) -> str:
    return "[" + ", ".join(_num(v) for v in values) + "]"


def plant_file_text(arm: Arm) -> str:
    """The plant model file (TOML, the format of ``kr6r900sixx_dynamics.toml``) of a KUKA
    six-axis ``arm``; raises ``ValueError`` for an arm without the closed-form layout."""
    from pyopenshowvar.kinematics import matrix_to_frame

    model = arm.kuka
    if model is None or arm.dof != 6:
        raise ValueError(f"{arm.name}: not a KUKA six-axis arm (no closed-form model)")
    speed = np.asarray(arm.max_speed, dtype=np.float64)
    effort = np.asarray(arm.max_effort, dtype=np.float64)
    if not (np.all(np.isfinite(speed)) and np.all(np.isfinite(effort))):
        raise ValueError(f"{arm.name}: the plant needs every axis' max_speed and max_effort")
    links = estimate_links(arm)
    frames = np.zeros((6, 4, 4))
    acc = np.eye(4)
    for j in range(6):
        frames[j] = acc
        acc = acc @ dh_matrix(model.a[j], model.alpha[j], model.d[j], model.offset[j])
    src = arm.source
    lines = [
        f"# The physical {arm.name} the emulator simulates: the plant's OWN model, written by",
        "# kukavarproxy_emu.plant.estimate from the arm's description (see its docstring and",
        '# docs/arms.md, "The emulator as any arm"); edit it freely, nothing regenerates it.',
        f"# Description: {src.text or arm.key}",
        f"# ({src.url} at {src.commit}; {src.licence})" if src.url else "# (a local file)",
        "# Geometry, axis signs, speeds and max torques: the description. Masses, centres of",
        f"# mass, inertia: {links[0].how}. Motor inertia, gears, friction, servo: estimates.",
        "",
        f'name = "{arm.name} (simulated physical robot)"',
        f"flange = {_row(matrix_to_frame(model.flange))}",
        _SERVO_AND_REST,
        "# Per link: inertia is the full tensor about the centre of mass in base axes at the",
        "# all-zero pose, [ixx, ixy, ixz, iyy, iyz, izz] (kg·m²); origin the joint origin (mm).",
    ]
    for j in range(6):
        gear = MOTOR_RPM * 6.0 / speed[j]
        rotor = ROTOR_PER_NM[0 if j < 3 else 1] * effort[j] / gear
        origin = frames[j, :3, 3]
        t = links[j].tensor
        viscous = VISCOUS_SHARE * effort[j] / math.radians(speed[j])
        lines += [
            "",
            f"[[link]]  # A{j + 1}",
            f"dh = {_row([model.a[j], model.alpha[j], model.d[j], model.offset[j]])}",
            f"sign = {int(model.sign[j])}",
            f"origin = {_row(origin)}",
            f"mass = {_num(links[j].mass)}",
            f"com = {_row(links[j].com - origin)}",
            f"inertia = {_row([t[0, 0], t[0, 1], t[0, 2], t[1, 1], t[1, 2], t[2, 2]])}",
            f"rotor = {_num(rotor)}",
            f"gear = {_num(gear)}",
            f"coulomb = {_num(COULOMB_SHARE * effort[j])}",
            f"static = {_num(STATIC_RATIO * COULOMB_SHARE * effort[j])}",
            f"viscous = {_num(viscous)}",
            f"max_torque = {_num(effort[j])}",
        ]
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m kukavarproxy_emu.plant.estimate NAME|FILE``: print the plant model file."""
    from pyopenshowvar.arms import load_arm

    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 1:
        sys.stderr.write("usage: python -m kukavarproxy_emu.plant.estimate NAME|FILE\n")
        return 2
    sys.stdout.write(plant_file_text(load_arm(args[0])))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
