"""The numeric inverse kinematics of :func:`~.ik.solve`: batched, damped least squares.

Levenberg–Marquardt steps ``(JᵀJ + λI)⁻¹Jᵀe`` with Sugihara's damping, joint limits kept by
projection (± 360° first for a revolute joint) and an active set, all candidates of all
queries stepped together as numpy batches, random restarts round after round, and a redundant
arm's solution moved towards the preferred configuration in the task's null space. The
method is described in :mod:`.ik`'s docstring; :class:`Chain` is what it needs of an arm.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

import numpy as np
import numpy.typing as npt

from ..kinematics.frames import FloatArray

if TYPE_CHECKING:
    from ..kinematics.model import RobotModel

__all__ = ["Chain", "numeric"]

#: The damping λ = k·½‖e‖² + λ₀ (e in metres and radians): Sugihara's form with k = 0.1,
#: which halved the steps to convergence on the catalogue arms compared with k = 1.
LAMBDA_K = 0.1
LAMBDA0 = 1e-8
_YZX, _ZXY = [1, 2, 0], [2, 0, 1]
#: Candidates kept alive in all while only a few queries are left (numpy batches are cheap).
POOL = 128
#: Redundancy resolution towards ``preferred``: null-space steps and gain per step (0..1).
NULL_STEPS = 30
NULL_GAIN = 0.2


class Chain(Protocol):
    """What the solver needs of an arm (a :class:`~pyopenshowvar.arms.Arm` is one): its
    limits and home, its flange, the closed-form model where one applies, and the batched
    link frames and joint axes the numeric steps are built from."""

    @property
    def name(self) -> str: ...
    @property
    def dof(self) -> int: ...
    @property
    def home(self) -> FloatArray | None: ...
    @property
    def flange(self) -> FloatArray: ...
    @property
    def kuka(self) -> RobotModel | None: ...
    @property
    def revolute(self) -> npt.NDArray[np.bool_]: ...
    @property
    def lower(self) -> FloatArray: ...
    @property
    def upper(self) -> FloatArray: ...
    @property
    def _all_revolute(self) -> bool: ...
    def fk(self, q: npt.ArrayLike, tool: npt.ArrayLike | None = None) -> FloatArray: ...
    def _chain(self, a: FloatArray, b: FloatArray) -> FloatArray: ...
    def _world_axes(self, frames: FloatArray) -> FloatArray: ...


def _wrap_clip(
    q: FloatArray, lo: FloatArray, hi: FloatArray, rev: npt.NDArray[np.bool_]
) -> FloatArray:
    """Into the limits: revolute values outside try ± 2π first, then everything is clipped."""
    out = (q < lo) | (q > hi)
    if not np.any(out):
        return q
    two_pi = 2.0 * math.pi
    q = np.where(rev & (q > hi) & (q - two_pi >= lo), q - two_pi, q)
    q = np.where(rev & (q < lo) & (q + two_pi <= hi), q + two_pi, q)
    return np.clip(q, lo, hi)


def _bounded(
    q: FloatArray,
    dq: FloatArray,
    jt: FloatArray,
    e: FloatArray,
    lam: FloatArray,
    lo: FloatArray,
    hi: FloatArray,
    rev: npt.NDArray[np.bool_],
) -> FloatArray:
    """Active-set correction of steps that run into a limit (no ± 360° way round).

    Clipping alone leaves the other joints' step computed as if the blocked joint had moved,
    and the solver stalls on solutions that lie on a limit (a pose taken with axes at their
    stops). Here the blocked joints go to their limit and the rest is solved again without them.
    """
    new = q + dq
    two_pi = 2.0 * math.pi
    blocked = ((new < lo) & ~(rev & (new + two_pi <= hi))) | (
        (new > hi) & ~(rev & (new - two_pi >= lo))
    )
    rows = np.flatnonzero(np.any(blocked, axis=1))
    if not len(rows):
        return dq
    blk = blocked[rows]
    to_limit = np.where(new[rows] < lo, lo - q[rows], hi - q[rows])
    jt_f = jt[rows] * ~blk[..., None]  # blocked joints' rows of Jᵀ removed
    # the task left after moving the blocked joints to their limits
    rest = e[rows] - np.einsum("kni,kn->ki", jt[rows], np.where(blk, to_limit, 0.0))
    h = jt_f @ np.swapaxes(jt_f, 1, 2) + lam[rows, None, None] * np.eye(q.shape[1])
    free = np.linalg.solve(h, jt_f @ rest[..., None])[..., 0]
    out = dq.copy()
    out[rows] = np.where(blk, to_limit, free)
    return out


class _Batch:
    """The live candidates: values (internal units), owning query, age and seed flag."""

    def __init__(
        self, q: FloatArray, owner: npt.NDArray[np.intp], seed: npt.NDArray[np.bool_]
    ) -> None:
        self.q, self.owner, self.seed = q, owner, seed
        self.age = np.zeros(len(owner), dtype=np.int64)

    def keep(self, mask: npt.NDArray[np.bool_]) -> None:
        self.q, self.owner, self.seed, self.age = (
            self.q[mask],
            self.owner[mask],
            self.seed[mask],
            self.age[mask],
        )

    def add(self, q: FloatArray, owner: npt.NDArray[np.intp]) -> None:
        self.q = np.concatenate([self.q, q])
        self.owner = np.concatenate([self.owner, owner])
        self.seed = np.concatenate([self.seed, np.zeros(len(owner), dtype=bool)])
        self.age = np.concatenate([self.age, np.zeros(len(owner), dtype=np.int64)])


def numeric(
    arm: Chain,
    flat: FloatArray,
    pos_only: bool,
    seeds: FloatArray,
    pref: FloatArray | None,
    eff: FloatArray,
    tol: float,
    deadline: float,
    clock: Callable[[], float],
    iterations: int,
    restarts: int,
    rng: np.random.Generator,
) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    n_q, n = seeds.shape
    rev = arm.revolute
    # internal units: radians and metres, so position (m) and rotation (rad) errors mix
    scale = np.where(rev, math.degrees(1.0), 1000.0)
    lo, hi = arm.lower / scale, arm.upper / scale
    rows = 3 if pos_only else 6
    near = (seeds if pref is None else pref) / scale
    eye = np.eye(n)

    best = seeds / scale
    solved = np.zeros(n_q, dtype=bool)
    b = _Batch(_wrap_clip(seeds / scale, lo, hi, rev), np.arange(n_q), np.ones(n_q, dtype=bool))
    if n_q * restarts <= 64:
        # a few queries: random candidates from the start cost (almost) nothing extra
        extra = np.repeat(np.arange(n_q), restarts - 1)
        b.add(rng.uniform(lo, hi, size=(len(extra), n)), extra)
    while len(b.owner) and clock() < deadline:
        old = b.age >= iterations
        if np.any(old):
            # candidates that did not converge in time: their query gets fresh random ones
            # (the seed is replaced by `restarts` of them, a random one by one)
            best[b.owner[old]] = b.q[old]
            # few unsolved queries left: numpy's per-call cost dominates, so each gets more
            # candidates per round (a pool of POOL in all) instead of more rounds
            waiting = len(np.unique(b.owner))
            per = max(restarts, min(POOL // max(waiting, 1), POOL))
            again = np.concatenate(
                [
                    np.repeat(b.owner[old & b.seed], per),
                    np.repeat(b.owner[old & ~b.seed], max(1, per // restarts)),
                ]
            )
            b.keep(~old)
            b.add(rng.uniform(lo, hi, size=(len(again), n)), again)
        e, jt, trace = _task(arm, b.q, flat[b.owner], pos_only, eff)
        # the skew part of R_err is sinθ·axis, the rotation vector to 1e-10 relative at the
        # tolerance (solve() checks the true log at the end); the trace guard keeps θ ≈ π,
        # whose skew part is ≈ 0 too, from counting as converged
        ee = np.einsum("ki,ki->k", e, e)
        done = (ee <= tol * tol) & (trace > 1.0)  # ‖e‖ ≤ tol: every component is too
        if np.any(done):
            _settle(done, b.owner, b.q, best, solved, near)
            live = ~solved[b.owner]
            b.keep(live)
            e, jt, ee = e[live], jt[live], ee[live]
            if not len(b.owner):
                break
        lam = LAMBDA_K * 0.5 * ee + LAMBDA0
        h = jt @ np.swapaxes(jt, 1, 2) + lam[:, None, None] * eye
        dq = np.linalg.solve(h, jt @ e[..., None])[..., 0]
        dq = _bounded(b.q, dq, jt, e, lam, lo, hi, rev)
        b.q = _wrap_clip(b.q + dq, lo, hi, rev)
        b.age += 1
    alive = b.owner[~solved[b.owner]]
    best[alive] = b.q[~solved[b.owner]]
    if pref is not None and n > rows and np.any(solved):
        idx = np.flatnonzero(solved)
        best[idx] = _towards(
            arm, best[idx], flat[idx], pref[idx] / scale, pos_only, eff, tol, lo, hi
        )
    return best * scale, solved


def _towards(
    arm: Chain,
    q: FloatArray,
    flat: FloatArray,
    pref: FloatArray,
    pos_only: bool,
    eff: FloatArray,
    tol: float,
    lo: FloatArray,
    hi: FloatArray,
) -> FloatArray:
    """Redundancy resolution: move solved configurations (internal units) towards ``pref``
    in the null space of the task, correcting the task error on the way (a projected
    gradient step plus a Gauss-Newton step per iteration). A query keeps its new values only
    if they still meet the tolerance and are nearer ``pref``."""
    rev = arm.revolute
    rows = 3 if pos_only else 6
    start = q.copy()
    for _ in range(NULL_STEPS):
        e, jt, _ = _task(arm, q, flat, pos_only, eff)
        j = np.swapaxes(jt, 1, 2)
        jjt = j @ jt + 1e-9 * np.eye(rows)
        pull = NULL_GAIN * (pref - q)
        # J⁺·e (task correction) + (I − J⁺J)·pull (null-space motion), J⁺ = Jᵀ(JJᵀ)⁻¹
        fix = np.linalg.solve(jjt, e[..., None] - j @ pull[..., None])
        q = _wrap_clip(q + pull + (jt @ fix)[..., 0], lo, hi, rev)
    e, _, trace = _task(arm, q, flat, pos_only, eff)
    good = (np.max(np.abs(e), axis=1) <= tol) & (trace > 1.0)
    good &= np.sum((q - pref) ** 2, axis=1) < np.sum((start - pref) ** 2, axis=1)
    return np.where(good[:, None], q, start)


def _task(
    arm: Chain, q: FloatArray, flat: FloatArray, pos_only: bool, eff: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """At configurations ``q`` (internal units) for targets ``flat``: the task error
    (position m, then the skew part of R_target·R_tcpᵀ), the transposed geometric Jacobian
    (one row per joint, per rad / per m) and the trace of R_err (3 for position-only)."""
    rev = arm.revolute
    if arm._all_revolute:
        frames = arm._chain(np.sin(q), np.cos(q))
    else:
        frames = arm._chain(np.where(rev, np.sin(q), q * 1000.0), np.where(rev, np.cos(q), 0.0))
    tcp = frames[:, -1] @ eff
    p = tcp[:, :3, 3] / 1000.0
    e = flat[:, :3, 3] / 1000.0 - p
    w = arm._world_axes(frames)
    rr = p[:, None, :] - frames[..., :3, 3] / 1000.0
    lin = w[..., _YZX] * rr[..., _ZXY] - w[..., _ZXY] * rr[..., _YZX]  # w × r, few numpy calls
    if not arm._all_revolute:
        lin = np.where(rev[:, None], lin, w)
    if pos_only:
        return e, lin, np.full(len(q), 3.0)
    rt = flat[:, :3, :3] @ np.swapaxes(tcp[:, :3, :3], 1, 2)
    er = rt[:, _ZXY, _YZX] - rt[:, _YZX, _ZXY]  # (r21 - r12, r02 - r20, r10 - r01)
    ang = w if arm._all_revolute else np.where(rev[:, None], w, 0.0)
    trace = np.trace(rt, axis1=1, axis2=2)
    return np.concatenate([e, 0.5 * er], axis=1), np.concatenate([lin, ang], axis=-1), trace


def _settle(
    done: npt.NDArray[np.bool_],
    owner: npt.NDArray[np.intp],
    cq: FloatArray,
    best: FloatArray,
    solved: npt.NDArray[np.bool_],
    near: FloatArray,
) -> None:
    """Record converged candidates; of several for one query keep the one nearest ``near``."""
    idx = np.flatnonzero(done)
    idx = idx[~solved[owner[idx]]]
    dist = np.sum((cq[idx] - near[owner[idx]]) ** 2, axis=1)
    order = np.lexsort((dist, owner[idx]))  # per query, nearest first
    idx = idx[order]
    first = np.unique(owner[idx], return_index=True)[1]
    pick = idx[first]
    best[owner[pick]] = cq[pick]
    solved[owner[pick]] = True
