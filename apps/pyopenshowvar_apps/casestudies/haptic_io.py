"""One IPO cycle's motion and torque, read over KVP in separate requests that agree.

A KRC publishes ``$AXIS_ACT``, ``$VEL_AXIS_ACT[]`` and ``$TORQUE_AXIS_ACT[]`` once per 12 ms
interpolation cycle, but KVP reads one variable per request (a few ms each), so two reads can
fall in different cycles: a torque of cycle k+1 against the speeds of cycle k is an error of
the whole inertial torque change. :class:`CycleReader` handles it without any server feature:

* **a consistent group** — the speeds are read twice around the torque, pipelined in one
  batch: ``$VEL_AXIS_ACT[]``, ``$TORQUE_AXIS_ACT[]``, ``$vel_axis_act[]``, ``$AXIS_ACT`` (KRL
  names are case-insensitive; the second spelling only keeps the two answers apart).
  Speeds change every cycle while the arm moves, so two identical speed readings bracket one
  cycle: the torque between them is that cycle's (at rest every cycle is alike, and so is any
  torque). A group whose brackets differ is marked inconsistent and not used for estimation;
  the axes are read right after the bracket, at most one cycle late (a gravity error of
  (∂g/∂q)·q̇·12 ms, well below the torque noise at hand-guiding speeds);
* **the previous cycle's speed** — every speed reading is kept with the time it arrived, so the
  speed at the start of the bracketed cycle is the distinct reading before it; the number of
  cycles between them comes from the arrival times (readings are a few ms apart, so almost
  always one);
* **steady groups** — when the two speed readings differ (a tick fell between them) but by
  less than ``steady_dps`` on every axis, the arm hardly accelerated over the bracket, so the
  torque of either cycle is explained by the speeds with a near-zero acceleration: such a group
  is used with the mean acceleration between the two readings. On a loaded machine, where a
  group can take longer than a cycle, these keep a hand-guided (gentle) motion measurable;
* **plausibility** — the cycle count between two speed readings comes from arrival times, which
  a busy machine (or an emulator catching up late cycles) can fool; a mean acceleration above
  twice the axis' limit (``accel_limit``, what the app set in ``$ACC_AXIS``) cannot be the
  arm's, so such a motion is dropped rather than turned into a phantom inertial force.

Issue 11 will add a one-request snapshot; until then this is what a client can do.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pyopenshowvar import Struct, parse_array, parse_value
from pyopenshowvar.kinematics import KR6R900SIXX, RobotModel
from pyopenshowvar_apps.casestudies.devices import Clock
from pyopenshowvar_apps.casestudies.haptic_model import IPO, CycleMotion

__all__ = ["CycleReader", "Reading"]

FloatArray = npt.NDArray[np.float64]
SPEED, TORQUE, AXES = "$VEL_AXIS_ACT[]", "$TORQUE_AXIS_ACT[]", "$AXIS_ACT"
#: The same speeds again, after the torque (a second spelling: one answer per name).
SPEED_AGAIN = "$vel_axis_act[]"
GROUP = [SPEED, TORQUE, SPEED_AGAIN, AXES]


@dataclass(frozen=True)
class Reading:
    """One group: arrival time (clock s), axes (deg), end-of-cycle speeds (deg/s), torques
    (Nm), whether they belong to one cycle, and that cycle's motion when its start is known."""

    t: float
    q: FloatArray
    qd: FloatArray
    tau: FloatArray
    tau_text: str
    consistent: bool
    motion: CycleMotion | None
    qd_after: FloatArray | None = None
    steady: bool = False


def _reals(text: str, what: str) -> FloatArray:
    values = parse_array(text, "REAL")
    if len(values) < 6:
        raise ValueError(f"{what}: expected 6 values, got {text!r}")
    return np.asarray(values[:6], dtype=np.float64)


def _axes(text: str) -> FloatArray:
    value = parse_value(text, "E6AXIS")
    if not isinstance(value, Struct):
        raise ValueError(f"$AXIS_ACT: not a structure: {text!r}")
    return np.array([float(value[f"A{i}"]) for i in range(1, 7)])  # type: ignore[arg-type]


class CycleReader:
    """Reads groups from ``client``; ``clock`` gives arrival times in robot seconds."""

    def __init__(
        self,
        client: Any,
        clock: Clock,
        *,
        model: RobotModel = KR6R900SIXX,
        ipo: float = IPO,
        steady_dps: float = 0.2,
        accel_limit: npt.ArrayLike | None = None,
    ) -> None:
        self.client = client
        self.steady_dps = steady_dps
        #: deg/s² per axis; None: the model's maxima (100 %)
        self.accel_limit = np.asarray(
            model.max_accel if accel_limit is None else accel_limit, dtype=np.float64
        )
        self.clock = clock
        self.ipo = ipo
        self.max_speed = np.asarray(model.max_speed, float)
        #: distinct speed readings: (first arrival, text, deg/s)
        self._speeds: deque[tuple[float, str, FloatArray]] = deque(maxlen=8)
        self.groups = 0
        self.consistent = 0
        self.steady = 0
        self.implausible = 0

    def _speed(self, t: float, text: str) -> FloatArray:
        if self._speeds and self._speeds[-1][1] == text:
            return self._speeds[-1][2]
        qd: FloatArray = _reals(text, SPEED) * self.max_speed / 100.0  # % of maximum → deg/s
        self._speeds.append((t, text, qd))
        return qd

    def _start_of(self, text: str) -> tuple[FloatArray, int] | None:
        """The speed at the start of the cycle whose end speed is ``text``, and the cycles
        between them; None before two distinct readings exist."""
        for i in range(len(self._speeds) - 1, 0, -1):
            if self._speeds[i][1] == text:
                t1, t0 = self._speeds[i][0], self._speeds[i - 1][0]
                # arrival times (robot s) are a few ms apart; a cycle skipped shows as a gap
                return self._speeds[i - 1][2], max(1, round((t1 - t0) / self.ipo))
        return None

    async def read(self) -> Reading:
        """One group (four pipelined reads); raises the client's errors."""
        sent = self.clock.now()
        res = await self.client.read_many(GROUP)
        t = self.clock.now()
        text = {n: str(res[n].unwrap()) for n in GROUP}
        # the proxy answers a batch one request after the other: the k-th of n reads was
        # made about k/n of the way from sending to the last answer
        t1, t2 = sent + (t - sent) / 4, sent + 3 * (t - sent) / 4
        qd = self._speed(t1, text[SPEED])
        qd_after = self._speed(t2, text[SPEED_AGAIN])
        consistent = text[SPEED] == text[SPEED_AGAIN]
        steady = False
        motion = None
        q = _axes(text[AXES])
        if consistent:
            start = self._start_of(text[SPEED])
            if start is not None:
                qd0, cycles = start
                motion = CycleMotion(q, qd0, qd, cycles * self.ipo)
            elif not np.any(qd):  # at rest from the first reading: the motion is known
                motion = CycleMotion(q, qd, qd, self.ipo)
        elif float(np.max(np.abs(qd_after - qd))) < self.steady_dps:
            steady = True
            cycles = max(1, round((t2 - t1) / self.ipo))
            motion = CycleMotion(q, qd, qd_after, cycles * self.ipo)
        if motion is not None and np.any(np.abs(motion.mean_accel) > 2.0 * self.accel_limit):
            motion = None
            self.implausible += 1
        self.groups += 1
        self.consistent += consistent
        self.steady += steady
        tau = _reals(text[TORQUE], TORQUE)
        return Reading(t, q, qd, tau, text[TORQUE], consistent, motion, qd_after, steady)

    @property
    def consistent_fraction(self) -> float:
        return self.consistent / self.groups if self.groups else math.nan

    @property
    def steady_fraction(self) -> float:
        return self.steady / self.groups if self.groups else math.nan
