"""The motion kernel: joint state, planned motions, one interpolation cycle per :meth:`tick`.

Programs (the thesis followers, path runners, later the KRL interpreter) call the planning
methods (:meth:`MotionKernel.ptp`, :meth:`~MotionKernel.lin`, their ``_rel`` forms); the kernel
neither knows nor cares how the program is written. A LIN can also be planned in slices
(:meth:`~MotionKernel.plan_lin` returns a :class:`PlanJob`), which the KRL advance run steps
within its per-cycle time budget, so a long line never holds the event loop. Each :meth:`~MotionKernel.tick` advances
the running segments by one IPO cycle and writes every motion variable of the store in one
synchronous step, so a KVP read served by the same asyncio loop always sees one cycle.
LIN planning lives in :mod:`.lin_plan`, the settings read from the store in :mod:`.settings`,
the published variables in :mod:`.publish`: three halves mixed into one kernel that owns the state.

Model (see docs/emulator-robot.md):

* planning at 100 % override; ``$OV_PRO`` scales the profile clock (speeds × ov, accelerations
  × ov²), so an override change acts on the running motion too, slewed as fast as the axis
  accelerations allow (:meth:`MotionKernel._slew`);
* a LIN's path velocity is limited so that no axis exceeds its speed or acceleration limit
  (:mod:`.path`); a line through a singularity is refused;
* approximation = superposition: the next segment starts at the ``$APO`` distance of the
  current one and the displacements add, re-timed by :func:`.segments.blend` within limits;
* the torque is gravity (link masses + ``$LOAD``) + a diagonal inertia × commanded
  acceleration + Jᵀ·``EMU_WRENCH``, all in the kinematics package's drive-torque convention.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Generator, Sequence

import numpy as np

from pyopenshowvar.kinematics import (
    KR6R900SIXX,
    RobotModel,
    UnreachableError,
    fk_matrix,
    inverse,
)

from ..store import VariableStore
from .dynamics import ControllerDynamics, MachineData
from .lin_plan import LinPlanner, PlanJob, lin_pose, next_result
from .profiles import FloatArray, Profile
from .publish import Publisher
from .segments import ConstLimits, Kind, Segment, blend
from .settings import MotionRefused, axes_of, xyzabc

__all__ = ["DEFAULT_INERTIA", "MotionKernel", "MotionRefused", "PlanJob"]

log = logging.getLogger(__name__)

#: Diagonal inertia seen by each drive, kg·m² (rough, pose independent: the arm's links as
#: point masses at mid reach for A1..A3, the wrist for A4..A6). Only the inertial *term* of
#: $TORQUE_AXIS_ACT uses it, to show acceleration peaks; it is no dynamic model.
DEFAULT_INERTIA = (2.0, 2.5, 0.7, 0.04, 0.04, 0.01)
#: Bisection steps for the override rate of one cycle (resolution 2⁻¹² of the change).
OV_BISECT = 12
#: KRC machine datum $APO_DIS_PTP (deg): 100 % C_PTP would start blending this far out.
APO_DIS_PTP = 90.0
TraceSample = tuple[float, FloatArray, FloatArray]


class MotionKernel(LinPlanner, Publisher):
    """Owns the joint state and the queue of planned motions of one simulated robot."""

    def __init__(
        self,
        store: VariableStore,
        model: RobotModel = KR6R900SIXX,
        *,
        ipo: float = 0.012,
        noise: float = 0.0,
        seed: int | None = None,
        inertia: Sequence[float] | None = None,
        machine: MachineData | None = None,
    ) -> None:
        self.store = store
        self.model = model
        self.ipo = ipo
        #: Standard deviation (deg) of the measurement noise on $AXIS_ACT_MEAS (0 = none).
        self.noise = noise
        self._rng = np.random.default_rng(seed)
        #: The controller's dynamic model (accelerations adapted to $LOAD); None without
        #: machine data for ``model``.
        self.dynamics = ControllerDynamics.for_model(model, machine)
        dyn = self.dynamics
        if inertia is not None:
            self.inertia = np.asarray(inertia, dtype=np.float64)
        elif machine is not None and dyn is not None:  # the ideal plant's inertia term
            self.inertia = dyn.diag_inertia(model.home)
        else:
            self.inertia = np.asarray(DEFAULT_INERTIA, dtype=np.float64)
        q0 = axes_of(store.get("$AXIS_ACT"), "$AXIS_ACT")
        self.q = q0.copy()
        self.qd = np.zeros(6)  # deg/s
        self.qdd = np.zeros(6)  # deg/s²
        self.time = 0.0  # simulated seconds since start
        self.ticks = 0
        self.rate = 1.0  # profile clock rate = effective override
        #: A program stop: the rate ramps to 0 like an override of 0, so the robot brakes on
        #: its path and the same motion resumes when the hold is released.
        self.hold = False
        self.active: list[Segment] = []  # running; two while blending
        self.pending: deque[Segment] = deque()  # planned by the advance run, not started
        self.planned_q = q0.copy()  # end of the last planned motion (base of *_REL)
        self._cache: dict[tuple[str, str], tuple[object, object]] = {}
        # the q and planned_q objects of a cycle that found the robot still (see tick)
        self._still_q: FloatArray | None = None
        self._still_planned: FloatArray | None = None
        self._q_base = q0.copy()  # PTP: q = base + Σ delta·s
        self._lin_base = np.eye(4)  # LIN: TCP pose in $BASE the running segments add to
        self._frames: tuple[FloatArray, FloatArray] = (np.zeros(6), np.zeros(6))
        #: Called with a message when a running motion must stop (IK failure during a LIN).
        self.on_fault: Callable[[str], None] | None = None
        #: Set to a list to record (time, q, qd) every cycle (tests, plots).
        self.trace: list[TraceSample] | None = None
        self._tcp = self._tcp_position(self.q)
        self._has_wrench = "EMU_WRENCH" in store.names()
        # The store already holds this state (HOME by default, with the reference's rounded
        # torques): publish nothing until something observable changes.
        self._published: tuple[object, ...] | None = self._key()

    # --- state ------------------------------------------------------------------------------
    @property
    def moving(self) -> bool:
        return bool(self.active or self.pending)

    @property
    def queued(self) -> int:
        """Motions planned but not started (the advance run's look-ahead)."""
        return len(self.pending)

    def can_plan(self, advance: int) -> bool:
        """Whether the advance run may plan another motion with ``$ADVANCE = advance``.

        With nothing running the main run itself needs one; otherwise up to ``advance``
        motions may wait behind the executing one (0: plan only when the robot stopped).
        """
        # With nothing running, the first pending motion is the one the main run executes next.
        ahead = len(self.pending) if self.active else len(self.pending) - 1
        return ahead < max(advance, 0)

    # --- planning (called by programs) -----------------------------------------------------
    def ptp(self, target: object, *, approx: bool = False, label: str = "PTP") -> None:
        """Plan ``PTP target [C_PTP]`` to an axis value (struct or 6 numbers, deg)."""
        q1 = axes_of(target, label)
        delta = q1 - self.planned_q
        if not self.active and not self.pending and np.all(np.abs(delta) < 1e-9):
            return  # the robot stands on the target: the statement completes at once
        self.check_limits(q1, label)
        v, a = self._limits()
        limits = ConstLimits(delta, v, a)
        if self.dynamics is not None:
            self.dynamics.use_load(self.store.get("$LOAD"))
            limits.adapt(*self.dynamics.ptp_limits(self.planned_q, delta, limits.v, limits.a))
        curve, bw = next_result(limits.plan())
        cptp = float(self._apo()["CPTP"])  # type: ignore[arg-type]
        lead = float(np.max(np.abs(delta)))
        # $APO.CPTP % of $APO_DIS_PTP on the leading axis, at most half the segment (§5).
        frac = min(0.5, cptp / 100.0 * APO_DIS_PTP / lead) if lead > 0 else 0.0
        profile = Profile(*curve) if curve[0].size > 1 else Profile.instant()
        seg = Segment(Kind.PTP, profile, limits, bw, delta, q1, approx, frac, label=label)
        next_result(self._enqueue(seg))

    def ptp_rel(self, delta: object, *, approx: bool = False, label: str = "PTP_REL") -> None:
        """Plan ``PTP_REL`` by an axis increment, added to the previous planned end point."""
        self.ptp(self.planned_q + axes_of(delta, label), approx=approx, label=label)

    def ptp_pose(
        self,
        pose: object,
        *,
        s: int | None = None,
        t: int | None = None,
        approx: bool = False,
        label: str = "PTP",
    ) -> None:
        """Plan a PTP to a Cartesian pose (TCP in $BASE): the KRC resolves it with IK."""
        self._frames = self._read_frames()
        try:
            q1 = inverse(
                self.model,
                xyzabc(pose, label),
                s=s,
                t=t,
                current=self.planned_q,
                tool=self._frames[0],
                base=self._frames[1],
            )
        except UnreachableError as exc:
            raise MotionRefused(f"{label}: target not reachable: {exc}") from None
        self.ptp(q1, approx=approx, label=label)

    def ptp_rel_pose(
        self, increment: object, *, approx: bool = False, tool: bool = False, label: str = "PTP_REL"
    ) -> None:
        """``PTP_REL`` by a POS/FRAME increment (Algorithm 4.12's ``PTP_REL MYPOS``)."""
        inc = xyzabc(increment, label)
        if not self.active and not self.pending and not np.any(inc):
            return
        self.ptp_pose(self.rel_pose(inc, tool=tool), approx=approx, label=label)

    def _enqueue(self, seg: Segment) -> Generator[None, None, None]:
        """Queue ``seg``, approximating the motion before it if that one allows it."""
        before = self.pending[-1] if self.pending else (self.active[-1] if self.active else None)
        if before is not None and before.approx:

            def progress() -> float:
                if before in self.pending:
                    return 0.0
                return before.progress if before in self.active else 1.0

            if seg.kind is Kind.LIN and before.kind is Kind.LIN:
                yield from self._blend_lin(before, seg, progress)
            else:
                yield from blend(before, seg, progress)
        self.pending.append(seg)
        self.planned_q = seg.end_q.copy()

    def stop(self, *, hard: bool = False) -> None:
        """Forget the planned motions; the running ones end exactly (``hard``: at once)."""
        self.pending.clear()
        for seg in self.active:
            seg.approx = False
            seg.blend_at = None
        if hard:
            self.active.clear()
            self._q_base = self.q.copy()
        self.planned_q = self.active[-1].end_q.copy() if self.active else self.q.copy()

    def reset_to(self, q: FloatArray) -> None:
        """Forget every motion and stand at ``q`` (deg): the set-point after the drives were
        switched off (a fault), where the arm physically is."""
        self.stop(hard=True)
        self.q = np.array(q, dtype=np.float64)
        self.planned_q = self.q.copy()
        self._q_base = self.q.copy()
        self.qd = np.zeros(6)
        self.qdd = np.zeros(6)
        self._still_q = self._still_planned = None

    @property
    def at_rest(self) -> bool:
        """Standing on the planned point with nothing to run: a tick changes only the time."""
        return (
            not self.active
            and not self.pending
            and self.q is self._still_q
            and self.planned_q is self._still_planned
        )

    # --- the interpolation cycle -----------------------------------------------------------
    def tick(self) -> None:
        """Advance one IPO cycle and publish the new state to the store."""
        dt = self.ipo
        ov = self.store.get("$OV_PRO")
        target = 0.0 if self.hold else float(ov) / 100.0  # type: ignore[arg-type]
        if (
            not self.active
            and not self.pending
            and self.q is self._still_q
            and self.planned_q is self._still_planned
        ):
            # Standing on the planned point, nothing to run: this cycle would compute the
            # same position, zero speed and acceleration again (most cycles of a cell at rest).
            self.rate = target
        else:
            self.rate = self._slew(target, dt) if self.active else target
            q_old = self.q
            self._advance(dt * self.rate)
            q_new = self._position()
            qd = (q_new - q_old) / dt
            self.qdd = (qd - self.qd) / dt
            self.qd, self.q = qd, q_new
            still = not self.active and not self.pending and not qd.any() and not self.qdd.any()
            if still and np.array_equal(q_new, self.planned_q):
                self._still_q, self._still_planned = self.q, self.planned_q
        self.time += dt
        self.ticks += 1
        if self.trace is not None:
            self.trace.append((self.time, self.q.copy(), self.qd.copy()))
        self.publish()

    def _slew(self, target: float, dt: float) -> float:
        """The override rate for this cycle: towards ``target`` as fast as the axes allow.

        The profile clock runs at rate ``r``: this cycle moves each segment by ``r·dt`` of its
        profile, so the set-point velocity is ``r·w`` (``w``: the mean velocity at 100 % over
        that step). ``r`` moves towards the target only as far as keeps every axis' change of
        set-point velocity within its acceleration limit: an override step never becomes an
        acceleration step.
        """
        rate = self.rate
        if target == rate:
            return rate
        lim = np.full(6, np.inf)
        for seg in self.active:
            lim = np.minimum(lim, seg.axis_accel())
        qd_old = self.qd

        def excess(r: float) -> float:
            step = dt * max(r, 1e-9)
            qd = r * sum((seg.mean_velocity(step) for seg in self.active), np.zeros(6))
            return float(np.max(np.abs(qd - qd_old) - lim * dt))

        if excess(target) <= 0.0:
            return target
        # Without a change the motion keeps within its limits (up to rounding): allow that much.
        allowed = max(excess(rate), 0.0)
        ok, bad = rate, target
        for _ in range(OV_BISECT):
            mid = 0.5 * (ok + bad)
            if excess(mid) <= allowed:
                ok = mid
            else:
                bad = mid
        return ok

    def _start_next(self, carry: float, budget: float) -> bool:
        if not self.pending:
            return False
        nxt = self.pending[0]
        if self.active:
            last = self.active[-1]
            if len(self.active) > 1 or last.kind is not nxt.kind:
                return False
            start = last.blend_at
            if start is None or last.t < start:
                return False
            nxt.t = min(last.t - start, budget)
        else:
            nxt.t = carry
            if nxt.kind is Kind.LIN:
                self._lin_base = fk_matrix(self.model, self._q_base, *self._frames)
        self.pending.popleft()
        self.active.append(nxt)
        return True

    def _advance(self, budget: float) -> None:
        self._start_next(0.0, budget)
        for seg in self.active:
            seg.t += budget
        for _ in range(64):  # bounded: zero-length segments retire immediately
            carry = 0.0
            finished = [seg for seg in self.active if seg.done]
            for seg in finished:
                carry = max(carry, seg.t - seg.duration)
                self.active.remove(seg)
                if seg.kind is Kind.PTP:
                    self._q_base = self._q_base + seg.delta
                else:
                    self._lin_base = lin_pose(self._lin_base, [(seg.delta, seg.rotvec, 1.0)])
                    self._q_base = seg.end_q.copy()
            if not self.active and not finished:
                carry = 0.0
            if not self._start_next(carry, budget) and not finished:
                break
        if not self.active:
            self._q_base = self.planned_q.copy() if not self.pending else self._q_base

    def _position(self) -> FloatArray:
        if not self.active:
            return self._q_base.copy()
        if self.active[0].kind is Kind.PTP:
            q = self._q_base.copy()
            for seg in self.active:
                q += seg.delta * seg.profile.s_at(seg.t)
            return q
        parts = [(seg.delta, seg.rotvec, seg.profile.s_at(seg.t)) for seg in self.active]
        pose = lin_pose(self._lin_base, parts)
        try:
            q = inverse(
                self.model, pose, current=self.q, tool=self._frames[0], base=self._frames[1]
            )
            self.check_limits(q, "LIN")
        except (UnreachableError, MotionRefused) as exc:
            self.stop(hard=True)
            if self.on_fault is not None:
                self.on_fault(f"LIN stopped: {exc}")
            return self.q.copy()
        return np.asarray(q, dtype=np.float64)
