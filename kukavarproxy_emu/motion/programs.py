"""The interface of a robot program the simulated controller runs: :class:`Program`, :class:`Idle`.

The programs themselves are KRL files run by the KRL interpreter
(:mod:`kukavarproxy_emu.krl.executor`), which implements this interface; which one runs is
chosen by :mod:`kukavarproxy_emu.program_factory`, above both. A program's
:meth:`Program.step` runs once per IPO cycle, before the kernel advances; it only plans
motions and reads/writes variables, and a :class:`~.kernel.MotionRefused` raised there stops
it (the robot task reports it).
"""

from __future__ import annotations

from .kernel import MotionKernel

__all__ = ["Idle", "Program"]


class Program:
    """Base class: ``start`` once when selected, ``step`` every cycle while running."""

    #: What ``$PRO_NAME1[]`` shows.
    krl_name = ""

    def start(self, kernel: MotionKernel) -> None:
        """Called when the program is started or restarted after a stop."""

    def step(self, kernel: MotionKernel) -> None:
        """One interpolation cycle of the program (the advance run's work)."""


class Idle(Program):
    """``--program none``: no robot program selected (``$PRO_STATE1`` = ``#P_FREE``)."""
