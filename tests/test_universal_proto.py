"""The protobuf link (thesis §4.2.1): the thesis' messages over TCP, the stand-in simulator, and
peers that break the protocol (a clear error, never a hang)."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Callable

import numpy as np
import pytest
from pyopenshowvar_apps.universal import universal_pb2 as pb
from pyopenshowvar_apps.universal.backend import BackendError
from pyopenshowvar_apps.universal.inputs import ScriptedInput, hold
from pyopenshowvar_apps.universal.protolink import (
    MAX_FRAME,
    ProtoArm,
    ProtocolError,
    StandInSimulator,
    encode_frame,
    model_id,
    read_frame,
)
from pyopenshowvar_apps.universal.server import ControlServer

from pyopenshowvar.arms import catalogue, load_arm

CRANE = load_arm("knuckle_boom_crane")


def test_the_messages_are_the_thesis_schema() -> None:
    # Algorithm 4.1: ToOSC {required int32 model = 1; optional string modelName = 2;
    # repeated double valveSignals = 3 [packed]}, ToAAUC {repeated double jointAngles = 1,
    # jointVelocities = 2 [packed]}
    fields = {f.name: (f.number, f.type) for f in pb.ToOSC.DESCRIPTOR.fields}
    d = pb.ToOSC.DESCRIPTOR.fields_by_name
    assert fields["model"][0] == 1 and d["model"].is_required
    assert fields["modelName"][0] == 2 and not d["modelName"].is_repeated
    assert fields["valveSignals"][0] == 3 and d["valveSignals"].is_repeated
    assert d["valveSignals"].is_packed
    r = pb.ToAAUC.DESCRIPTOR.fields_by_name
    assert r["jointAngles"].number == 1 and r["jointVelocities"].number == 2
    assert r["jointAngles"].is_packed and r["jointVelocities"].is_packed
    msg = pb.ToOSC(model=2, modelName="knuckle_boom_crane", valveSignals=[0.5, -1.0, 0.0])
    frame = encode_frame(msg)
    assert int.from_bytes(frame[:4], "big") == len(frame) - 4
    assert pb.ToOSC.FromString(frame[4:]) == msg
    with pytest.raises(Exception, match="required"):
        pb.ToOSC(valveSignals=[1.0]).SerializeToString()  # no model: not well-formed


async def _reader_of(data: bytes) -> asyncio.StreamReader:
    reader = asyncio.StreamReader()
    reader.feed_data(data)
    reader.feed_eof()
    return reader


async def test_frames_are_bounded_and_reads_time_out() -> None:
    reader = await _reader_of((MAX_FRAME + 1).to_bytes(4, "big") + b"x" * 16)
    with pytest.raises(ProtocolError, match="bytes"):
        await read_frame(reader, 1.0)
    reader = await _reader_of((10).to_bytes(4, "big") + b"abc")
    with pytest.raises(asyncio.IncompleteReadError):
        await read_frame(reader, 1.0)
    silent = asyncio.StreamReader()
    with pytest.raises(TimeoutError):
        await read_frame(silent, 0.05)


async def test_round_trip_against_the_stand_in_simulator() -> None:
    backend = ProtoArm(CRANE, timeout=2.0)
    port = await backend.listen()
    sim = StandInSimulator("127.0.0.1", port)
    task = asyncio.create_task(sim.run())
    try:
        state = await backend.start()
        assert np.allclose(state.q, CRANE.home_q) and np.allclose(state.qdot, 0.0)
        assert sim.arm is CRANE and model_id(CRANE) == catalogue().index(CRANE.key) + 1
        for _ in range(40):  # open the slew valve halfway for 40 exchanges
            await backend.command(np.array([15.0, 0.0, 0.0]), 0.02)
            await asyncio.sleep(0.01)
        state = await backend.feedback()
        assert state.q[0] > CRANE.home_q[0] + 1.0 and state.qdot[0] > 1.0
        assert np.allclose(state.q[1:], CRANE.home_q[1:])
        # the server switches the model over the link (modelName selects the arm)
        cobra = load_arm("adept_cobra600")
        state = await backend.set_arm(cobra)
        assert sim.arm is cobra and state.q.shape == (4,)
        assert np.allclose(state.q, cobra.home_q)
        assert backend.exchanges == sim.messages
    finally:
        await backend.close()
        await asyncio.wait_for(task, 2.0)  # the stand-in ends when the server hangs up


async def test_the_server_drives_the_crane_through_the_link() -> None:
    backend = ProtoArm(CRANE, timeout=2.0)
    port = await backend.listen()
    task = asyncio.create_task(StandInSimulator("127.0.0.1", port).run())
    device = ScriptedInput(hold((0.3, 0.3, 0.0)), duration=1.0)
    server = ControlServer(backend, device, solver="closed-form", mode="velocity")
    try:
        await server.start()
        tip0 = server.solver.fk(server.state.q)  # type: ignore[union-attr]
        await server.run(1.5)
        tip = server.solver.fk((await backend.feedback()).q)
        moved = tip - tip0
        # the tip went out along +x +y (eq. 2.8), and the simulator's joints report it back
        assert moved[0] > 100.0 and moved[1] > 100.0 and abs(moved[2]) < 0.3 * moved[1]
    finally:
        await server.close()
        await asyncio.wait_for(task, 2.0)


Peer = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]


async def _broken_peer(behaviour: Peer) -> tuple[ProtoArm, asyncio.Task[None]]:
    backend = ProtoArm(CRANE, timeout=0.3, accept_timeout=2.0)
    port = await backend.listen()

    async def connect() -> None:
        r, w = await asyncio.open_connection("127.0.0.1", port)
        try:
            await behaviour(r, w)
        finally:
            w.close()

    return backend, asyncio.create_task(connect())


async def _answer(r: asyncio.StreamReader, w: asyncio.StreamWriter, reply: bytes) -> None:
    await read_frame(r, 2.0)
    w.write(reply)
    await w.drain()
    await asyncio.sleep(1.0)


@pytest.mark.parametrize(
    ("reply", "error"),
    [
        ((MAX_FRAME + 5).to_bytes(4, "big"), "bytes"),
        ((4).to_bytes(4, "big") + b"\xff\xff\xff\xff", "not a ToAAUC"),
        (encode_frame(pb.ToAAUC(jointAngles=[0.0, 0.1], jointVelocities=[0.0, 0.0])), "3 joints"),
        (
            encode_frame(pb.ToAAUC(jointAngles=[0, 0, math.nan], jointVelocities=[0, 0, 0])),
            "non-finite",
        ),
        (b"", "did not answer"),
    ],
)
async def test_a_broken_simulator_is_a_clear_error(reply: bytes, error: str) -> None:
    backend, peer = await _broken_peer(lambda r, w: _answer(r, w, reply))
    try:
        with pytest.raises(BackendError, match=error):
            await backend.start()
    finally:
        await backend.close()
        peer.cancel()
        await asyncio.gather(peer, return_exceptions=True)


async def test_no_simulator_is_a_clear_error() -> None:
    backend = ProtoArm(CRANE, accept_timeout=0.1)
    await backend.listen()
    with pytest.raises(BackendError, match="no simulator connected"):
        await backend.start()
    await backend.close()


@pytest.mark.parametrize(
    ("message", "error"),
    [
        (b"\x00\x00\x00\x03\xff\xff\xff", "not a ToOSC"),
        (encode_frame(pb.ToOSC(model=999)), "unknown model 999"),
        (encode_frame(pb.ToOSC(model=1, modelName="nosuch")), "unknown model name"),
        (
            encode_frame(pb.ToOSC(model=1, modelName="knuckle_boom_crane", valveSignals=[1.0])),
            "1 valve signals",
        ),
        (b"\x00\x00\x00\x00", "without its required model"),  # an empty ToOSC
    ],
)
async def test_the_stand_in_refuses_bad_messages(message: bytes, error: str) -> None:
    async def serve(r: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
        w.write(message)
        await w.drain()
        await r.read()  # until the stand-in hangs up
        w.close()

    server = await asyncio.start_server(serve, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    try:
        with pytest.raises(ProtocolError, match=error):
            await asyncio.wait_for(StandInSimulator("127.0.0.1", port, idle_timeout=1.0).run(), 3.0)
    finally:
        server.close()
        await server.wait_closed()
