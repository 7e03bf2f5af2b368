"""The simulated KR 6 R900 sixx's motion inside the emulator: clock, motion kernel, program interface.

* :class:`IpoClock` — one tick per interpolation cycle (12 ms) against absolute deadlines,
  real time or ``speed`` × faster; records tick jitter.
* :class:`MotionKernel` — joint state and planned motions (PTP, LIN, ``_REL``, C_PTP/C_DIS
  approximation); writes $AXIS_ACT, $POS_ACT, $TORQUE_AXIS_ACT, ... once per cycle.
* :mod:`.programs` — the program interface; the thesis programs (``follow``, ``actuator``,
  ``ext_move_axis``, ``joint_path``, ``cart_path``) are KRL files run by :mod:`..krl`.

:class:`kukavarproxy_emu.robot_task.Robot` ties them together (``Emulator.robot``); it stands
above this package and the KRL interpreter, which this package never imports.

See docs/emulator-robot.md.
"""

from __future__ import annotations

from .clock import IpoClock, JitterStats
from .kernel import MotionKernel, MotionRefused
from .profiles import Trapezoid, ptp_profile
from .programs import Idle, Program

__all__ = [
    "Idle",
    "IpoClock",
    "JitterStats",
    "MotionKernel",
    "MotionRefused",
    "Program",
    "Trapezoid",
    "ptp_profile",
]
