"""Closed-form position solvers, where an arm has one: KUKA six-axis arms, 3R cranes, SCARAs.

:func:`closed_form_for` recognises an arm by measuring it in its all-zero pose (as
:func:`pyopenshowvar.arms.derive_robot_model` does for the KUKA family) and keeps a closed form
only if it reproduces the arm's own forward kinematics at random configurations:

* **kuka** — KUKA six-axis arms (``arm.kuka``): a 3-DOF position input moves the TCP and
  holds the flange orientation (what a translational jog does): the orientation of the first
  θ_a the solver sees after it is made or :meth:`~ClosedFormSolver.reset` — latched, since one
  re-read from a moving, lagging arm would drift (we watched the wrist run into its limit
  that way). The exact closed form of :mod:`pyopenshowvar.kinematics.inverse` gives every
  solution; the one nearest θ_a wins.
* **3r** — an articulated 3R arm whose first axis is vertical through the base origin and whose
  two other axes are parallel and horizontal, all in one plane (the thesis' knuckle-boom
  crane): slew from the target's azimuth (or the opposite one, reaching over the top), then
  the two-link triangle in the arm's plane (elbow up and down).
* **scara** — an R-R-P-R arm with all axes vertical and the tip on the last axis (the Cobra 600):
  the two-link triangle in the horizontal plane, the height from the prismatic joint; the
  last joint (the tool's rotation) does not move the tip and keeps θ_a's value.

Every solution is searched over the ±360° equivalents of each revolute joint inside its
limits, checked by forward kinematics, and the one nearest θ_a is returned, so the set is
exact: no solution inside the limits means the target is out of reach (the accuracy test uses
that as its exact reachability check for these arms). For a target out of reach the solver
moves the tip as far towards the target as the closed form allows, along the straight line
from the current tip (bisection), rather than not at all.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any

import numpy as np
import numpy.typing as npt

from ..arms.model import Arm
from ..kinematics.frames import FloatArray
from .pointfk import PointFK
from .solver import NoClosedFormError, Solver

__all__ = ["ClosedForm", "ClosedFormSolver", "closed_form_for"]

_Z = np.array([0.0, 0.0, 1.0])
#: Bisection steps for the out-of-reach fallback.
BISECT = 12


def _two_link(
    dx: FloatArray, dy: FloatArray, l1: float, l2: float
) -> tuple[FloatArray, FloatArray]:
    """Planar two-link IK, both elbows: (angle of link 1, relative angle γ of link 2), each
    ``(k, 2)``; NaN where the point is out of the links' reach."""
    d2 = dx**2 + dy**2
    c = (d2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
    c = np.where(np.abs(c) <= 1.0 + 1e-12, np.clip(c, -1.0, 1.0), np.nan)
    gamma = np.stack([np.arccos(c), -np.arccos(c)], axis=-1)
    base = np.arctan2(dy, dx)[:, None] - np.arctan2(l2 * np.sin(gamma), l1 + l2 * np.cos(gamma))
    return base, gamma


class ClosedForm:
    """One arm's closed form: :meth:`best` gives, per target, the solution nearest θ_a."""

    def __init__(self, arm: Arm, kind: str, params: dict[str, Any]) -> None:
        self.arm, self.kind, self.p = arm, kind, params
        self.fk = PointFK(arm)
        self._tol = 1e-6 * max(1.0, float(np.max(np.abs(arm.fk(arm.home_q)[:3, 3]))))

    def candidates(
        self, x: FloatArray, q_a: FloatArray, rot: FloatArray | None = None
    ) -> FloatArray:
        """Raw branch solutions ``(k, m, dof)`` for targets ``(k, 3)`` (NaN = none);
        ``rot`` is the flange orientation a KUKA arm holds (default: θ_a's)."""
        p, k, n = self.p, len(x), self.arm.dof
        if self.kind == "3r":
            az = np.arctan2(x[:, 1], x[:, 0])
            rad = np.hypot(x[:, 0], x[:, 1])
            out = []
            for flip, r in ((0.0, rad), (math.pi, -rad)):  # the azimuth or over the top
                q1 = p["s1"] * (az + flip - p["az0"])
                base, gamma = _two_link(r - p["rs"], x[:, 2] - p["hs"], p["l1"], p["l2"])
                q2 = base - p["phi0"]
                q3 = p["s3"] * (gamma - (p["psi0"] - p["phi0"]))
                out.append(np.stack([np.repeat(q1[:, None], 2, 1), q2, q3], axis=-1))
            return np.asarray(np.degrees(np.concatenate(out, axis=1)))
        if self.kind == "scara":
            base, gamma = _two_link(x[:, 0], x[:, 1], p["l1"], p["l2"])
            q1 = p["s1"] * (base - p["phi0"])
            q2 = p["s2"] * (gamma - (p["psi0"] - p["phi0"]))
            d3 = np.repeat((p["s3"] * (x[:, 2] - p["z0"]))[:, None], 2, 1)
            q4 = np.full((k, 2), q_a[3])
            return np.stack([np.degrees(q1), np.degrees(q2), d3, q4], axis=-1)
        # kuka: the full pose with θ_a's flange orientation
        from ..kinematics.inverse import inverse

        assert self.arm.kuka is not None
        pose = np.broadcast_to(self.arm.fk(q_a), (k, 4, 4)).copy()
        if rot is not None:
            pose[:, :3, :3] = rot
        pose[:, :3, 3] = x
        q = inverse(self.arm.kuka, pose, current=np.broadcast_to(q_a, (k, n)), errors="nan")
        return np.asarray(q[:, None, :])

    def best(
        self, x: npt.ArrayLike, q_a: npt.ArrayLike, rot: FloatArray | None = None
    ) -> FloatArray:
        """Per target ``(k, 3)``: the solution inside the limits nearest ``q_a`` (NaN row if
        there is none)."""
        xa = np.atleast_2d(np.asarray(x, dtype=np.float64))
        qa = np.asarray(q_a, dtype=np.float64)
        cand = self.candidates(xa, qa, rot)
        lo, hi, rev = self.arm.lower, self.arm.upper, self.arm.revolute
        # per joint, the ±360° equivalent inside the limits nearest θ_a
        shifts = np.array([0.0, -360.0, 360.0])
        options = cand[..., None] + np.where(rev[:, None], shifts, np.array([0.0, np.nan, np.nan]))
        inside = (options >= lo[:, None] - 1e-9) & (options <= hi[:, None] + 1e-9)
        dist = np.where(inside, np.abs(options - qa[:, None]), np.inf)
        pick = np.argmin(dist, axis=-1)
        q = np.take_along_axis(options, pick[..., None], axis=-1)[..., 0]
        q = np.where(np.isfinite(np.min(dist, axis=-1)), np.clip(q, lo, hi), np.nan)
        # exact solutions only: the forward kinematics must give the target back
        reached = self.fk(np.nan_to_num(q))
        ok = np.all(np.isfinite(q), axis=-1)
        ok &= np.linalg.norm(reached - xa[:, None, :], axis=-1) <= self._tol
        span = hi - lo
        score = np.where(ok, np.sum(((q - qa) / span) ** 2, axis=-1), np.inf)
        j = np.argmin(score, axis=1)
        out = q[np.arange(len(xa)), j]
        return np.where(np.isfinite(score[np.arange(len(xa)), j])[:, None], out, np.nan)


def _measure(arm: Arm) -> tuple[FloatArray, FloatArray, FloatArray]:
    """World axes, axis points and the tip at the all-zero pose."""
    frames = arm.link_frames(np.zeros(arm.dof))
    axes = np.einsum("kij,kj->ki", frames[:, :3, :3], np.stack([j.axis for j in arm.joints]))
    return axes, frames[:, :3, 3], arm.fk(np.zeros(arm.dof))[:3, 3]


def _derive(arm: Arm) -> ClosedForm | None:
    if arm.kuka is not None:
        return ClosedForm(arm, "kuka", {})
    axes, pts, tip = _measure(arm)
    scale = max(1.0, float(np.max(np.abs(pts))), float(np.max(np.abs(tip))))
    if arm.dof == 3 and all(arm.revolute):
        w1, w2, w3 = axes
        if abs(abs(w1 @ _Z) - 1.0) > 1e-9 or np.hypot(*pts[0][:2]) > 1e-9 * scale:
            return None
        if abs(w2 @ _Z) > 1e-9 or abs(abs(w2 @ w3) - 1.0) > 1e-9:
            return None
        e_r = np.cross(_Z, w2)  # +q about w2 turns e_r towards +z: a plain planar angle
        s, e = (pts[1] @ e_r, pts[1][2]), (pts[2] @ e_r, pts[2][2])
        t = (tip @ e_r, tip[2])
        params = {
            "s1": float(np.sign(w1 @ _Z)), "s3": float(np.sign(w2 @ w3)),
            "az0": math.atan2(e_r[1], e_r[0]), "rs": s[0], "hs": s[1],
            "l1": math.dist(s, e), "l2": math.dist(e, t),
            "phi0": math.atan2(e[1] - s[1], e[0] - s[0]),
            "psi0": math.atan2(t[1] - e[1], t[0] - e[0]),
        }  # fmt: skip
        return _verified(ClosedForm(arm, "3r", params))
    if arm.dof == 4 and arm.joint_types == ("revolute", "revolute", "prismatic", "revolute"):
        if np.any(np.abs(np.abs(axes @ _Z) - 1.0) > 1e-9) or np.hypot(*pts[0][:2]) > 1e-9 * scale:
            return None
        e_xy, t_xy = pts[1][:2], tip[:2]
        if np.hypot(*(tip[:2] - pts[3][:2])) > 1e-9 * scale:
            return None  # the tip is off the last axis: the tool's rotation would move it
        params = {
            "s1": float(np.sign(axes[0] @ _Z)), "s2": float(np.sign(axes[1] @ _Z)),
            "s3": float(np.sign(axes[2] @ _Z)), "z0": float(tip[2]),
            "l1": float(np.hypot(*e_xy)), "l2": float(np.hypot(*(t_xy - e_xy))),
            "phi0": math.atan2(e_xy[1], e_xy[0]),
            "psi0": math.atan2(t_xy[1] - e_xy[1], t_xy[0] - e_xy[0]),
        }  # fmt: skip
        return _verified(ClosedForm(arm, "scara", params))
    return None


def _verified(cf: ClosedForm, samples: int = 64) -> ClosedForm | None:
    """``cf`` if it finds, for random configurations, their own tip again (else None)."""
    arm = cf.arm
    rng = np.random.default_rng(0)
    q = rng.uniform(arm.lower, arm.upper, size=(samples, arm.dof))
    x = cf.fk(q)
    got = np.array([cf.best(x[i : i + 1], q[i])[0] for i in range(samples)])
    return cf if np.all(np.isfinite(got)) else None


@lru_cache(maxsize=32)
def closed_form_for(arm: Arm) -> ClosedForm | None:
    """The arm's closed form, or None when it has none this module knows (see the docstring)."""
    return _derive(arm)


class ClosedFormSolver(Solver):
    """Position (eq. 2.9) by the closed form; velocity by the base class (eqs. 3.5, 3.7)."""

    name = "closed-form"

    def __init__(self, arm: Arm, **options: Any) -> None:
        if options.get("tool") is not None:
            raise ValueError("the closed-form solver works on the flange (no tool)")
        cf = closed_form_for(arm)
        if cf is None:
            raise NoClosedFormError(
                f"{arm.name} has no closed form here (KUKA six-axis arms, 3R cranes and SCARAs "
                "do); use dls, ga or pso"
            )
        super().__init__(arm, **options)
        self.cf = cf
        #: The flange orientation a KUKA arm holds (latched at the first call).
        self.orientation: FloatArray | None = None

    def reset(self) -> None:
        self.orientation = None

    def _solve(
        self, x: FloatArray, q_a: FloatArray, deadline: float
    ) -> tuple[FloatArray, int, float, bool]:
        if self.cf.kind == "kuka" and self.orientation is None:
            self.orientation = np.array(self.arm.fk(q_a)[:3, :3])
        rot = self.orientation
        q = self.cf.best(x, q_a, rot)[0]
        if np.all(np.isfinite(q)):
            return q, 1, 0.0, True
        # out of reach: as far along the line from the current tip as the closed form goes
        start = self.fk(q_a)
        lo, hi, best = 0.0, 1.0, q_a
        for _ in range(BISECT):
            mid = (lo + hi) / 2.0
            qm = self.cf.best(start + mid * (x - start), q_a, rot)[0]
            if np.all(np.isfinite(qm)):
                lo, best = mid, qm
            else:
                hi = mid
        return best, BISECT, float(np.linalg.norm(self.fk(best) - x)), False
