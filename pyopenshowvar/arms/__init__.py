"""Arms as data: any serial arm from a D-H table, a URDF-like chain or a URDF file.

The thesis' architecture adds a manipulator "simply by defining its D-H table and its joint
limits"; this package makes that the toolkit's model of an arm. :func:`load_arm` takes a
catalogue name (``kvp arms list``) or a file and returns an :class:`Arm` with joint names,
types and limits, batched ``fk`` / ``jacobian`` / ``ik`` on numpy arrays, inertials where
known, and the exact closed-form IK for KUKA six-axis arms (:attr:`Arm.kuka`). Millimetres and
degrees at the API, as everywhere in the toolkit. See docs/arms.md.
"""

from __future__ import annotations

from .catalogue import arm_for_model_name, catalogue, load_arm
from .errors import ArmFileError, UnknownArmError
from .files import arm_from_dict, load_toml
from .ik import IKResult, solve
from .kuka import derive_robot_model, from_robot_model
from .model import Arm, Inertial, Joint, JointType, Source

__all__ = [
    "Arm",
    "ArmFileError",
    "IKResult",
    "Inertial",
    "Joint",
    "JointType",
    "Source",
    "UnknownArmError",
    "arm_for_model_name",
    "arm_from_dict",
    "catalogue",
    "derive_robot_model",
    "from_robot_model",
    "load_arm",
    "load_toml",
    "solve",
]
