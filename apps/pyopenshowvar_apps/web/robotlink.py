"""The live view's side of KVP: poll the robot on its own connection and keep one snapshot.

One asyncio :class:`~pyopenshowvar.Client` reads the robot's state pipelined (one round of
``read_many`` per period), turns it into a JSON-ready dict and hands it to the listeners (the
web server's sessions). The jog pad writes on a second connection (:mod:`.jog`), so a stop
never waits behind a batch of status reads. Variables a controller does not have (the
emulator-only ``$EMU_MESSAGE[]``, the jog globals before KVP_JOG is installed) are read once,
found missing, and then left out, so a real KRC costs no failed reads per period.

The arm is drawn from the kinematics: :func:`arm_frames` sends the frame of every joint (D-H
frames 0..5), the flange and the TCP, so the page only has to draw what it is given. Which
arm: the one the controller's ``$MODEL_NAME[]`` names in the catalogue (read with the slow
variables, so a different robot behind the same address is noticed), unless the server was
given one (``kvp web --robot``); see :mod:`..armpick`.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from pyopenshowvar import Client, KvpError, Struct, UnknownVariableError
from pyopenshowvar.kinematics import RobotModel, link_frames, pose_to_matrix

from ..armpick import DEFAULT_CHOICE, ArmChoice, choose_arm
from ..common import to_jsonable

__all__ = ["MAX_WATCH", "RobotLink", "arm_frames"]

log = logging.getLogger(__name__)

#: Read every period (those a controller lacks are dropped after the first try).
FAST = (
    "$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[]", "$OV_PRO", "$PRO_STATE1", "$PRO_NAME1[]",
    "$MODE_OP", "$STOPMESS", "JOG_MODE", "$EMU_MESSAGE[]",
)  # fmt: skip
#: Read about once a second: they change rarely.
SLOW = ("$SOFTN_END[]", "$SOFTP_END[]", "$TOOL", "$BASE", "$ROBNAME[]", "$MODEL_NAME[]")
#: Names the watch lists of all pages may add to one poll, in total.
MAX_WATCH = 32
_AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
_POSE = ("X", "Y", "Z", "A", "B", "C")


def frame6(value: object) -> np.ndarray | None:
    """X, Y, Z, A, B, C of a FRAME/POS/E6POS value, or None if it is not one."""
    if isinstance(value, Struct) and all(k in value for k in _POSE):
        return np.array([float(value[k]) for k in _POSE])  # type: ignore[arg-type]
    return None


def axes_of(value: object) -> np.ndarray | None:
    """A1..A6 of an AXIS/E6AXIS value, or None if it is not one."""
    if isinstance(value, Struct) and all(k in value for k in _AXES):
        return np.array([float(value[k]) for k in _AXES])  # type: ignore[arg-type]
    return None


def arm_frames(
    model: RobotModel, q: Iterable[float], tool: np.ndarray | None = None
) -> list[list[float]]:
    """Joint frames 0..5, the flange and the TCP, each as x axis, y axis, z axis, origin (mm)."""
    frames = link_frames(model, np.asarray(list(q), dtype=np.float64))
    flange = frames[6] @ model.flange
    tcp = flange @ pose_to_matrix(tool) if tool is not None else flange
    out = []
    for m in (*frames[:6], flange, tcp):
        cols = np.concatenate([m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3]])
        out.append([round(float(v), 4) for v in cols])
    return out


class RobotLink:
    """Polls the robot ``hz`` times a second and keeps :attr:`snapshot` (see module doc)."""

    def __init__(
        self,
        host: str,
        port: int,
        *,
        timeout: float = 2.0,
        hz: float = 20.0,
        arm: ArmChoice | None = None,
    ) -> None:
        self.client = Client(host, port, timeout=timeout, auto_reconnect=True, keepalive=None)
        self.period = 1.0 / hz
        #: The arm given by the user (None: follow ``$MODEL_NAME[]``).
        self.given = arm
        #: The arm drawn and jogged now.
        self.arm = arm or DEFAULT_CHOICE
        self.snapshot: dict[str, Any] = {
            "t": "state",
            "link": {"connected": False, "error": "connecting"},
        }
        self.listeners: list[Callable[[dict[str, Any]], None]] = []
        #: Watch-list names requested by the pages (set by the server, bounded by MAX_WATCH).
        self.watch: set[str] = set()
        self.missing: set[str] = set()
        self.values: dict[str, Any] = {}
        self.seq = 0
        self.rate = 0.0  # polls per second achieved
        self.connected = False
        self._last_slow = -math.inf

    @property
    def model(self) -> RobotModel:
        """The closed-form model of the arm drawn and jogged now."""
        return self.arm.model

    # --- state the jog controller uses ------------------------------------------------------
    def axes(self) -> np.ndarray | None:
        return axes_of(self.values.get("$AXIS_ACT"))

    def pose(self) -> np.ndarray | None:
        return frame6(self.values.get("$POS_ACT"))

    def frame(self, name: str) -> np.ndarray | None:
        return frame6(self.values.get(name))

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self.values.get("$SOFTN_END[]"), self.values.get("$SOFTP_END[]")
        if isinstance(lo, list) and isinstance(hi, list) and len(lo) >= 6 and len(hi) >= 6:
            return np.array(lo[:6], dtype=float), np.array(hi[:6], dtype=float)
        return self.model.lower.copy(), self.model.upper.copy()

    def text(self, name: str) -> str:
        v = self.values.get(name)
        return str(v) if v is not None else ""

    def jog_ready(self) -> str | None:
        """Why the KVP_JOG program cannot jog now, or None when it can."""
        if not self.connected:
            return "no connection to the robot"
        if "JOG_MODE" in self.missing:
            return "the KVP_JOG globals are not on this controller (see docs/web.md)"
        name, state = self.text("$PRO_NAME1[]"), self.text("$PRO_STATE1")
        if name.upper() != "KVP_JOG":
            return f"the robot runs {name or 'no program'}, not KVP_JOG (see docs/web.md)"
        if state != "#P_ACTIVE":
            return f"KVP_JOG is not running ({state or 'state unknown'})"
        return None

    # --- the poll loop ----------------------------------------------------------------------
    async def run(self) -> None:
        """Poll until cancelled; reconnects on its own (errors show in the snapshot)."""
        next_at = time.monotonic()
        stamps: list[float] = []
        while True:
            try:
                await self.poll_once()
            except (KvpError, OSError) as exc:
                self.connected = False
                self.snapshot = {"t": "state", "link": {"connected": False, "error": str(exc)}}
                self._notify()
                await asyncio.sleep(1.0)
                next_at = time.monotonic()
                continue
            now = time.monotonic()
            stamps = [t for t in stamps if now - t < 1.0]
            stamps.append(now)
            self.rate = float(len(stamps))
            next_at = max(next_at + self.period, now)
            await asyncio.sleep(next_at - now)

    async def poll_once(self) -> None:
        now = time.monotonic()
        names = [n for n in FAST if n not in self.missing]
        slow = now - self._last_slow > 1.0
        if slow:
            names += [n for n in SLOW if n not in self.missing]
        names += sorted(self.watch - set(names))[:MAX_WATCH]
        results = await self.client.read_many(names, typed=True)
        self.connected = True
        if slow:
            self._last_slow = now
        watch: dict[str, dict[str, Any]] = {}
        for name, r in results.items():
            if name in self.watch:
                watch[name] = {"text": r.text, "error": None if r.ok else str(r.error)}
            if r.ok:
                self.values[name] = r.value
            elif isinstance(r.error, UnknownVariableError) and name in FAST + SLOW:
                self.missing.add(name)
        if slow:
            self._pick_arm()
        self.seq += 1
        self.snapshot = self._build(watch)
        self._notify()

    def _pick_arm(self) -> None:
        """Follow the controller's ``$MODEL_NAME[]`` (unless an arm was given)."""
        name = self.text("$MODEL_NAME[]")
        choice = choose_arm(name, self.given)
        if choice != self.arm:
            if choice.model is not self.arm.model:
                log.info("drawing %s (%s)", choice.model.name, choice.source)
            self.arm = choice

    def _notify(self) -> None:
        for listener in list(self.listeners):
            listener(self.snapshot)

    def _build(self, watch: dict[str, dict[str, Any]]) -> dict[str, Any]:
        stats = self.client.stats
        lo, hi = self.limits()
        q = self.axes()
        tool = self.frame("$TOOL")
        torques = self.values.get("$TORQUE_AXIS_ACT[]")
        ov = self.values.get("$OV_PRO")
        state = {
            "t": "state",
            "seq": self.seq,
            "link": {
                "connected": True,
                "error": None,
                "ewma_ms": round(stats.ewma * 1e3, 2) if stats.count else None,
                "max_ms": round(stats.maximum * 1e3, 2) if stats.count else None,
                "reads": stats.count,
                "rate": self.rate,
            },
            "axes": [round(float(x), 3) for x in q] if q is not None else None,
            "limits": {"lo": lo.tolist(), "hi": hi.tolist()},
            "pose": to_jsonable(self.values.get("$POS_ACT")),
            "torques": [round(float(x), 2) for x in torques[:6]]
            if isinstance(torques, list)
            else None,
            "ov": ov if isinstance(ov, int) else None,
            "mode_op": self.text("$MODE_OP"),
            "robot": self.text("$ROBNAME[]"),
            "program": {
                "name": self.text("$PRO_NAME1[]"),
                "state": self.text("$PRO_STATE1"),
                "stopmess": self.values.get("$STOPMESS") is True,
                "message": self.text("$EMU_MESSAGE[]"),
                "jog_ready": self.jog_ready(),
            },
            "arm": arm_frames(self.model, q, tool) if q is not None else None,
            "model": {
                "name": self.model.name,
                "key": self.arm.key,
                "source": self.arm.source,
                "reach": round(self.arm.reach, 1),
            },
            "watch": watch,
        }
        return state
