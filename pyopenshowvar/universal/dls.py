"""Damped least squares on the Jacobian: the classical solver beside the thesis' optimisers.

The thesis benchmarks its GA and PSO against "the classical Jacobian method" (§5.2.2); this is
that method for any arm, on the tip position (3 rows of the geometric Jacobian):

* **velocity** (eq. 2.10): ``θ̇ = Jᵀ(JJᵀ + λ²I)⁻¹·ẋ_ds``, with λ from the smallest singular
  value (Chiaverini's rule: no damping away from singularities, up to :data:`LAMBDA_MAX`
  times the workspace scale at one), then the speed and position limits;
* **position** (eq. 2.9): the arms package's batched Levenberg-Marquardt IK
  (:func:`pyopenshowvar.arms.solve`, position-only, the DLS step with Sugihara's damping,
  joint limits, random restarts) seeded with θ_a, so a near target converges from the
  current configuration and, of several solutions, the one nearest θ_a wins. It gets
  :data:`IK_SHARE` of the budget; if it finds no solution (the target is out of reach), the
  rest goes to a local Levenberg-Marquardt search from θ_a for the closest point (the tip
  stops at the boundary, no jump to a random configuration).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from ..arms.ik import solve as ik_solve
from ..arms.model import Arm
from ..kinematics.frames import FloatArray
from .solver import SolveInfo, Solver

__all__ = ["LAMBDA_MAX", "DLSSolver"]

#: Largest damping at a singularity, as a fraction of the workspace scale (mm/rad).
LAMBDA_MAX = 0.05
#: Largest joint step of one position iteration (deg; mm for prismatic joints: scaled).
MAX_STEP = 20.0
#: Steps of the closest-point search.
LOCAL_STEPS = 30
#: Share of the budget for the batched IK with restarts; the rest finds the closest point.
IK_SHARE = 0.7


class DLSSolver(Solver):
    """Damped least squares (see the module docstring)."""

    name = "dls"

    def __init__(
        self,
        arm: Arm,
        *,
        tol_mm: float | None = None,
        tool: npt.ArrayLike | None = None,
        **options: Any,
    ) -> None:
        super().__init__(arm, tool=tool, **options)
        self.tool = tool
        #: Position tolerance: 1e-6 of the workspace scale (0.002 mm on a KR 6, 0.02 mm on
        #: the 21 m crane box) unless given.
        self.tol = tol_mm if tol_mm is not None else 1e-6 * self.workspace.scale
        self.eps = LAMBDA_MAX * self.workspace.scale
        self._to_api = np.where(arm.revolute, math.degrees(1.0), 1.0)
        self._max_step = np.where(arm.revolute, MAX_STEP, MAX_STEP / 100.0 * self.span)
        self._h = np.where(arm.revolute, 1e-5, 1e-5 * self.span)

    def _jacobian(self, q: FloatArray) -> FloatArray:
        """Tip position rows of the Jacobian, per API unit (mm per deg or per mm)."""
        return np.asarray(self.arm.jacobian(q, self.tool)[:3] / self._to_api)

    def _dls(self, j: FloatArray, e: FloatArray, extra: float = 0.0) -> FloatArray:
        sigma = np.linalg.svd(j, compute_uv=False)
        smin = float(sigma[-1]) if len(sigma) >= 3 else 0.0
        # Chiaverini: λ² = λ_max²·(1 − (σ_min/ε)²) inside the ε band, zero outside
        lam2 = (self.eps**2) * max(0.0, 1.0 - (smin / self.eps) ** 2) + extra
        jjt = j @ j.T + (lam2 + 1e-12) * np.eye(3)
        return np.asarray(j.T @ np.linalg.solve(jjt, e))

    def velocity(self, q_a: npt.ArrayLike, xdot_ds: npt.ArrayLike, dt: float) -> FloatArray:
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f"dt must be > 0 s, got {dt}")
        q = self._config(q_a)
        xdot = self._target(xdot_ds)
        start = self.clock()
        # joints in units of their range: a prismatic joint's mm and a revolute joint's rad
        # would otherwise differ by orders of magnitude and the damping would freeze the one
        # with the smaller column
        qdot = self._dls(self._jacobian(q) * self.span, xdot) * self.span
        out = self.limit_rate(q, qdot, dt)
        err = float(np.linalg.norm(self._jacobian(q) @ out - xdot))
        self.last = SolveInfo(err * dt, self.clock() - start, 1, err, True)
        return out

    def _jac_fd(self, q: FloatArray) -> FloatArray:
        """Tip Jacobian per API unit by forward differences: one batched FK call (cheaper
        than the full geometric Jacobian when only the position rows are needed)."""
        h = self._h
        p = self.fk(np.concatenate([q[None], q + np.diag(h)]))
        return np.asarray(((p[1:] - p[0]) / h[:, None]).T)

    def _local(
        self, x: FloatArray, q: FloatArray, deadline: float
    ) -> tuple[FloatArray, float, int]:
        """Levenberg-Marquardt from ``q``: (closest configuration found, its error mm, steps).

        Sugihara's damping λ = μ·(k·½‖e‖² + λ₀) on workspace-normalised errors (large far from
        the target, vanishing near it); a step that does not reduce the error is retried with
        μ × 4. Gives up after :data:`LOCAL_STEPS` steps or when progress stalls, so a target
        across the workspace leaves time for the restarts."""
        scale = self.workspace.scale
        e = x - self.fk(q)
        err = float(np.linalg.norm(e))
        mu, steps, stalled = 1.0, 0, 0
        while err > self.tol and steps < LOCAL_STEPS and self.clock() < deadline:
            steps += 1
            jn = self._jac_fd(q) * (self.span / scale)  # per joint range, normalised
            en = e / scale
            lam = mu * (0.05 * float(en @ en) + 1e-9)
            dq = jn.T @ np.linalg.solve(jn @ jn.T + lam * np.eye(3), en) * self.span
            ratio = float(np.max(np.abs(dq) / self._max_step))
            if ratio > 1.0:
                dq = dq / ratio
            trial = np.clip(q + dq, self.lower, self.upper)
            te = x - self.fk(trial)
            terr = float(np.linalg.norm(te))
            if terr < err:
                stalled = stalled + 1 if err - terr < 0.01 * err else 0
                q, e, err, mu = trial, te, terr, max(mu / 4.0, 1.0)
                if stalled >= 3:
                    break  # creeping along a limit or the boundary
            else:
                mu *= 4.0
                if mu > 1e6:
                    break  # a local minimum: the boundary or a limit
        return q, err, steps

    def _solve(
        self, x: FloatArray, q_a: FloatArray, deadline: float
    ) -> tuple[FloatArray, int, float, bool]:
        # the batched LM with restarts (θ_a first, so a near target converges from it and the
        # nearest solution wins); it gets most of the budget
        remaining = deadline - self.clock()
        # (no ``preferred``: its null-space polish runs a fixed number of steps past any
        # deadline; of candidates converging together the one nearest the seed wins anyway)
        res = ik_solve(
            self.arm, x, q_a, tool=self.tool, tol=self.tol * 1e-3,
            timeout=max(remaining * IK_SHARE, 1e-6), clock=self.clock, rng=self.rng,
        )  # fmt: skip
        if bool(res.ok):
            q = np.clip(np.asarray(res.q), self.lower, self.upper)
            return q, 1, float(np.linalg.norm(x - self.fk(q))), True
        # not solved: out of reach (or out of time); the closest point from θ_a stands
        q, err, steps = self._local(x, q_a, deadline)
        return q, steps, err, err <= self.tol
