"""The simulated KR 6 R900 sixx inside the emulator: clock, motion kernel, programs.

* :class:`IpoClock` — one tick per interpolation cycle (12 ms) against absolute deadlines,
  real time or ``speed`` × faster; records tick jitter.
* :class:`MotionKernel` — joint state and planned motions (PTP, LIN, ``_REL``, C_PTP/C_DIS
  approximation); writes $AXIS_ACT, $POS_ACT, $TORQUE_AXIS_ACT, ... once per cycle.
* :mod:`.programs` — the program interface; the thesis programs (``follow``, ``actuator``,
  ``ext_move_axis``, ``joint_path``, ``cart_path``) are KRL files run by :mod:`..krl`.
* :class:`Robot` — ties them together; ``Emulator.robot``.

See docs/emulator-robot.md.
"""

from __future__ import annotations

from .clock import IpoClock, JitterStats
from .kernel import MotionKernel, MotionRefused
from .profiles import Trapezoid, ptp_profile
from .programs import PROGRAMS, Program, make_program
from .robot import Robot

__all__ = [
    "PROGRAMS",
    "IpoClock",
    "JitterStats",
    "MotionKernel",
    "MotionRefused",
    "Program",
    "Robot",
    "Trapezoid",
    "make_program",
    "ptp_profile",
]
