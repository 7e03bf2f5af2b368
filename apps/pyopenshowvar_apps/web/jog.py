"""Hold-to-move jogging: one owner at a time, a keep-alive from the page, a limit for the robot.

The page sends ``jog`` when a button goes down and repeats it as a keep-alive while the
button is held (every 25 ms); it sends ``release`` when the button comes up, the pointer
is cancelled, the window loses focus or the tab is hidden. :class:`JogController` turns that
into KVP traffic on its own connection:

* press: read ``JOG_COUNT`` with the robot's axes and pose, then write the increment and accelerations, ``JOG_UNTIL`` (a few
  increments ahead) and ``JOG_MODE``;
* while held, every :data:`TOPUP` s: read ``JOG_COUNT`` (again with the axes and pose) and move ``JOG_UNTIL`` to
  :data:`~.jogplan.CREDIT` increments ahead of it, but never past what the software limits
  (axes) or the reachable workspace (Cartesian) allow, nor past the end of a step. The room
  is measured from axes read in the same batch as the count, never from the live view, which
  may be a poll period old: the robot would have used that room already;
* a keep-alive may change the jog override only (anything else stops the jog);
* release, a dropped WebSocket, :data:`HOLD_TIMEOUT` without a keep-alive, or a failed write:
  the increment zeroed first, then ``JOG_UNTIL = 0`` and ``JOG_MODE = 0``, pipelined.

If the PC itself goes silent the robot still stops: it plans nothing past ``JOG_UNTIL`` (the
KRL program's own watchdog, see ``krl/kvp_jog.src``).
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from pyopenshowvar import Client, KvpError
from pyopenshowvar.kinematics import (
    RobotModel,
    UnreachableError,
    inverse,
    matrix_to_frame,
    pose_to_matrix,
)

from .jogplan import CREDIT, JogPlan, JogRequest, plan_jog
from .robotlink import RobotLink, axes_of, frame6

__all__ = ["HOLD_TIMEOUT", "TOPUP", "JogController"]

log = logging.getLogger(__name__)

#: The jog stops when the page has not repeated its keep-alive for this long (it sends one
#: every 25 ms, so four in a row were lost or the page froze).
HOLD_TIMEOUT = 0.1
#: Seconds between two moves of JOG_UNTIL while a jog is held.
TOPUP = 0.04
#: Increments that may already be planned or running beyond the PC's last view of the robot.
IN_FLIGHT = 3
#: Keep this far (deg) from a software limit switch.
LIMIT_MARGIN = 0.5
#: A Cartesian jog stops before a joint would jump this far (deg): a wrist singularity.
JUMP = 20.0


@dataclass(frozen=True)
class _Sample:
    """JOG_COUNT and where the robot is, read in one pipelined batch."""

    count: int
    axes: np.ndarray | None
    pose: np.ndarray | None


@dataclass
class _Jog:
    owner: object
    press: int
    req: JogRequest
    plan: JogPlan
    #: JOG_COUNT when the press started.
    start: int
    last_hold: float
    last_topup: float = 0.0


def advance_pose(pose: np.ndarray, inc: np.ndarray, n: float, *, tool: bool) -> np.ndarray:
    """``pose`` moved ``n`` increments: in $BASE (about the base axes at the TCP) or in $TOOL."""
    start = pose_to_matrix(pose)
    step = pose_to_matrix(np.asarray(inc) * n)
    if tool:
        return np.asarray(matrix_to_frame(start @ step), dtype=np.float64)
    end = start.copy()
    end[:3, :3] = step[:3, :3] @ start[:3, :3]
    end[:3, 3] += step[:3, 3]
    return np.asarray(matrix_to_frame(end), dtype=np.float64)


class JogController:
    """The single jog in progress (see the module docstring)."""

    def __init__(
        self,
        client: Client,
        link: RobotLink,
        *,
        model: RobotModel | None = None,
        hold_timeout: float = HOLD_TIMEOUT,
        credit: int = CREDIT,
    ) -> None:
        self.client = client
        self.link = link
        self._model = model
        self.hold_timeout = hold_timeout
        self.credit = credit
        self.jog: _Jog | None = None
        self._lock = asyncio.Lock()
        #: Why the last jog ended (shown on the page), and when.
        self.last_stop: tuple[str, float] | None = None
        self._done: dict[object, int] = {}  # owner -> last press that ended (never restart it)

    @property
    def model(self) -> RobotModel:
        """The arm jogged: the one given, else the link's (the connected robot's)."""
        return self._model if self._model is not None else self.link.model

    # --- what the page sees -----------------------------------------------------------------
    def describe(self, owner: object) -> dict[str, Any]:
        jog = self.jog
        out: dict[str, Any] = {"active": jog is not None, "mine": False, "label": None}
        if jog is not None:
            unit = "mm/s" if jog.req.frame != "axis" and jog.req.index < 3 else "deg/s"
            out.update(
                mine=jog.owner is owner,
                label=jog.req.label,
                speed=round(jog.plan.speed, 2),
                unit=unit,
            )
        if self.last_stop is not None:
            out["stopped"] = self.last_stop[0]
        return out

    # --- events from the pages --------------------------------------------------------------
    async def press(self, owner: object, press: int, req: JogRequest) -> str | None:
        """Start (or keep alive) a jog; returns why it was refused, or None."""
        now = time.monotonic()
        jog = self.jog
        if jog is not None:
            if jog.owner is not owner:
                return "another page is jogging"
            if jog.press == press:
                if replace(req, override=jog.req.override) != jog.req:
                    # Only the override may change while a button is held: a keep-alive that
                    # names another axis, direction or step is not the page's button.
                    await self.stop(owner, "the press changed its button")
                    return "a held press cannot change its button: press again"
                jog.last_hold = now
                if req.override != jog.req.override and req.step is None:
                    await self._retune(jog, req)
                return None
            await self.stop(owner, "new press")
        if self._done.get(owner) == press:
            return None  # this press already ended (released, timed out or step done)
        reason = self.link.jog_ready()
        if reason is not None:
            self._done[owner] = press
            return reason
        plan = plan_jog(req, self.model)
        async with self._lock:
            try:
                sample = await self._sample()
            except (KvpError, OSError, ValueError) as exc:
                self._done[owner] = press
                return f"cannot read the robot: {exc}"
            credit = self._credit(req, plan, sample, whole=req.step is not None)
            if credit <= 0 or (plan.count is not None and credit < plan.count):
                self._done[owner] = press
                return self._limit_text(req)
            start = sample.count
            try:
                self.jog = _Jog(owner, press, req, plan, start, now, last_topup=now)
                until = plan.until(start, start, min(credit, self.credit))
                await self.client.write_many(plan.start_writes(until))
            except (KvpError, OSError, ValueError) as exc:
                self.jog = None
                self._done[owner] = press
                await self._zero(plan)
                return f"jog write failed: {exc}"
        log.info("jog %s at %.3g/s", req.label, plan.speed)
        return None

    async def release(self, owner: object, reason: str = "released") -> None:
        """The owner's button came up (or its page went away): stop now."""
        jog = self.jog
        if jog is not None and jog.owner is owner:
            await self.stop(owner, reason)

    async def stop(self, owner: object | None, reason: str) -> None:
        async with self._lock:
            jog = self.jog
            if jog is None or (owner is not None and jog.owner is not owner):
                return
            self.jog = None
            self._done[jog.owner] = jog.press
            self.last_stop = (reason, time.monotonic())
            await self._zero(jog.plan)
        log.info("jog %s stopped: %s", jog.req.label, reason)

    def forget(self, owner: object) -> None:
        self._done.pop(owner, None)

    async def _zero(self, plan: JogPlan) -> None:
        try:
            await self.client.write_many(plan.stop_writes())
        except (KvpError, OSError) as exc:
            # The robot still stops: it plans nothing past the last JOG_UNTIL.
            log.warning("jog stop write failed (%s); the robot stops at JOG_UNTIL instead", exc)

    async def _retune(self, jog: _Jog, req: JogRequest) -> None:
        plan = plan_jog(req, self.model)
        async with self._lock:
            if self.jog is not jog:
                return
            jog.req, jog.plan = req, plan
            writes = plan.start_writes(0)[:4]  # accelerations and increment
            try:
                await self.client.write_many(writes)
            except (KvpError, OSError) as exc:
                log.warning("jog override change failed: %s", exc)

    # --- the watchdog and the credit --------------------------------------------------------
    async def run(self, period: float = 0.01) -> None:
        """Stop on a missing keep-alive, move JOG_UNTIL on, notice a finished step."""
        while True:
            await asyncio.sleep(period)
            jog = self.jog
            if jog is None:
                continue
            now = time.monotonic()
            if now - jog.last_hold > self.hold_timeout:
                ms = self.hold_timeout * 1e3
                await self.stop(jog.owner, f"no keep-alive from the page for {ms:.0f} ms")
                continue
            if now - jog.last_topup < TOPUP:
                continue
            jog.last_topup = now
            await self._topup(jog)

    async def _topup(self, jog: _Jog) -> None:
        """Move JOG_UNTIL ahead of the program's count (or end a finished step)."""
        if not self.link.connected:
            await self.stop(jog.owner, "the live state of the robot is lost")
            return
        try:
            sample = await self._sample()
        except (KvpError, OSError, ValueError) as exc:
            await self.stop(jog.owner, f"cannot read JOG_COUNT: {exc}")
            return
        seen, plan = sample.count, jog.plan
        if plan.count is not None:
            if seen - jog.start >= plan.count:
                await self.stop(jog.owner, "step done")
                return
            credit = self.credit  # the whole step was checked against the limits at the press
        else:
            credit = min(self.credit, self._credit(jog.req, plan, sample, whole=False))
        if credit <= 0:
            await self.stop(jog.owner, self._limit_text(jog.req))
            return
        async with self._lock:
            if self.jog is not jog:
                return
            try:
                await self.client.write("JOG_UNTIL", str(plan.until(jog.start, seen, credit)))
            except (KvpError, OSError) as exc:
                self.jog = None
                self._done[jog.owner] = jog.press
                self.last_stop = (f"write failed: {exc}", time.monotonic())
                await self._zero(plan)

    async def _sample(self) -> _Sample:
        """JOG_COUNT, $AXIS_ACT and $POS_ACT in one batch: the count and the position the
        credit is measured from belong to the same moment (within one round trip)."""
        got = await self.client.read_many(["JOG_COUNT", "$AXIS_ACT", "$POS_ACT"], typed=True)
        count = int(got["JOG_COUNT"].unwrap())
        return _Sample(count, axes_of(got["$AXIS_ACT"].value), frame6(got["$POS_ACT"].value))

    def _credit(self, req: JogRequest, plan: JogPlan, sample: _Sample, *, whole: bool) -> int:
        """Increments the robot may plan without passing a limit (``whole``: the full step)."""
        need = plan.count if whole and plan.count is not None else self.credit
        if req.frame == "axis":
            q = sample.axes
            if q is None:
                return 0
            lo, hi = self.link.limits()
            i, step = req.index, abs(float(plan.increment[req.index]))
            room = float(hi[i] - q[i] if req.direction > 0 else q[i] - lo[i]) - LIMIT_MARGIN
            fit = math.floor(room / step + 1e-9) - (0 if whole else IN_FLIGHT)
            return max(0, min(need, fit))
        n = need + (0 if whole else IN_FLIGHT)
        return need if self._reachable(req, plan, sample, n) else 0

    def _reachable(self, req: JogRequest, plan: JogPlan, sample: _Sample, n: int) -> bool:
        """Whether the TCP can go ``n`` increments on without leaving the workspace or the
        limits, or swinging a joint through a singularity (the KRC would stop the program)."""
        pose, q = sample.pose, sample.axes
        if pose is None or q is None:
            return False
        tool, base = self.link.frame("$TOOL"), self.link.frame("$BASE")
        ahead = advance_pose(pose, plan.increment, n, tool=req.frame == "tool")
        try:
            q_ahead = inverse(self.model, ahead, current=q, tool=tool, base=base)
        except UnreachableError:
            return False
        lo, hi = self.link.limits()
        if np.any(q_ahead > hi - LIMIT_MARGIN) or np.any(q_ahead < lo + LIMIT_MARGIN):
            return False
        return bool(np.max(np.abs(q_ahead - q)) < JUMP + n * 0.5)

    @staticmethod
    def _limit_text(req: JogRequest) -> str:
        if req.frame == "axis":
            sign = "+" if req.direction > 0 else "-"
            return f"software limit {sign}{req.key} ahead"
        return f"{req.key} {'+' if req.direction > 0 else '-'}: out of reach or a singularity ahead"
