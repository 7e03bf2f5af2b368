"""Which robot program and SPS the simulated controller runs: ``--program`` / ``--sps`` to objects.

The thesis programs are KRL files shipped in ``kukavarproxy_emu/programs/`` (``follow.src``,
``actuator.src``, ``ext_move_axis.src``, ``joint_path.src``, ``cart_path.src`` and the SPS
``sps.sub``), run by the KRL interpreter (:mod:`kukavarproxy_emu.krl.executor`).
``--program NAME`` picks a shipped file, ``--program PATH.src`` a user's own. This module
stands above both the motion kernel's program interface (:mod:`.motion.programs`) and the
interpreter that implements it, so the motion package never imports the interpreter.
"""

from __future__ import annotations

from pathlib import Path

from .krl.executor import KrlProgram, KrlSubmit, load_module
from .motion.programs import Idle, Program
from .store import VariableStore

__all__ = ["PROGRAMS", "make_program", "make_submit"]

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
    if isinstance(program, str) and program not in PROGRAMS and "." not in Path(program).name:
        known = ", ".join(PROGRAMS)
        raise ValueError(f"unknown program {program!r} (known: {known}, or a .src file)")
    return KrlProgram(load_module(program), store)


def make_submit(sps: str | Path | None, store: VariableStore, *, ipo: float) -> KrlSubmit | None:
    """The submit interpreter for ``--sps`` (a shipped name or a ``.sub`` path), started;
    None for ``none`` / None (no SPS)."""
    if sps is None or sps == "none":
        return None
    submit = KrlSubmit(load_module(sps), store, ipo=ipo)
    submit.start()
    return submit
