"""A KUKA arm over KVP as the server's arm: the thesis' section 4 integration (JOpenShowVar).

The server's joint velocity commands become the increments of the shipped **KVP_JOG**
program (the web jog pad's, ``pyopenshowvar_apps/web/krl/kvp_jog.src``, docs/web.md): axis
mode (``JOG_MODE = 1``, ``PTP_REL JOG_AX``), one increment ``JOG_AX = u·T`` per cadence T of
20 ms, its acceleration ``JOG_ACC`` chosen so it takes T up and T down (consecutive
increments add up to the speed u), and the credit ``JOG_UNTIL`` = the program's count +
:data:`~..web.jogplan.CREDIT`, moved on at every tick. No new KRL.

Safety, on top of the server's (which stops when the input falls silent or disconnects):

* the connected robot must be the arm the server computes for: a KUKA six-axis arm whose
  ``$MODEL_NAME[]`` matches the arm's, running KVP_JOG with its globals;
* speeds are clamped per axis to what the drive can brake to zero within one cadence at its
  acceleration limit (``max_accel·T``, the pad's rule) and to its speed limit, times
  ``speed_scale``; the whole vector is scaled so the flange stays under ``tcp_limit`` mm/s
  (250 mm/s: the T1 limit);
* an axis stops :data:`LIMIT_MARGIN` before its software limit, counting the increments that
  may still be in flight;
* :meth:`KvpArm.stop` zeroes the increment, ``JOG_UNTIL`` and ``JOG_MODE`` (pipelined); if the
  PC itself dies, the program plans at most CREDIT more increments (100 ms) and waits.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from pyopenshowvar import Axis, Client, KvpError
from pyopenshowvar.arms import Arm

from ..web.jogplan import CADENCE, CREDIT
from .backend import ArmBackend, BackendError, FloatArray, JointState

__all__ = ["LIMIT_MARGIN", "TCP_LIMIT", "KvpArm"]

#: Keep this far (deg) from a software limit switch, as the web pad does.
LIMIT_MARGIN = 0.5
#: Flange speed limit (mm/s): T1's 250 mm/s.
TCP_LIMIT = 250.0
#: Increments that may already be planned or running beyond what the PC last saw.
IN_FLIGHT = 3
_AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
_ZERO = Axis(A1=0.0, A2=0.0, A3=0.0, A4=0.0, A5=0.0, A6=0.0)


def _norm_model(text: str) -> str:
    return text.strip().strip('"').lstrip("#").upper()


class KvpArm(ArmBackend):
    """A KRC (or the emulator) running KVP_JOG, driven at joint velocity (module docstring)."""

    def __init__(
        self, arm: Arm, host: str, port: int, *, timeout: float = 1.0,
        speed_scale: float = 1.0, tcp_limit: float = TCP_LIMIT,
    ) -> None:  # fmt: skip
        super().__init__(arm)
        if arm.kuka is None:
            raise BackendError(
                f"{arm.key or arm.name}: only KUKA six-axis arms are driven over KVP"
            )
        if not 0.0 < speed_scale <= 1.0:
            raise ValueError(f"speed_scale must be in (0, 1], got {speed_scale}")
        self.client = Client(host, port, timeout=timeout, keepalive=None)
        self.name = f"KUKA over KVP {host}:{port} ({arm.key})"
        self.cap = np.fmin(arm.max_speed, arm.max_accel * CADENCE) * speed_scale
        self.tcp_limit = tcp_limit
        self.lower, self.upper = np.array(arm.lower), np.array(arm.upper)
        self._state: JointState | None = None
        self._count = 0
        self._jogging = False
        self._acc = -1  # JOG_ACC as last written
        self.writes = 0

    def speed_caps(self) -> FloatArray:
        return np.asarray(self.cap)

    async def start(self) -> JointState:
        try:
            await self.client.connect()
            got = await self.client.read_many(
                ["$MODEL_NAME[]", "$PRO_NAME1[]", "$PRO_STATE1", "JOG_MODE", "JOG_COUNT",
                 "$SOFTN_END[]", "$SOFTP_END[]"], typed=True,
            )  # fmt: skip
        except (KvpError, OSError) as exc:
            raise BackendError(f"cannot reach the robot: {exc}") from None
        model = got["$MODEL_NAME[]"].text or ""
        if model and self.arm.model_name and _norm_model(model) != _norm_model(self.arm.model_name):
            raise BackendError(
                f"the robot is a {model.strip()}, not a {self.arm.model_name} "
                f"({self.arm.key}): pick the arm it is"
            )
        if not got["JOG_MODE"].ok:
            raise BackendError("the KVP_JOG globals are not on this controller (docs/web.md)")
        name = (got["$PRO_NAME1[]"].text or "").strip().strip('"')
        state = got["$PRO_STATE1"].text or ""
        if name.upper() != "KVP_JOG" or state.strip() != "#P_ACTIVE":
            raise BackendError(f"the robot runs {name or 'no program'} ({state.strip()}), "
                               "not KVP_JOG: select and start it (docs/web.md)")  # fmt: skip
        lo, hi = got["$SOFTN_END[]"], got["$SOFTP_END[]"]
        if lo.ok and hi.ok and isinstance(lo.value, list) and isinstance(hi.value, list):
            self.lower = np.maximum(self.lower, np.array(lo.value[:6], dtype=float))
            self.upper = np.minimum(self.upper, np.array(hi.value[:6], dtype=float))
        self.lower, self.upper = self.lower + LIMIT_MARGIN, self.upper - LIMIT_MARGIN
        await self.stop()
        return await self.feedback()

    async def feedback(self) -> JointState:
        try:
            got = await self.client.read_many(["$AXIS_ACT", "JOG_COUNT"], typed=True)
            axes, count = got["$AXIS_ACT"], got["JOG_COUNT"]
            if not (axes.ok and count.ok):
                raise BackendError(f"cannot read the axes: {axes.error or count.error}")
            value: Any = axes.value
            q = np.array([float(value[k]) for k in _AXES])
            self._count = int(str(count.text).strip())
        except (KvpError, OSError) as exc:
            raise BackendError(f"the robot's connection failed: {exc}") from None
        now = time.monotonic()
        prev = self._state
        qdot = np.zeros(6) if prev is None or now - prev.t <= 0 else (q - prev.q) / (now - prev.t)
        self._state = JointState(now, q, qdot)
        return self._state

    def clamp(self, q: FloatArray, u: FloatArray) -> FloatArray:
        """The command the robot gets: per-axis caps, the flange limit, the software limits."""
        u = np.clip(np.nan_to_num(np.asarray(u, dtype=np.float64)), -self.cap, self.cap)
        v = self.arm.jacobian(q)[:3] @ np.radians(u)
        speed = float(np.linalg.norm(v))
        if speed > self.tcp_limit:
            u = u * (self.tcp_limit / speed)
        ahead = (CREDIT + IN_FLIGHT) * CADENCE
        room_up = np.maximum(self.upper - q, 0.0) / ahead
        room_down = np.maximum(q - self.lower, 0.0) / ahead
        return np.asarray(np.clip(u, -room_down, room_up))

    async def command(self, u: FloatArray, dt: float) -> None:
        assert self._state is not None
        u = self.clamp(self._state.q, u)
        if not np.any(np.abs(u) > 1e-6):
            if self._jogging:
                await self.stop()
            return
        inc = u * CADENCE
        acc = math.ceil(100.0 * float(np.max(np.abs(u) / CADENCE / self.arm.max_accel)))
        acc = max(1, min(100, acc))
        writes: list[tuple[str, object]] = []
        if acc != self._acc:  # every access costs a KVP round trip: only what changed
            writes.append(("JOG_ACC", str(acc)))
        writes += [
            ("JOG_AX", Axis(**{k: float(v) for k, v in zip(_AXES, inc, strict=True)})),
            ("JOG_UNTIL", str(self._count + CREDIT)),
        ]
        if not self._jogging:
            writes.append(("JOG_MODE", "1"))
        try:
            await self.client.write_many(writes)  # type: ignore[arg-type]
        except (KvpError, OSError) as exc:
            self._jogging = False
            self._acc = -1
            raise BackendError(f"the jog write failed: {exc}") from None
        self._jogging = True
        self._acc = acc
        self.writes += 1

    async def stop(self) -> None:
        """Zero the increment first, then the credit and the mode (pipelined)."""
        self._jogging = False
        self._acc = -1
        try:
            await self.client.write_many([("JOG_AX", _ZERO), ("JOG_UNTIL", "0"), ("JOG_MODE", "0")])
        except (KvpError, OSError) as exc:
            # the robot still stops: the program plans nothing past the last JOG_UNTIL
            raise BackendError(
                f"the stop write failed ({exc}); the robot stops at JOG_UNTIL"
            ) from None

    async def close(self) -> None:
        await self.client.close()
