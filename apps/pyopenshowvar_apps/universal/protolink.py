"""The open link to external simulators: the thesis' protobuf messages over TCP (§4.2.1).

The thesis drives the OSC crane simulator with Protocol Buffers: the server sends ``ToOSC``
(model id, optional model name, the valve signals) and the simulator answers ``ToAAUC`` (the
actual joint angles and velocities). ``universal.proto`` beside this module is that schema
(Algorithm 4.1, proto2), ``universal_pb2.py`` the code protoc generated from it.

On the wire every message is one frame: a 4-byte big-endian length, then the message; frames
longer than :data:`MAX_FRAME` are refused. The exchange is lockstep — one ``ToOSC``, one
``ToAAUC`` — with a timeout on every read, so a silent or broken peer is an error, never a
hang. As in the thesis the simulator is a client: :class:`ProtoArm` (the server's backend)
listens, a simulator connects.

Signals: ``valveSignals`` are joint velocity commands in [−1, 1] of each joint's speed limit
(a hydraulic valve's opening; :func:`pyopenshowvar.universal.tracking.joint_limits`), the
replies are in rad and rad/s (m, m/s for prismatic joints). ``modelName`` is the catalogue
name of the arm (the simulator loads it), ``model`` its position in the catalogue (1-based).

:class:`StandInSimulator` is the small simulator on the other end, for tests and the demo:
each joint follows its valve through a first-order lag (:data:`VALVE_LAG`) up to its speed
limit, with hard end stops, in real time.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Callable

import numpy as np
from google.protobuf.message import DecodeError

from pyopenshowvar.arms import Arm, catalogue, load_arm
from pyopenshowvar.universal.tracking import joint_limits

from . import universal_pb2 as pb
from .backend import ArmBackend, BackendError, FloatArray, JointState

__all__ = [
    "MAX_FRAME",
    "ProtoArm",
    "ProtocolError",
    "StandInSimulator",
    "encode_frame",
    "model_id",
    "read_frame",
]

log = logging.getLogger(__name__)

HEADER = 4
#: The largest frame accepted (bytes): a ToAAUC of 2000 joints; a 7-axis arm needs ~130.
MAX_FRAME = 32 * 1024
#: The hydraulic valve's response in the stand-in simulator (s).
VALVE_LAG = 0.1


class ProtocolError(BackendError):
    """A peer broke the framing or sent a message that does not fit."""


def encode_frame(message: pb.ToOSC | pb.ToAAUC) -> bytes:
    body = message.SerializeToString()
    return len(body).to_bytes(HEADER, "big") + body


async def read_frame(reader: asyncio.StreamReader, timeout: float) -> bytes:
    """One frame's message bytes; ProtocolError for an oversized frame, TimeoutError if the
    peer is silent, IncompleteReadError if it hung up mid-frame."""
    async with asyncio.timeout(timeout):
        header = await reader.readexactly(HEADER)
        size = int.from_bytes(header, "big")
        if size > MAX_FRAME:
            raise ProtocolError(f"frame of {size} bytes (at most {MAX_FRAME})")
        return await reader.readexactly(size)


def model_id(arm: Arm) -> int:
    """The arm's ``model`` number: its 1-based position in the catalogue (0 for a file)."""
    names = catalogue()
    return names.index(arm.key) + 1 if arm.key in names else 0


def _units(arm: Arm) -> FloatArray:
    """API units (deg, mm) per SI unit (rad, m) per joint."""
    return np.where(arm.revolute, math.degrees(1.0), 1000.0)


class ProtoArm(ArmBackend):
    """The server's side: listens on ``host:port`` for one simulator (see the module doc)."""

    switchable = True

    def __init__(
        self, arm: Arm, host: str = "127.0.0.1", port: int = 0, *, timeout: float = 1.0,
        accept_timeout: float = 30.0,
    ) -> None:  # fmt: skip
        super().__init__(arm)
        self.host, self.port = host, port
        self.timeout, self.accept_timeout = timeout, accept_timeout
        self.name = f"external simulator over protobuf ({arm.key})"
        self._server: asyncio.Server | None = None
        self._peer: asyncio.Future[tuple[asyncio.StreamReader, asyncio.StreamWriter]] | None = None
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._state: JointState | None = None
        self.exchanges = 0

    async def listen(self) -> int:
        """Bind and listen (before :meth:`start`); returns the port."""
        loop = asyncio.get_running_loop()
        self._peer = loop.create_future()

        async def accept(r: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
            if self._peer is not None and not self._peer.done():
                self._peer.set_result((r, w))
            else:  # one simulator at a time
                w.close()

        self._server = await asyncio.start_server(accept, self.host, self.port)
        self.port = self._server.sockets[0].getsockname()[1]
        return self.port

    async def start(self) -> JointState:
        if self._server is None:
            await self.listen()
        assert self._peer is not None
        try:
            self._reader, self._writer = await asyncio.wait_for(self._peer, self.accept_timeout)
        except TimeoutError:
            raise BackendError(
                f"no simulator connected to {self.host}:{self.port} within "
                f"{self.accept_timeout:g} s"
            ) from None
        await self._exchange(np.zeros(self.arm.dof))
        assert self._state is not None
        return self._state

    async def _exchange(self, valves: FloatArray) -> None:
        if self._reader is None or self._writer is None:
            raise BackendError("the simulator is not connected")
        arm = self.arm
        msg = pb.ToOSC(model=model_id(arm), modelName=arm.key, valveSignals=valves.tolist())
        try:
            self._writer.write(encode_frame(msg))
            await self._writer.drain()
            payload = await read_frame(self._reader, self.timeout)
        except TimeoutError:
            raise BackendError(f"the simulator did not answer within {self.timeout:g} s") from None
        except (OSError, asyncio.IncompleteReadError) as exc:
            raise BackendError(f"the simulator's connection failed: {exc}") from None
        try:
            reply = pb.ToAAUC.FromString(payload)
        except DecodeError as exc:
            raise ProtocolError(f"not a ToAAUC message: {exc}") from None
        q, qd = np.array(reply.jointAngles), np.array(reply.jointVelocities)
        if q.shape != (arm.dof,) or qd.shape != (arm.dof,):
            raise ProtocolError(
                f"ToAAUC has {len(q)} angles and {len(qd)} velocities, {arm.key} has {arm.dof} joints"
            )
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
            raise ProtocolError("ToAAUC carries a non-finite value")
        unit = _units(arm)
        self._state = JointState(time.monotonic(), q * unit, qd * unit)
        self.exchanges += 1

    async def feedback(self) -> JointState:
        if self._state is None:
            raise BackendError("the simulator has not reported yet")
        return self._state

    async def command(self, u: FloatArray, dt: float) -> None:
        speed, _ = joint_limits(self.arm)
        await self._exchange(np.clip(np.asarray(u) / speed, -1.0, 1.0))

    async def stop(self) -> None:
        if self._writer is not None and not self._writer.is_closing():
            await self._exchange(np.zeros(self.arm.dof))

    async def set_arm(self, arm: Arm) -> JointState:
        await self.stop()
        self.arm = arm
        self.name = f"external simulator over protobuf ({arm.key})"
        await self._exchange(np.zeros(arm.dof))
        assert self._state is not None
        return self._state

    async def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            with contextlib.suppress(OSError):
                await self._writer.wait_closed()
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()


class StandInSimulator:
    """The simulator end for tests and demos: connects, answers every ToOSC with a ToAAUC."""

    def __init__(
        self, host: str, port: int, *, idle_timeout: float = 10.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:  # fmt: skip
        self.host, self.port = host, port
        self.idle_timeout, self.clock = idle_timeout, clock
        self.arm: Arm | None = None
        self.q = np.zeros(0)
        self.qdot = np.zeros(0)
        self.messages = 0

    def _load(self, msg: pb.ToOSC) -> Arm:
        name = msg.modelName if msg.HasField("modelName") else ""
        if self.arm is not None and (
            name == self.arm.key or (not name and msg.model == model_id(self.arm))
        ):
            return self.arm
        names = catalogue()
        if not name:
            if not 1 <= msg.model <= len(names):
                raise ProtocolError(f"unknown model {msg.model} (1..{len(names)})")
            name = names[msg.model - 1]
        if name not in names:
            raise ProtocolError(f"unknown model name {name!r}")
        arm = load_arm(name)
        self.arm, self.q, self.qdot = arm, np.array(arm.home_q), np.zeros(arm.dof)
        self.speed, self.accel = joint_limits(arm)
        log.info("stand-in simulator: now simulating %s", arm.key)
        return arm

    def step(self, valves: FloatArray, dt: float) -> None:
        """Advance the hydraulics by ``dt`` seconds (valves in [−1, 1])."""
        assert self.arm is not None
        wanted = np.clip(valves, -1.0, 1.0) * self.speed
        self.qdot = self.qdot + (wanted - self.qdot) * min(1.0, dt / VALVE_LAG)
        nxt = self.q + self.qdot * dt
        wall = (nxt <= self.arm.lower) | (nxt >= self.arm.upper)
        self.q = np.clip(nxt, self.arm.lower, self.arm.upper)
        self.qdot = np.where(wall, 0.0, self.qdot)

    async def run(self) -> None:
        """Connect and serve until the server hangs up (ProtocolError on a bad message)."""
        reader, writer = await asyncio.open_connection(self.host, self.port)
        last = self.clock()
        try:
            while True:
                try:
                    payload = await read_frame(reader, self.idle_timeout)
                except asyncio.IncompleteReadError:
                    return  # the server closed the link
                try:
                    msg = pb.ToOSC.FromString(payload)
                except DecodeError as exc:
                    raise ProtocolError(f"not a ToOSC message: {exc}") from None
                if not msg.HasField("model"):
                    raise ProtocolError("ToOSC without its required model")
                arm = self._load(msg)
                valves = np.array(msg.valveSignals)
                if valves.shape != (arm.dof,) or not np.all(np.isfinite(valves)):
                    raise ProtocolError(f"{len(valves)} valve signals for {arm.dof} joints")
                now = self.clock()
                dt, last = min(now - last, 0.1), now
                # sub-steps of at most 5 ms keep the lag's integration stable
                for _ in range(max(1, math.ceil(dt / 0.005))):
                    self.step(valves, dt / max(1, math.ceil(dt / 0.005)))
                unit = _units(arm)
                reply = pb.ToAAUC(jointAngles=(self.q / unit).tolist(),
                                  jointVelocities=(self.qdot / unit).tolist())  # fmt: skip
                writer.write(encode_frame(reply))
                await writer.drain()
                self.messages += 1
        finally:
            writer.close()
            with contextlib.suppress(OSError):
                await writer.wait_closed()
