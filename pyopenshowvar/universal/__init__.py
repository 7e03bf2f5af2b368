"""The universal control architecture's solvers: one interface, any arm (thesis ch. 2.2, 3.2).

The thesis operates different cranes and robot arms with the same input device: a control
server maps the device's fixed DOFs to the arm's variable DOFs with an interchangeable solver.
Every solver implements the thesis' two mappings for any :class:`~pyopenshowvar.arms.Arm`,
within its joint limits (degrees, mm):

* ``solver.position(x_ds, q_a) -> θ_d`` (eq. 2.9),
* ``solver.velocity(q_a, ẋ_ds, dt) -> θ̇_d`` (eq. 2.10),

and is chosen by name at run time with :func:`make_solver`: ``closed-form`` (KUKA six-axis
arms, 3R cranes, SCARAs), ``dls`` (damped least squares), ``ga`` (the thesis' genetic
algorithm, §3.2.1) and ``pso`` (its particle swarm, §3.2.2). :func:`accuracy_test` is the
thesis' 512-target accuracy test (§3.2.1.1, Fig. 3.8). numpy only. See docs/universal.md.
"""

from __future__ import annotations

from .closed import ClosedFormSolver, closed_form_for
from .dls import DLSSolver
from .factory import SOLVERS, make_solver, solver_names
from .ga import GASolver
from .pointfk import PointFK
from .pso import PSOSolver
from .solver import BUDGET, NoClosedFormError, SolveInfo, Solver
from .workspace import Workspace, grid_targets, workspace_of

__all__ = [
    "BUDGET",
    "SOLVERS",
    "ClosedFormSolver",
    "DLSSolver",
    "GASolver",
    "NoClosedFormError",
    "PSOSolver",
    "PointFK",
    "SolveInfo",
    "Solver",
    "Workspace",
    "closed_form_for",
    "grid_targets",
    "make_solver",
    "solver_names",
    "workspace_of",
]
