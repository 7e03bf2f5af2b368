"""Inverse kinematics for any serial arm: KUKA closed form where it applies, else numeric.

:func:`solve` takes targets as 4×4 poses, XYZABC ``(…, 6)`` or positions XYZ ``(…, 3)``
(position-only IK), each possibly batched, and returns an :class:`IKResult`.

* **Closed form** (``arm.kuka``, KUKA six-axis arms with a spherical wrist, full poses):
  every solution inside the limits is enumerated (:func:`~pyopenshowvar.kinematics.inverse`)
  and the one nearest the seed wins. A pose it does not solve has no solution.
* **Numeric** (every other case): Levenberg–Marquardt steps ``(JᵀJ + λI)⁻¹Jᵀe`` with
  Sugihara's damping λ = k·½‖e‖² + λ₀ ("solvability-unconcerned": large far from the target,
  so targets at or beyond the workspace boundary do not blow up; vanishing near it). Joint
  limits are kept by projection (a revolute joint first tries its value ± 360°) and an
  active set: joints a step would push through a limit stop there and the others are solved
  again without them. All candidates of all queries are stepped together as numpy batches.
  The seed is tried first; queries it does not solve within ``iterations`` steps get
  ``restarts`` random configurations at once, round after round, until solved or out of time.
  Among candidates that converge together the one nearest ``preferred`` (default: the seed)
  wins; for a redundant arm, a solution is then moved towards ``preferred`` in the null space
  of the task (kept only if it still meets the tolerance and got nearer).

Errors are measured like KDL / TRAC-IK: each component of the twist between target and
reached frame (position in metres, rotation vector in radians) within ``tol``. ``timeout``
is seconds per query (wall clock unless ``clock`` says otherwise): a batch of N queries stops
after N·timeout.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, Protocol

import numpy as np
import numpy.typing as npt

from ..kinematics.errors import UnreachableError
from ..kinematics.frames import FloatArray, as_transform, inv_transform, pose_to_matrix
from .spatial import rotation_log

if TYPE_CHECKING:
    from ..kinematics.model import RobotModel

__all__ = ["Chain", "IKResult", "solve"]

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


@dataclass(frozen=True)
class IKResult:
    """Solutions ``q`` (…, dof; the last candidate's values where not ``ok``), per-query
    ``ok``, remaining position error (mm, largest component) and rotation error (rad, largest
    component; 0 for position-only targets), and the method used."""

    q: FloatArray
    ok: npt.NDArray[np.bool_]
    pos_err: FloatArray
    rot_err: FloatArray
    method: str
    arm_name: str = ""

    @property
    def rate(self) -> float:
        """Fraction of queries solved."""
        return float(np.mean(self.ok)) if self.ok.size else 1.0

    def value(self, errors: Literal["raise", "nan"] = "raise") -> FloatArray:
        """``q``, raising :class:`UnreachableError` for the first unsolved query (or NaN rows)."""
        if not np.all(self.ok):
            if errors == "raise":
                i = int(np.flatnonzero(~self.ok.reshape(-1))[0])
                where = (
                    f"target {np.unravel_index(i, self.ok.shape)} of {self.ok.size}: "
                    if self.ok.ndim
                    else ""
                )
                raise UnreachableError(
                    f"{where}no {self.method} IK solution for {self.arm_name} inside the joint "
                    f"limits (left {self.pos_err.reshape(-1)[i]:.3g} mm, "
                    f"{self.rot_err.reshape(-1)[i]:.3g} rad from the target)"
                )
            return np.where(self.ok[..., None], self.q, np.nan)
        return self.q


_RNG: list[np.random.Generator] = []


def _default_rng() -> np.random.Generator:
    """One generator for the process, seeded with a constant, so restarts are reproducible."""
    if not _RNG:
        _RNG.append(np.random.default_rng(0x1C0DE))
    return _RNG[0]


def _targets(target: npt.ArrayLike) -> tuple[FloatArray, bool]:
    t = np.asarray(target, dtype=np.float64)
    if t.shape[-2:] == (4, 4):
        return t, False
    if t.shape[-1:] == (6,):
        return pose_to_matrix(t), False
    if t.shape[-1:] == (3,):
        m = np.broadcast_to(np.eye(4), (*t.shape[:-1], 4, 4)).copy()
        m[..., :3, 3] = t
        return m, True
    raise ValueError(f"a target is a 4x4 pose, X Y Z A B C or X Y Z; got shape {t.shape}")


def solve(
    arm: Chain,
    target: npt.ArrayLike,
    seed: npt.ArrayLike | None = None,
    *,
    preferred: npt.ArrayLike | None = None,
    tool: npt.ArrayLike | None = None,
    method: Literal["auto", "closed", "numeric"] = "auto",
    tol: float = 1e-5,
    timeout: float = 0.05,
    iterations: int = 20,
    restarts: int = 8,
    rng: np.random.Generator | None = None,
    clock: Callable[[], float] = time.perf_counter,
) -> IKResult:
    """Solve IK for one target or a batch (see the module docstring).

    ``clock`` is the time source of the timeout: wall-clock time by default;
    ``time.process_time`` counts only this process's CPU time (bench/ik.py on a shared machine).
    """
    if not (timeout > 0.0 and math.isfinite(timeout)):
        raise ValueError(f"timeout must be > 0 s, got {timeout}")
    # numpy.random loads on first use (0.1 s on a busy machine): before the clock starts
    gen = rng or _default_rng()
    deadline_start = clock()
    mats, pos_only = _targets(target)
    lead = mats.shape[:-2]
    flat = mats.reshape(-1, 4, 4)
    n_q = flat.shape[0]
    seeds = np.broadcast_to(
        np.asarray(arm.home if seed is None else seed, dtype=np.float64), (*lead, arm.dof)
    ).reshape(n_q, arm.dof)
    pref = None
    if preferred is not None:
        pref = np.broadcast_to(np.asarray(preferred, dtype=np.float64), (*lead, arm.dof))
        pref = pref.reshape(n_q, arm.dof)
    tool_m = as_transform(tool)
    use_closed = method == "closed" or (method == "auto" and arm.kuka is not None and not pos_only)
    if use_closed:
        if arm.kuka is None or pos_only:
            raise ValueError(
                f"{arm.name}: the closed form needs a KUKA six-axis arm and a full pose"
            )
        q, ok = _closed(arm, flat, seeds if pref is None else pref, tool_m)
        name = "closed-form"
    else:
        eff = arm.flange if tool_m is None else arm.flange @ tool_m
        deadline = deadline_start + timeout * max(n_q, 1)
        q, ok = _numeric(arm, flat, pos_only, seeds, pref, eff, tol, deadline, clock,
                         iterations, restarts, gen)  # fmt: skip
        name = "numeric"
    reached = arm.fk(np.nan_to_num(q), tool_m)
    pe = np.max(np.abs(reached[:, :3, 3] - flat[:, :3, 3]), axis=-1)
    re = np.zeros(n_q)
    if not pos_only:
        re = np.max(
            np.abs(rotation_log(flat[:, :3, :3] @ np.swapaxes(reached[:, :3, :3], 1, 2))), axis=-1
        )
    ok &= (pe <= tol * 1000.0) & (re <= tol)  # the true rotation log, for both methods
    return IKResult(
        q.reshape(*lead, arm.dof),
        ok.reshape(lead),
        pe.reshape(lead),
        re.reshape(lead),
        name,
        arm.name,
    )


def _closed(
    arm: Chain, flat: FloatArray, near: FloatArray, tool_m: FloatArray | None
) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    from ..kinematics.inverse import inverse

    assert arm.kuka is not None
    poses = flat if tool_m is None else flat @ inv_transform(tool_m)
    q = inverse(arm.kuka, poses, current=near, errors="nan")
    ok = ~np.isnan(q[:, 0])
    return np.where(ok[:, None], q, near), ok


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


def _numeric(
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
