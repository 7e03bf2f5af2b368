"""`kvp web` without a browser: the KVP_JOG program, the jog controller and the WebSocket server.

Everything runs over real TCP: the emulator runs the shipped KVP_JOG program, the web server
talks KVP to it, and the test talks WebSocket to the server like the page does. The stop
bounds are checked in the emulator's simulated time (load on the machine cannot change them);
wall-clock stop latencies are measured by bench/web_jog.py.
"""

from __future__ import annotations

import asyncio
import json
import socket
from collections.abc import AsyncIterator
from typing import Any

import numpy as np
import pytest
import websockets
from hypothesis import given
from hypothesis import strategies as st
from pyopenshowvar_apps.web.jogplan import (
    AXIS_KEYS,
    AXIS_SPEED,
    CADENCE,
    CART_KEYS,
    JogRequest,
    plan_jog,
)
from pyopenshowvar_apps.web.runner import KRL_DIR, WebServer
from websockets.asyncio.client import ClientConnection, connect

from kukavarproxy_emu import Emulator, EmulatorConfig
from pyopenshowvar import Client
from pyopenshowvar.kinematics import KR6R900SIXX

TOKEN = "test-token-123"
JOG = {"t": "jog", "press": 1, "frame": "axis", "key": "A1", "dir": 1, "ov": 100}
#: Degrees within which an axis counts as standing still: a dynamic plant's encoders are noisy
#: and its servos' integral action creeps the last hundredths of a degree in slowly.
STILL = 1e-3
#: What a stopped axis may still creep afterwards (deg) under a dynamic plant.
CREEP = 0.02


def jog_config(**kw: Any) -> EmulatorConfig:
    return EmulatorConfig(
        port=0,
        program=str(KRL_DIR / "kvp_jog.src"),
        config_files=(KRL_DIR / "kvp_jog_config.dat",),
        **kw,
    )


#: The keep-alive timeout of tests that are not about it: a loaded machine may hold the test's
#: own event loop (which sends the keep-alives) longer than the pad's 100 ms; the silent-page
#: test sets the real one back.
LENIENT_HOLD = 0.5


@pytest.fixture
async def rig() -> AsyncIterator[tuple[Emulator, WebServer]]:
    async with (
        Emulator(jog_config()) as emu,
        WebServer("127.0.0.1", emu.port, token=TOKEN, emulated=True) as web,
    ):
        web.jog.hold_timeout = LENIENT_HOLD
        yield emu, web


async def page(web: WebServer) -> ClientConnection:
    # max_queue=None: a test that does not read every state must still see the close frame
    ws = await connect(f"ws://127.0.0.1:{web.port}/ws?token={TOKEN}", max_queue=None)
    hello = json.loads(await ws.recv())
    assert hello["t"] == "hello" and hello["emulated"] is True
    return ws


async def until(predicate: Any, timeout: float = 5.0) -> None:
    async with asyncio.timeout(timeout):
        while not await predicate():  # noqa: ASYNC110 - polling a browser or KVP is what a client does
            await asyncio.sleep(0.01)


async def hold(ws: ClientConnection, seconds: float, msg: dict[str, Any] = JOG) -> None:
    """Press and keep the button down like the page: a keep-alive every 25 ms."""
    end = asyncio.get_running_loop().time() + seconds
    while asyncio.get_running_loop().time() < end:
        await ws.send(json.dumps(msg))
        await asyncio.sleep(0.025)


async def settled(kvp: Client) -> float:
    """A1 once the robot stands still (all axes) and the jog program is idle again."""

    async def idle() -> bool:
        return await kvp.read("JOG_MODE") == "0"

    await until(idle)
    a, b = np.zeros(6), np.ones(6)
    while np.max(np.abs(a - b)) > STILL:
        a = await kvp.read_joint_angles()
        await asyncio.sleep(0.05)
        b = await kvp.read_joint_angles()
    return float(b[0])


# --- the arithmetic of one press (pure) -----------------------------------------------------
@given(
    frame=st.sampled_from(["axis", "base", "tool"]),
    index=st.integers(0, 5),
    direction=st.sampled_from([-1, 1]),
    ov=st.floats(1, 100),
    step=st.none() | st.sampled_from([0.1, 1.0, 10.0]),
)
def test_plan_keeps_cadence_and_limits(
    frame: str, index: int, direction: int, ov: float, step: float | None
) -> None:
    keys = AXIS_KEYS if frame == "axis" else CART_KEYS
    req = JogRequest(frame, keys[index], direction, step, ov)  # type: ignore[arg-type]
    plan = plan_jog(req, KR6R900SIXX)
    inc = plan.increment
    assert np.count_nonzero(inc) == 1 and np.sign(inc[index]) == direction
    if step is not None:  # step mode: equal increments adding up to exactly the step
        assert plan.count is not None and abs(abs(inc[index]) * plan.count - step) < 1e-9
    if frame == "axis":
        acc, a_max = plan.acc[0], KR6R900SIXX.max_accel[index]
        assert 1 <= acc <= 100
        # A triangular increment at this acceleration lasts ~2 cadences (INT % rounding aside)
        if acc >= 5 and step is None:
            t = np.sqrt(abs(inc[index]) / (a_max * acc / 100))
            assert abs(t - CADENCE) < 0.1 * CADENCE
    writes = plan.start_writes(plan.until(100, 100, 5))
    assert writes[-1] == ("JOG_MODE", str(plan.mode)) and writes[-2][0] == "JOG_UNTIL"
    # never more than the credit ahead of the count, and never past the end of a step
    assert plan.until(100, 103, 5) == (108 if step is None else min(108, 100 + plan.count))
    assert plan.stop_writes()[0][0] == plan.target  # the increment is zeroed first


def test_axis_speeds_stop_within_one_cadence() -> None:
    # Every jog speed can be braked to zero within one cadence at the axis' acceleration limit.
    assert np.all(np.array(AXIS_SPEED) <= KR6R900SIXX.max_accel * CADENCE)


@pytest.mark.parametrize(
    ("kw", "error"),
    [
        ({"frame": "joint", "key": "A1"}, "frame"),
        ({"frame": "axis", "key": "X"}, "keys"),
        ({"frame": "base", "key": "X", "direction": 0}, "direction"),
        ({"frame": "base", "key": "X", "step": 50.0}, "step"),
        ({"frame": "tool", "key": "C", "override": 0.0}, "override"),
    ],
)
def test_bad_requests_are_refused(kw: dict[str, Any], error: str) -> None:
    kw.setdefault("direction", 1)
    with pytest.raises(ValueError, match=error):
        JogRequest(**kw)


# --- the KRL program on the emulator --------------------------------------------------------
async def test_krl_stop_bound_in_simulated_time() -> None:
    """After the PC zeroes the increment the robot moves for at most 3 cadences + 1 IPO; and
    when the PC falls silent it plans nothing past JOG_UNTIL (the robot's own watchdog)."""
    async with Emulator(jog_config()) as emu, Client("127.0.0.1", emu.port) as kvp:
        robot = emu.robot
        assert robot is not None
        plan = plan_jog(JogRequest("axis", "A1", 1, None, 100.0), KR6R900SIXX)
        await asyncio.sleep(0.1)  # KVP_JOG voids any left-over JOG_UNTIL when it starts
        count = int(await kvp.read("JOG_COUNT"))
        await kvp.write_many(plan.start_writes(count + 5))
        for _ in range(15):
            count = int(await kvp.read("JOG_COUNT"))
            await kvp.write("JOG_UNTIL", str(count + 5))
            await asyncio.sleep(0.04)
        robot.kernel.trace = []
        await kvp.write_many(plan.stop_writes())
        t_zero = robot.time
        await asyncio.sleep(0.3)
        moving = [t for t, _, qd in robot.kernel.trace if np.any(np.abs(qd) > 1e-9)]
        assert moving, "the robot was not moving when the stop was written"
        assert moving[-1] - t_zero <= 3 * CADENCE + robot.kernel.ipo + 1e-9
        # ... and on its own when the PC stops moving JOG_UNTIL on (the robot's watchdog)
        count = int(await kvp.read("JOG_COUNT"))
        await kvp.write_many(plan.start_writes(count + 5))
        robot.kernel.trace = []
        t_silent = robot.time
        await asyncio.sleep(0.5)
        moving = [t for t, _, qd in robot.kernel.trace if np.any(np.abs(qd) > 1e-9)]
        assert moving and moving[-1] - t_silent <= (5 + 2) * CADENCE + 2 * robot.kernel.ipo
        assert await kvp.read("JOG_COUNT") == str(count + 5)  # exactly the 5 it was allowed


async def test_tool_increment_runs_in_the_tcp_frame(tmp_path: Any) -> None:
    """``LIN_REL … #TOOL`` (needed by the Tool jog) moves along the TCP's own axes."""
    src = tmp_path / "tooljog.src"
    src.write_text(
        "DEF TOOLJOG()\n  PTP {A1 0, A2 -90, A3 90, A4 0, A5 30, A6 0}\n"
        "  LIN_REL {X 10.0} #TOOL\n  DONE = TRUE\nEND\n"
    )
    (tmp_path / "tooljog.dat").write_text("DEFDAT TOOLJOG\nDECL BOOL DONE=FALSE\nENDDAT\n")
    async with Emulator(EmulatorConfig(port=0, program=str(src), speed=20)) as emu:
        async with Client("127.0.0.1", emu.port) as kvp:

            async def done() -> bool:
                return await kvp.read("DONE") == "TRUE" and not emu.robot.kernel.moving  # type: ignore[union-attr]

            await until(done)
            before, pose = None, await kvp.read_pose()
            while before is None or abs(pose.x - before.x) + abs(pose.z - before.z) > 1e-3:
                await asyncio.sleep(0.05)  # a dynamic plant's servos settle after the set-point
                before, pose = pose, await kvp.read_pose()
    from pyopenshowvar.kinematics import fk_matrix

    start = fk_matrix(KR6R900SIXX, [0, -90, 90, 0, 30, 0])
    expected = start[:3, 3] + 10.0 * start[:3, 0]  # 10 mm along the flange's own x axis
    assert np.allclose([pose.x, pose.y, pose.z], expected, atol=0.01)


# --- through the web server, like the page --------------------------------------------------
async def test_jog_moves_and_stops_on_release(rig: tuple[Emulator, WebServer]) -> None:
    emu, web = rig
    async with Client("127.0.0.1", emu.port) as kvp:
        ws = await page(web)
        await hold(ws, 0.4)
        assert await kvp.read("JOG_MODE") == "1"
        await ws.send(json.dumps({"t": "release"}))
        a1 = await settled(kvp)
        assert a1 > 0.5, "A1 did not move"
        await asyncio.sleep(0.1)
        assert (await kvp.read_joint_angles())[0] == pytest.approx(a1, abs=CREEP)
        # The same press does not start again: its keep-alives after release are ignored
        await hold(ws, 0.1)
        assert await kvp.read("JOG_MODE") == "0"
        await ws.close()


async def test_dropped_connection_and_silent_page_stop_the_jog(
    rig: tuple[Emulator, WebServer],
) -> None:
    emu, web = rig
    async with Client("127.0.0.1", emu.port) as kvp:
        web.jog.hold_timeout = 5.0  # only the drop itself may stop this jog (a loaded machine)
        ws = await page(web)
        await hold(ws, 0.3)
        ws.transport.abort()  # the TCP connection drops without a closing handshake
        a1 = await settled(kvp)
        assert a1 > 0.1 and web.jog.last_stop is not None
        assert "lost" in web.jog.last_stop[0]
        web.jog.hold_timeout = 0.1
        ws = await page(web)  # a page that freezes: no release, no keep-alive
        await ws.send(json.dumps({**JOG, "press": 2}))
        await settled(kvp)
        assert web.jog.last_stop is not None and "keep-alive" in web.jog.last_stop[0]
        await ws.close()


async def test_step_mode_moves_exactly_one_step(rig: tuple[Emulator, WebServer]) -> None:
    emu, web = rig
    async with Client("127.0.0.1", emu.port) as kvp:
        ws = await page(web)
        await hold(ws, 0.8, {**JOG, "key": "A6", "dir": -1, "step": 1.0})
        await ws.send(json.dumps({"t": "release"}))
        await settled(kvp)
        q = await kvp.read_joint_angles()
        assert q[5] == pytest.approx(-1.0, abs=1e-3)
        assert web.jog.last_stop is not None and web.jog.last_stop[0] == "step done"
        await ws.close()


async def test_cartesian_jogs_move_along_base_and_tool_axes(
    rig: tuple[Emulator, WebServer],
) -> None:
    emu, web = rig
    async with Client("127.0.0.1", emu.port) as kvp:
        # Out of the wrist singularity of HOME (A5 = 0) first: a 10 degree A5 step.
        plan = plan_jog(JogRequest("axis", "A5", 1, 10.0, 100.0), KR6R900SIXX)
        assert plan.count is not None
        await asyncio.sleep(0.1)  # KVP_JOG voids any left-over JOG_UNTIL when it starts
        start = int(await kvp.read("JOG_COUNT"))
        await kvp.write_many(plan.start_writes(start + plan.count))
        async with asyncio.timeout(5):
            while await kvp.read("JOG_COUNT") != str(start + plan.count) or emu.robot.kernel.moving:  # type: ignore[union-attr]  # noqa: ASYNC110
                await asyncio.sleep(0.02)
        await kvp.write_many(plan.stop_writes())
        await asyncio.sleep(0.1)  # the pad sees the new pose
        start = await kvp.read_pose()
        ws = await page(web)
        await hold(ws, 0.3, {**JOG, "press": 1, "frame": "base", "key": "X"})
        await ws.send(json.dumps({"t": "release"}))
        await settled(kvp)
        moved = await kvp.read_pose()
        assert moved.x - start.x > 5.0
        assert abs(moved.y - start.y) < 0.05 and abs(moved.z - start.z) < 0.05
        assert abs(moved.b - start.b) < CREEP
        from pyopenshowvar.kinematics import pose_to_matrix

        axes = pose_to_matrix([moved.x, moved.y, moved.z, moved.a, moved.b, moved.c])
        await hold(ws, 0.3, {**JOG, "press": 2, "frame": "tool", "key": "Z"})
        await ws.send(json.dumps({"t": "release"}))
        await settled(kvp)
        end = await kvp.read_pose()
        delta = np.array([end.x - moved.x, end.y - moved.y, end.z - moved.z])
        assert np.linalg.norm(delta) > 5.0
        assert np.allclose(delta / np.linalg.norm(delta), axes[:3, 2], atol=1e-2)  # tool z
        await ws.close()


async def test_jog_stops_before_the_software_limit() -> None:
    config = jog_config()
    async with Emulator(config) as emu:
        emu.store.set_system("$SOFTP_END[1]", 3.0)
        async with (
            WebServer("127.0.0.1", emu.port, token=TOKEN, emulated=True) as web,
            Client("127.0.0.1", emu.port) as kvp,
        ):
            web.jog.hold_timeout = LENIENT_HOLD
            await until(lambda: _true(web.link.seq > 2))
            ws = await page(web)
            await hold(ws, 0.8)
            a1 = await settled(kvp)
            assert 1.0 < a1 <= 3.0 - 0.5 + 1e-6  # stops short of the limit, with the margin
            assert await kvp.read("$PRO_STATE1") == "#P_ACTIVE"  # no limit-switch stop
            assert web.jog.last_stop is not None and "limit" in web.jog.last_stop[0]
            await ws.close()


async def test_jog_limit_uses_a_fresh_axis_sample_not_the_live_view() -> None:
    """The page's live view may lag (here it polls twice a second): the room left before the
    software limit is computed from $AXIS_ACT read together with JOG_COUNT, so a stale view
    cannot carry the robot past the margin."""
    config = jog_config()
    async with Emulator(config) as emu:
        emu.store.set_system("$SOFTP_END[1]", 3.0)
        async with (
            WebServer("127.0.0.1", emu.port, token=TOKEN, emulated=True, hz=2.0) as web,
            Client("127.0.0.1", emu.port) as kvp,
        ):
            web.jog.hold_timeout = LENIENT_HOLD
            await until(lambda: _true(web.link.seq > 1))
            ws = await page(web)
            await hold(ws, 1.5)
            a1 = await settled(kvp)
            assert 1.0 < a1 <= 3.0 - 0.5 + 1e-6
            assert web.jog.last_stop is not None and "limit" in web.jog.last_stop[0]
            await ws.close()


async def _true(value: bool) -> bool:
    return value


async def test_live_state_watch_list_and_writes(rig: tuple[Emulator, WebServer]) -> None:
    _, web = rig
    ws = await page(web)
    await ws.send(json.dumps({"t": "watch", "names": ["MYINT", "NOPE_VAR"]}))
    await ws.send(json.dumps({"t": "write", "id": 7, "name": "MYINT", "value": "55"}))
    seen: dict[str, Any] = {}
    async with asyncio.timeout(5):
        while "NOPE_VAR" not in seen or seen.get("MYINT", {}).get("text") != "55":
            msg = json.loads(await ws.recv())
            if msg["t"] == "state" and msg["link"]["connected"]:
                assert len(msg["axes"]) == 6 and len(msg["arm"]) == 8
                assert msg["program"]["name"] == "KVP_JOG" and msg["program"]["jog_ready"] is None
                seen.update(msg["watch"])
            elif msg["t"] == "result":
                assert msg == {"t": "result", "id": 7, "name": "MYINT", "text": "55"}
    assert seen["NOPE_VAR"]["error"]
    await ws.close()


async def ask(ws: ClientConnection, msg: dict[str, Any]) -> dict[str, Any]:
    """Send one request and return its answer (a result, an error or a refusal)."""
    await ws.send(json.dumps(msg))
    async with asyncio.timeout(5):
        while True:
            answer = json.loads(await ws.recv())
            if answer.get("t") in ("result", "error", "refused"):
                return dict(answer)


async def test_watch_list_writes_get_kvp_writes_checks() -> None:
    """The same checks as `kvp write`: the literal before sending, the likely reason of a
    refusal after; motion variables only with --allow-motion-writes."""
    async with Emulator(jog_config()) as emu, Client("127.0.0.1", emu.port) as kvp:
        for allow in (False, True):
            async with WebServer(
                "127.0.0.1", emu.port, token=TOKEN, emulated=True, allow_motion_writes=allow
            ) as web:
                ws = await page(web)
                answer = await ask(ws, {"t": "write", "id": 1, "name": "MYINT", "value": "{A1 2"})
                assert answer["t"] == "error" and "not a KRL literal" in answer["message"]
                answer = await ask(ws, {"t": "write", "id": 2, "name": "MYINT", "value": "1.5"})
                assert answer["id"] == 2 and answer["error"].startswith("write refused: 'MYINT'")
                assert "wrong type: the variable is INT" in answer["error"]
                answer = await ask(ws, {"t": "write", "id": 3, "name": "$OV_PRO", "value": "40"})
                if allow:
                    assert answer == {"t": "result", "id": 3, "name": "$OV_PRO", "text": "40"}
                    assert await kvp.read("$OV_PRO") == "40"
                else:
                    assert answer["error"] == (
                        "writing $OV_PRO can move the robot or change how it moves: refused"
                        " unless kvp web runs with --allow-motion-writes"
                    )
                    assert await kvp.read("$OV_PRO") == "100"
                answer = await ask(ws, {"t": "write", "id": 4, "name": "JOG_MODE", "value": "1"})
                assert answer["error"] == (
                    "JOG_MODE belongs to the jog program: only the server's jog logic writes it"
                )
                await ws.close()


# --- security and abuse ---------------------------------------------------------------------
@pytest.mark.parametrize(
    ("query", "headers"),
    [("", {}), ("?token=wrong-token", {}), (f"?token={TOKEN}", {"Origin": "http://evil.example"})],
)
async def test_websocket_refused_without_token_or_from_elsewhere(
    rig: tuple[Emulator, WebServer], query: str, headers: dict[str, str]
) -> None:
    _, web = rig
    with pytest.raises(websockets.exceptions.InvalidStatus) as info:
        await connect(f"ws://127.0.0.1:{web.port}/ws{query}", additional_headers=headers)
    assert info.value.response.status_code == 403


async def test_abuse_is_bounded(rig: tuple[Emulator, WebServer]) -> None:
    _, web = rig
    ws = await page(web)
    await ws.send(json.dumps({"t": "read", "id": 1, "name": "x" * 500}))
    await ws.send(json.dumps({"t": "nope"}))  # a JSON object a page does not send: an error
    await ws.send(json.dumps({"t": "jog", "press": 1, "frame": "axis", "key": "Q9", "dir": 1}))
    errors = 0
    async with asyncio.timeout(20):
        while errors < 3:
            errors += json.loads(await ws.recv())["t"] == "error"
    big = await page(web)
    await big.send("x" * 10_000)  # larger than MAX_MESSAGE: the connection is closed
    with pytest.raises(websockets.exceptions.ConnectionClosed):
        async with asyncio.timeout(20):
            while True:
                await big.recv()
    flood = await page(web)
    with pytest.raises(websockets.exceptions.ConnectionClosed):
        async with asyncio.timeout(20):
            for _ in range(5000):  # far beyond the per-connection message budget
                await flood.send('{"t": "watch", "names": []}')
            while True:
                await flood.recv()
    # The well-behaved page is still served
    async with asyncio.timeout(20):
        while json.loads(await ws.recv())["t"] != "state":
            pass
    await ws.close()


async def test_a_robot_that_is_not_there_shows_as_a_state() -> None:
    """The state of a link that is connecting or lost is a ``state`` message too: the page
    shows only those (its banner says why the robot is not there)."""
    with socket.socket() as free:  # a port nobody listens on
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    async with WebServer("127.0.0.1", port, token=TOKEN, emulated=True) as web:
        ws = await page(web)
        async with asyncio.timeout(10):
            state = json.loads(await ws.recv())
        assert state["t"] == "state" and state["link"]["connected"] is False, state
        assert state["link"]["error"], state
        await ws.close()


async def test_loopback_without_token_refuses_other_host_names() -> None:
    """No token on loopback, but a page that re-points its own name here (DNS rebinding) or
    comes from elsewhere gets nothing."""
    async with Emulator(jog_config()) as emu, WebServer("127.0.0.1", emu.port) as web:
        for request in (
            "GET / HTTP/1.1\r\nHost: evil.example:80\r\n",
            "GET /ws HTTP/1.1\r\nHost: evil.example\r\nOrigin: http://evil.example\r\n"
            "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 13\r\n"
            "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n",
        ):
            reader, writer = await asyncio.open_connection("127.0.0.1", web.port)
            writer.write(request.encode() + b"\r\n")
            assert (await reader.readline()).startswith(b"HTTP/1.1 400")
            writer.close()
        ws = await connect(f"ws://127.0.0.1:{web.port}/ws")  # the real page: no token needed
        assert json.loads(await ws.recv())["t"] == "hello"
        await ws.close()
