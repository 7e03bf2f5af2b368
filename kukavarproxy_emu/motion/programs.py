"""Robot programs the simulated controller runs: the :class:`Program` interface and its makers.

The thesis programs are KRL files shipped in ``kukavarproxy_emu/programs/`` (``follow.src``,
``actuator.src``, ``ext_move_axis.src``, ``joint_path.src``, ``cart_path.src`` and the SPS
``sps.sub``), run by the KRL interpreter (:mod:`kukavarproxy_emu.krl.executor`); the former
Python re-implementations are gone. ``--program NAME`` picks a shipped file, ``--program
PATH.src`` a user's own. A program's :meth:`Program.step` runs once per IPO cycle, before the
kernel advances; it only plans motions and reads/writes variables, and a
:class:`~.kernel.MotionRefused` raised there stops it (the robot task reports it).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from .kernel import MotionKernel

if TYPE_CHECKING:
    from ..store import VariableStore

__all__ = ["PROGRAMS", "Idle", "Program", "make_program"]


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


#: ``--program NAME`` → the shipped KRL file it runs ("" = no program).
PROGRAMS: dict[str, str] = {
    "follow": "follow.src",
    "actuator": "actuator.src",
    "ext_move_axis": "ext_move_axis.src",
    "joint_path": "joint_path.src",
    "cart_path": "cart_path.src",
    "none": "",
}


def make_program(program: str | Path, store: VariableStore) -> Program:
    """The program for ``--program``: a shipped name, ``none``, or a ``.src`` path.

    The KRL source is parsed (and its ``.dat`` declared into ``store``) here, so a syntax
    error (``KrlSyntaxError``, a ``ValueError``) or a missing file (``OSError``) is raised when
    the robot is built, i.e. at emulator start.
    """
    if program == "none":
        return Idle()
    from ..krl.executor import KrlProgram, load_module  # the interpreter imports this module

    if isinstance(program, str) and program not in PROGRAMS and "." not in Path(program).name:
        known = ", ".join(PROGRAMS)
        raise ValueError(f"unknown program {program!r} (known: {known}, or a .src file)")
    return KrlProgram(load_module(program), store)
