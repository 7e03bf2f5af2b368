"""The universal architecture's solvers by name: ``kvp universal --solver NAME`` to a :class:`Solver`.

It stands above the solver interface (:mod:`.solver`) and the methods that implement it
(:mod:`.closed`, :mod:`.dls`, :mod:`.ga`, :mod:`.pso`), so the interface never imports them.
"""

from __future__ import annotations

from typing import Any

from ..arms.model import Arm
from .closed import ClosedFormSolver, closed_form_for
from .dls import DLSSolver
from .ga import GASolver
from .pso import PSOSolver
from .solver import Solver

__all__ = ["SOLVERS", "make_solver", "solver_names"]


def _registry() -> dict[str, type[Solver]]:
    return {s.name: s for s in (ClosedFormSolver, DLSSolver, GASolver, PSOSolver)}


#: The solvers by the names used at run time (``kvp universal --solver``).
SOLVERS = ("closed-form", "dls", "ga", "pso")


def solver_names(arm: Arm | None = None) -> list[str]:
    """The solver names; for an ``arm``, only those that apply (closed form where it has one)."""
    if arm is None:
        return list(SOLVERS)
    return [n for n in SOLVERS if n != "closed-form" or closed_form_for(arm) is not None]


def make_solver(name: str, arm: Arm, **options: Any) -> Solver:
    """A solver by name (``closed-form``, ``dls``, ``ga``, ``pso``) for ``arm``.

    Raises ``ValueError`` for an unknown name and :class:`NoClosedFormError` for
    ``closed-form`` on an arm without one.
    """
    registry = _registry()
    key = name.strip().lower().replace("_", "-")
    if key == "closed":
        key = "closed-form"
    if key not in registry:
        raise ValueError(f"unknown solver {name!r}: one of {', '.join(SOLVERS)}")
    return registry[key](arm, **options)
