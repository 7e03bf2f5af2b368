"""Which arm a view draws: the one the user named (``--robot``), else the one the robot names.

The web pad, the monitor and the gateway ask the connected controller for ``$MODEL_NAME[]``
and look the arm type up in the catalogue (:func:`pyopenshowvar.arms.arm_for_model_name`), so
a KR 16 is drawn, jogged and limited as a KR 16. A controller whose arm is not in the catalogue
(or does not answer) is drawn as the KR 6 R900 sixx, and the view says so; ``--robot NAME|FILE``
overrides the lookup (an arm the catalogue does not know, or a controller that hides it).
"""

from __future__ import annotations

from dataclasses import dataclass

from pyopenshowvar.arms import arm_for_model_name, load_arm
from pyopenshowvar.kinematics import KR6R900SIXX, RobotModel

__all__ = ["ArmChoice", "choose_arm", "given_arm"]


@dataclass(frozen=True)
class ArmChoice:
    """The closed-form model a view uses and why (``source``: shown to the user)."""

    model: RobotModel
    #: Catalogue name or file ("" for the fallback).
    key: str
    source: str

    @property
    def reach(self) -> float:
        """mm from A2 to the wrist centre: the scale a view draws the arm at."""
        return float(self.model.reach)


#: The arm drawn before (or without) an answer to $MODEL_NAME[].
DEFAULT_CHOICE = ArmChoice(KR6R900SIXX, "kr6_r900_sixx", "default")


def given_arm(spec: str) -> ArmChoice:
    """The arm of a ``--robot NAME|FILE``; ``ValueError`` if it is no KUKA six-axis arm."""
    arm = load_arm(spec)
    if arm.kuka is None:
        raise ValueError(f"--robot {spec}: {arm.name} is not a KUKA six-axis arm")
    return ArmChoice(arm.kuka, arm.key or spec, "--robot")


def choose_arm(model_name: str, given: ArmChoice | None = None) -> ArmChoice:
    """``given`` if the user named an arm, else the catalogue arm ``model_name`` names, else
    the KR 6 (``source`` says that the model name was not recognised)."""
    if given is not None:
        return given
    arm = arm_for_model_name(model_name)
    if arm is not None and arm.kuka is not None:
        return ArmChoice(arm.kuka, arm.key, f"$MODEL_NAME[] {model_name.strip()}")
    text = model_name.strip() or "(none)"
    return ArmChoice(KR6R900SIXX, "", f"$MODEL_NAME[] {text} not in the catalogue: KR 6 assumed")
