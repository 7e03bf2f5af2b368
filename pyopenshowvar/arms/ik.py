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
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from ..kinematics.errors import UnreachableError
from ..kinematics.frames import FloatArray, as_transform, inv_transform, pose_to_matrix
from .ik_numeric import Chain, numeric
from .spatial import rotation_log

if TYPE_CHECKING:
    pass

__all__ = ["Chain", "IKResult", "solve"]


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
        q, ok = numeric(arm, flat, pos_only, seeds, pref, eff, tol, deadline, clock,
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
