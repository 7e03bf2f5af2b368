"""Which KUKA arm the emulator is: ``--robot NAME|FILE`` resolved once at start-up.

A :class:`RobotSpec` holds the three separate things a KRC with its arm consists of:

* the **controller's** nominal model it plans with (the closed-form :class:`RobotModel` of the
  arm's description: geometry, software limits, speeds, accelerations, max torques, masses)
  and its machine data for the load adaptation;
* the controller's **identity and start-up state**: ``$MODEL_NAME[]``, ``$AXIS_ACT`` /
  ``$POS_ACT`` at the arm's home, ``$SOFTN_END`` / ``$SOFTP_END``, ``$TORQUE_AXIS_MAX``;
* the **physical robot** (the dynamic plant): its own model file, never the controller's
  numbers (``plant/<name>_dynamics.toml`` for the catalogue arms, written once from the
  description and kept; an arm file gets one generated at start-up, see
  :mod:`.plant.estimate`).

Only arms a KRC drives over KUKAVARPROXY are served: six-axis KUKA arms of the usual layout
(those with the closed form). The crane, the SCARA and the youBot are not KUKA KRC arms, and
the LBR iiwa runs on a KUKA Sunrise cabinet (Java), where no KUKAVARPROXY runs; all of them are
simulated by the universal architecture (``kvp universal --arm NAME``), and ``--robot`` refuses
them with one line saying so.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pyopenshowvar.arms import Arm
    from pyopenshowvar.kinematics import RobotModel

    from .motion.dynamics import MachineData
    from .plant.params import PlantParams

__all__ = ["DEFAULT_ROBOT", "RobotRefused", "RobotSpec", "resolve_robot"]

#: The arm the emulator is unless told otherwise.
DEFAULT_ROBOT = "kr6_r900_sixx"
_PLANT_DIR = Path(__file__).parent / "plant"
#: The planner's torque reserve of the KR 6's machine data (friction, servo, model error).
TORQUE_RESERVE = 0.15


class RobotRefused(ValueError):
    """``--robot`` names an arm the emulator cannot be (not a KRC six-axis arm, bad file)."""


@dataclass(frozen=True, eq=False)
class RobotSpec:
    """The arm of one emulator: see the module docstring."""

    #: Catalogue name, or the file's path.
    key: str
    arm: Arm
    #: The controller's nominal model.
    model: RobotModel
    #: ``$MODEL_NAME[]`` (without quotes).
    model_name: str
    #: The controller's machine data (None: the KR 6's own file, looked up by name).
    machine: MachineData | None
    #: The physical robot's model file (None: generated from the arm file, ``plant_text``).
    plant_file: Path | None
    plant_text: str = ""

    @property
    def is_default(self) -> bool:
        return self.key == DEFAULT_ROBOT

    def plant_params(self) -> PlantParams:
        """The physical robot's parameters, from its own model file."""
        from .plant.params import load_params, params_of

        if self.plant_file is not None:
            return load_params(self.plant_file)
        return params_of(tomllib.loads(self.plant_text), f"{self.key} (generated)")

    def sysvar_overrides(self) -> dict[str, str | tuple[str, ...]]:
        """Start-up values of the system variables that differ per arm ({} for the KR 6,
        whose values are the table's own)."""
        if self.is_default:
            return {}
        from pyopenshowvar.kinematics import forward, status_turn

        model = self.model
        home = np.asarray(model.home, dtype=np.float64)
        axes = ", ".join(f"A{i + 1} {float(v)!r}" for i, v in enumerate(home))
        ext = ", ".join(f"E{i} 0.0" for i in range(1, 7))
        x, y, z, a, b, c = (float(v) + 0.0 for v in forward(model, home))
        s, t = status_turn(model, home)
        pos = (
            f"{{E6POS: X {x!r}, Y {y!r}, Z {z!r}, A {a!r}, B {b!r}, C {c!r},"
            f" S {int(s)}, T {int(t)}, {ext}}}"
        )
        name = f'"{self.model_name}"'
        short = self.model_name.lstrip("#").split(" ")[0] or "KR"
        return {
            "$AXIS_ACT": f"{{E6AXIS: {axes}, {ext}}}",
            "$AXIS_ACT_MEAS": f"{{E6AXIS: {axes}, {ext}}}",
            "$POS_ACT": pos,
            "$POS_ACT_MES": pos,
            "$TORQUE_AXIS_ACT": "0.0",
            "$TORQUE_AXIS_MAX": _axes(model.max_torque, 0.0),
            "$SOFTN_END": _axes(model.lower, -5000.0),
            "$SOFTP_END": _axes(model.upper, 5000.0),
            "$MODEL_NAME": name,
            "$TRAFONAME": name,
            "$ROBNAME": f'"{short[:22]}-EMULATOR"',
        }


def _axes(values: object, fill: float) -> tuple[str, ...]:
    first = [float(v) for v in np.asarray(values, dtype=np.float64)]
    return tuple(repr(v) for v in [*first, *([fill] * (12 - len(first)))])


def _refuse(spec: str, why: str) -> RobotRefused:
    return RobotRefused(f"--robot {spec}: {why}")


@lru_cache(maxsize=16)
def resolve_robot(spec: str = "") -> RobotSpec:
    """The arm ``spec`` names (a catalogue name or an arm file; "" = the KR 6); raises
    :class:`RobotRefused` with one line for an arm the emulator cannot be."""
    from pyopenshowvar.arms import ArmFileError, UnknownArmError, catalogue, load_arm

    spec = spec.strip() or DEFAULT_ROBOT
    try:
        arm = load_arm(spec)
    except (UnknownArmError, ArmFileError, OSError, ValueError) as exc:
        raise _refuse(spec, str(exc)) from None
    key = arm.key if arm.key in catalogue() else spec
    if arm.dof == 7 and "iiwa" in (arm.key + arm.name).lower():
        raise _refuse(
            spec,
            f"{arm.name} runs on a KUKA Sunrise cabinet, not a KRC with KUKAVARPROXY; simulate"
            f" it with the universal architecture: kvp universal --arm {key}",
        )
    if arm.kuka is None or arm.dof != 6:
        raise _refuse(
            spec,
            f"{arm.name} is not a KUKA six-axis arm a KRC serves over KUKAVARPROXY ({arm.dof}"
            f" axes, no KUKA closed form); simulate it with the universal architecture:"
            f" kvp universal --arm {key}",
        )
    if key == DEFAULT_ROBOT:
        from pyopenshowvar.kinematics import KR6R900SIXX

        from .plant.params import DEFAULT_PARAMS_FILE

        return RobotSpec(key, arm, KR6R900SIXX, str(arm.model_name), None, DEFAULT_PARAMS_FILE)
    missing = [
        f"A{i + 1}"
        for i in range(6)
        if not all(math.isfinite(float(v[i])) for v in (arm.max_speed, arm.max_accel))
    ]
    if missing:
        raise _refuse(spec, f"the emulator needs max_speed and max_accel of {', '.join(missing)}")
    if not np.all(np.isfinite(arm.max_effort)):
        raise _refuse(spec, "the emulator needs every axis' max_effort (the drives' torque)")
    return _spec_of(key, arm)


def _spec_of(key: str, arm: Arm) -> RobotSpec:
    from .motion.dynamics import MachineData
    from .plant.estimate import MOTOR_RPM, ROTOR_PER_NM, estimate_links, plant_file_text

    assert arm.kuka is not None
    links = estimate_links(arm)  # the description's inertials, or the documented estimate
    # the controller's nominal masses: the same public numbers the plant starts from (as the
    # KR 6's two files); a real KRC's machine data would come with the arm type
    model = replace(
        arm.kuka,
        link_mass=np.array([link.mass for link in links]),
        link_com=np.array([link.com for link in links]),
        link_origin=np.zeros((6, 3)),
    )
    gear = MOTOR_RPM * 6.0 / np.asarray(arm.max_speed, dtype=np.float64)
    rotor = np.array([ROTOR_PER_NM[0 if j < 3 else 1] for j in range(6)]) * arm.max_effort / gear
    machine = MachineData(
        inertia=np.array([np.maximum(np.diag(link.tensor), 1e-9) for link in links]),
        motor_inertia=rotor * gear**2,
        torque_reserve=TORQUE_RESERVE,
    )
    own = _PLANT_DIR / f"{key}_dynamics.toml"
    if own.is_file():
        return RobotSpec(key, arm, model, _model_name(arm), machine, own)
    return RobotSpec(key, arm, model, _model_name(arm), machine, None, plant_file_text(arm))


def _model_name(arm: Arm) -> str:
    """``$MODEL_NAME[]``: the description's, else ``#`` and the name (CHAR[32], no quotes)."""
    text = arm.model_name or "#" + arm.name.upper().replace(" ", "")
    return text.replace('"', "'")[:32]
