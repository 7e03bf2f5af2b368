"""Kinematics of serial 6R arms for pyopenshowvar, the emulator and the apps.

One robot model (:class:`RobotModel`, the KR 6 R900 sixx built in as :data:`KR6R900SIXX`) and
the thesis' interchangeable solvers on top of it: forward kinematics (eq. 4.12) with KUKA
$TOOL/$BASE/ABC/S/T conventions, closed-form inverse kinematics (eq. 2.9), the geometric
Jacobian with damped-least-squares velocity IK (eq. 2.10), and statics (gravity, τ = Jᵀ F,
eq. 4.5). Degrees and millimetres at the API; every function is batched over leading axes.
See docs/kinematics.md.
"""

from __future__ import annotations

from .errors import UnreachableError
from .forward import (
    dh_transforms,
    fk_matrix,
    forward,
    link_frames,
    status_bits,
    status_turn,
    turn_bits,
)
from .frames import (
    ABC_SINGULAR_COS,
    abc_from_matrix,
    as_transform,
    frame_to_matrix,
    inv_transform,
    matrix_from_abc,
    matrix_to_frame,
    pose_to_matrix,
    rotation_angle_deg,
)
from .inverse import inverse, inverse_all
from .jacobian import LENGTH_SCALE, dls_velocity_ik, jacobian, manipulability, scaled_jacobian
from .model import KR6R900SIXX, RobotModel
from .single import SinglePoseFK
from .statics import GRAVITY, Load, gravity_torques, torques_to_wrench, wrench_to_torques

__all__ = [
    "ABC_SINGULAR_COS",
    "GRAVITY",
    "KR6R900SIXX",
    "LENGTH_SCALE",
    "Load",
    "RobotModel",
    "SinglePoseFK",
    "UnreachableError",
    "abc_from_matrix",
    "as_transform",
    "dh_transforms",
    "dls_velocity_ik",
    "fk_matrix",
    "forward",
    "frame_to_matrix",
    "gravity_torques",
    "inv_transform",
    "inverse",
    "inverse_all",
    "jacobian",
    "link_frames",
    "manipulability",
    "matrix_from_abc",
    "matrix_to_frame",
    "pose_to_matrix",
    "rotation_angle_deg",
    "scaled_jacobian",
    "status_bits",
    "status_turn",
    "torques_to_wrench",
    "turn_bits",
    "wrench_to_torques",
]
