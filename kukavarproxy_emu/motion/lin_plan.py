"""LIN planning of the motion kernel: a straight TCP line, planned in slices, LIN blends, and
the Cartesian targets of relative motions.

A LIN's joint path comes from inverse kinematics along the line (:mod:`.path`), its timing from
the path limits and, with machine data, the motors' torque rows (:mod:`.dynamics`); both take
long enough for a long line that the KRL advance run plans it slice by slice within its
per-cycle budget: :meth:`LinPlanner.plan_lin` returns a :class:`PlanJob` instead of working at
once. :class:`LinPlanner` is mixed into :class:`~.kernel.MotionKernel`, which owns the state,
the queue (``_enqueue``) and PTP planning.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Generator
from typing import TypeVar

import numpy as np

from pyopenshowvar.kinematics import fk_matrix, forward, inverse, matrix_to_frame, pose_to_matrix
from pyopenshowvar.krl import Struct

from .dynamics import ControllerDynamics
from .joint_path import LinGeometry, PathRefused, joint_path, leave_wrist_singularity
from .path import PathLimits
from .profiles import FloatArray, Profile
from .retime import blend_ratio, check_accelerations
from .segments import Kind, Segment, blend, rotation_log, rotvec_matrix
from .settings import MotionRefused, Settings, xyzabc

__all__ = ["LinPlanner", "PlanJob", "lin_pose", "next_result"]

T = TypeVar("T")
#: |A5| below this (deg) is on the wrist singularity, where a LIN first turns A4/A6 in place.
WRIST_SINGULAR = 1e-6
#: Tries to blend two LINs within the axis accelerations before they stop exactly instead.
BLEND_TRIES = 4


class PlanJob:
    """A motion being planned in slices: :meth:`step` until it returns True.

    Each :meth:`step` does at least one slice (an IK batch, a few hundred nodes of a pass) and
    stops at ``deadline`` (``time.perf_counter()``); the motion is queued by the last slice.
    A refused motion raises :class:`MotionRefused` from :meth:`step`.
    """

    def __init__(self, work: Generator[None, None, None]) -> None:
        self._work = work
        self.done = False
        self.slices = 0

    def step(self, deadline: float) -> bool:
        while not self.done:
            self.slices += 1
            try:
                next(self._work)
            except StopIteration:
                self.done = True
            if time.perf_counter() >= deadline:
                break
        return self.done

    def run(self) -> None:
        """Plan to the end at once (in-process callers and tests)."""
        self.step(math.inf)


def next_result(gen: Generator[None, None, T]) -> T:
    """Run a planning generator to its end at once and return its result."""
    while True:
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value  # type: ignore[no-any-return]


def lin_pose(base: FloatArray, parts: list[tuple[FloatArray, FloatArray, float]]) -> FloatArray:
    """The TCP pose of superposed LINs: ``base`` moved by each (displacement, rotation vector)
    at its fraction ``s`` (blended LINs add their displacements)."""
    pose = base.copy()
    for dp, rv, s in parts:
        pose[:3, 3] += dp * s
        pose[:3, :3] = rotvec_matrix(rv * s) @ pose[:3, :3]
    return pose


class LinPlanner(Settings):
    """The LIN-planning half of the motion kernel (state and queue live in the kernel)."""

    ipo: float
    dynamics: ControllerDynamics | None
    active: list[Segment]
    pending: deque[Segment]  # planned, not started (the kernel's queue)
    planned_q: FloatArray
    _frames: tuple[FloatArray, FloatArray]

    def ptp(self, target: object, *, approx: bool = False, label: str = "PTP") -> None:
        raise NotImplementedError  # provided by the kernel

    def _enqueue(self, seg: Segment) -> Generator[None, None, None]:
        raise NotImplementedError  # provided by the kernel

    def planned_pose(self) -> FloatArray:
        """The TCP pose (XYZABC in $BASE) at the end of the last planned motion."""
        tool, base = self._read_frames()
        return np.asarray(forward(self.model, self.planned_q, tool, base), dtype=np.float64)

    def rel_pose(self, increment: object, *, tool: bool = False) -> FloatArray:
        """Planned end pose moved by a Cartesian increment: X/Y/Z added in $BASE, and the
        rotation Rz(A)·Ry(B)·Rx(C) applied about the $BASE axes at the TCP; with ``tool``
        (``#TOOL``) the increment is a frame in the TCP's own axes instead."""
        inc = xyzabc(increment, "increment")
        start = pose_to_matrix(self.planned_pose())
        if tool:
            return np.asarray(matrix_to_frame(start @ pose_to_matrix(inc)), dtype=np.float64)
        rot = pose_to_matrix(np.array([0.0, 0.0, 0.0, *inc[3:]]))
        end = start.copy()
        end[:3, :3] = rot[:3, :3] @ start[:3, :3]
        end[:3, 3] += inc[:3]
        return np.asarray(matrix_to_frame(end), dtype=np.float64)

    def lin(self, pose: object, *, approx: bool = False, label: str = "LIN") -> None:
        """Plan ``LIN pose [C_DIS]``: a straight TCP line in $BASE at ``$VEL.CP``."""
        self.plan_lin(pose, approx=approx, label=label).run()

    def plan_lin(self, pose: object, *, approx: bool = False, label: str = "LIN") -> PlanJob:
        """``LIN pose`` as a :class:`PlanJob`: the target and $TOOL/$BASE/$VEL/$ACC/$APO are
        read now; the joint path and its timing are computed by the job's slices."""
        tool, base = frames = self._read_frames()
        start = fk_matrix(self.model, self.planned_q, tool, base)
        end = pose_to_matrix(xyzabc(pose, label))
        geo = LinGeometry(
            start, end[:3, 3] - start[:3, 3], rotation_log(end[:3, :3] @ start[:3, :3].T)
        )
        vel, acc = self.store.get("$VEL"), self.store.get("$ACC")
        assert isinstance(vel, Struct) and isinstance(acc, Struct)
        v = (float(vel["CP"]) * 1000.0, float(vel["ORI1"]))  # type: ignore[arg-type]
        a = (float(acc["CP"]) * 1000.0, float(acc["ORI1"]))  # type: ignore[arg-type]
        cdis = float(self._apo()["CDIS"])  # type: ignore[arg-type]
        frac = min(0.5, cdis / geo.length) if geo.length > 0 else 0.0
        return PlanJob(self._plan_lin(geo, frames, v, a, approx, frac, label))

    def plan_lin_rel(
        self, increment: object, *, approx: bool = False, tool: bool = False, label: str = "LIN_REL"
    ) -> PlanJob:
        return self.plan_lin(self.rel_pose(increment, tool=tool), approx=approx, label=label)

    def _plan_lin(
        self,
        geo: LinGeometry,
        frames: tuple[FloatArray, FloatArray],
        v: tuple[float, float],
        a: tuple[float, float],
        approx: bool,
        frac: float,
        label: str,
    ) -> Generator[None, None, None]:
        q0 = self.planned_q.copy()
        if not self.active and not self.pending and geo.length < 1e-9 and geo.angle < 1e-9:
            return
        try:
            config = None
            start = q0
            if abs(q0[4]) < WRIST_SINGULAR:
                start, config = leave_wrist_singularity(self.model, geo, q0, *frames)
            s, q = yield from joint_path(self.model, geo, start, *frames, config=config)
            lo, hi = self._soft_limits()
            outside = np.flatnonzero(np.any((q < lo[:6] - 1e-9) | (q > hi[:6] + 1e-9), axis=1))
            if len(outside):
                self.check_limits(q[outside[0]], f"{label} at {s[outside[0]]:.0%}")
            limits = PathLimits(
                self.model, s, q, geo, v, a, self.model.max_speed, self.model.max_accel
            )
            if self.dynamics is not None:
                yield  # the limits above were one slice; the motors' rows are more
                self.dynamics.use_load(self.store.get("$LOAD"))
                limits.constrain(*(yield from self.dynamics.path_rows(q, limits.qp, limits.qpp)))
                yield
            curve, bw = yield from limits.plan()
            lin_tool, lin_base = frames

            def solve(s_at: FloatArray, near: FloatArray) -> FloatArray:
                poses = geo.poses(s_at)
                return inverse(
                    self.model, poses, current=near, tool=lin_tool, base=lin_base, errors="nan"
                )

            curve, bw = yield from check_accelerations(limits, curve, bw, solve, self.ipo)
            profile = Profile(*curve)
        except PathRefused as exc:
            raise MotionRefused(f"{label}: {exc}") from None
        except ValueError as exc:  # a profile that stalls: too close to a singularity
            raise MotionRefused(f"{label}: {exc}") from None
        if not np.array_equal(q0, self.planned_q):
            raise MotionRefused(f"{label}: the motions before it changed while it was planned")
        if np.max(np.abs(start - q0)) > 1e-9:
            # starting on the wrist singularity: A4/A6 first turn in place (the TCP stays put)
            self.ptp(start, label=f"{label} (wrist)")
        rows = [(geo.dp, a[0]), (np.degrees(geo.rv), a[1])]
        seg = Segment(
            Kind.LIN, profile, limits, bw, geo.dp, q[-1].copy(), approx, frac, geo.rv, label, rows
        )
        self._frames = frames
        yield from self._enqueue(seg)

    def _blend_lin(
        self, cur: Segment, nxt: Segment, progress: Callable[[], float]
    ) -> Generator[None, None, None]:
        """Blend two LINs so that the axes keep their accelerations in the window, where
        they follow neither line (:func:`.retime.blend_ratio`): a window too fast is undone at
        once (no cycle ran since it was made) and made again slower; at worst no blend."""
        saved = (cur.profile, cur.blend_at, nxt.profile, nxt.head_end)
        end = fk_matrix(self.model, cur.end_q, *self._frames)
        base = end.copy()
        base[:3, 3] -= cur.delta
        base[:3, :3] = rotvec_matrix(cur.rotvec).T @ end[:3, :3]
        tool, frame = self._frames

        def solve(poses: FloatArray, near: FloatArray) -> FloatArray:
            return np.asarray(
                inverse(self.model, poses, current=near, tool=tool, base=frame, errors="nan")
            )

        slower = 1.0
        for _ in range(BLEND_TRIES):
            if not (yield from blend(cur, nxt, progress, slower)):
                return
            ratio = blend_ratio(cur, nxt, base, solve, self.ipo)
            if ratio <= 1.0 + 1e-9:
                return
            cur.profile, cur.blend_at, nxt.profile, nxt.head_end = saved
            slower *= 0.97 / ratio
