"""`kvp web` against hostile pages and HTTP clients, over real sockets (emulator + server).

* an authorised page that writes the jog program's own variables (and every other way to move
  the robot the watch list offers), then vanishes: the robot never moves; a page that
  vanishes mid-jog: the robot stops within the jog's stop bound;
* slowloris and connection floods: a page from another address still loads at once;
* crafted messages: a clean close with a reason, never a traceback; pages going away in the
  middle of a jog: no traceback either.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections.abc import AsyncIterator, Iterator

import numpy as np
import pytest
from pyopenshowvar_apps.web.abuse import (
    CRAFTED,
    ROGUE_WRITES,
    AttackTally,
    closing_pages,
    crafted,
    page_load,
    rogue_page,
    slowloris,
)
from pyopenshowvar_apps.web.jogplan import CADENCE
from pyopenshowvar_apps.web.runner import WebServer
from test_web_jog import JOG, STILL, TOKEN, ask, hold, jog_config, page, settled, until
from websockets.asyncio.client import connect

from kukavarproxy_emu import Emulator
from pyopenshowvar import Client

MOTION = "can move the robot or change how it moves: refused unless kvp web runs with --allow-motion-writes"
JOG_OWN = "belongs to the jog program: only the server's jog logic writes it"
#: Every write a page could try to move the robot with, and the refusal it gets.
ROGUE: list[tuple[str, str, str]] = [
    *((name, value, f"{name} {JOG_OWN}") for name, value in ROGUE_WRITES),
    ("jog_mode", "1", f"JOG_MODE {JOG_OWN}"),
    ("JOG_AX.A1", "2", f"JOG_AX {JOG_OWN}"),
    ("JOG_FR", "{X 5}", f"JOG_FR {JOG_OWN}"),
    ("JOG_COUNT", "-100", f"JOG_COUNT {JOG_OWN}"),
    ("JOG_ACC_CP", "9.0", f"JOG_ACC_CP {JOG_OWN}"),
    ("JOG_ACC_ORI", "900.0", f"JOG_ACC_ORI {JOG_OWN}"),
    ("$OV_PRO", "100", f"writing $OV_PRO {MOTION}"),
    ("$SOFTP_END[1]", "170", f"writing $SOFTP_END {MOTION}"),
    ("$OUT[1]", "TRUE", f"writing $OUT {MOTION}"),
    ("OUTPUT_VARS[1]", "TRUE", f"writing OUTPUT_VARS {MOTION}"),
    ("MYAXIS", "{A1 30}", f"writing MYAXIS {MOTION}"),
    ("EMU_WRENCH", "{X 100}", f"writing EMU_WRENCH {MOTION}"),
    ("EMU_RESTART", "TRUE", "use the Restart program button"),
]


@pytest.fixture
async def rig() -> AsyncIterator[tuple[Emulator, WebServer, Client]]:
    async with (
        Emulator(jog_config()) as emu,
        WebServer("127.0.0.1", emu.port, token=TOKEN, emulated=True) as web,
        Client("127.0.0.1", emu.port) as kvp,
    ):
        await until(lambda: _ready(web))
        yield emu, web, kvp


async def _ready(web: WebServer) -> bool:
    return web.link.jog_ready() is None


def ws_url(web: WebServer) -> str:
    return f"ws://127.0.0.1:{web.port}/ws?token={TOKEN}"


# --- item: nothing moves without a held button ------------------------------------------------
async def test_a_rogue_page_that_vanishes_leaves_the_robot_still(
    rig: tuple[Emulator, WebServer, Client],
) -> None:
    _emu, web, kvp = rig
    count, q0 = await kvp.read("JOG_COUNT"), await kvp.read_joint_angles()
    writes = tuple((name, value) for name, value, _ in ROGUE)
    answers = await rogue_page(ws_url(web), writes, vanish="abort")
    assert [a.get("error") for a in answers] == [why for _, _, why in ROGUE]
    await asyncio.sleep(0.3)  # what the writes would have started (2 deg per 20 ms on A1)
    assert await kvp.read("JOG_COUNT") == count and await kvp.read("JOG_MODE") == "0"
    assert await kvp.read("JOG_ACC") == "10" and await kvp.read("$OV_PRO") == "100"
    assert np.max(np.abs(await kvp.read_joint_angles() - q0)) < STILL
    assert web.jog.jog is None


async def test_motion_writes_allowed_by_the_flag_still_spare_the_jog_program() -> None:
    async with (
        Emulator(jog_config()) as emu,
        WebServer("127.0.0.1", emu.port, token=TOKEN, allow_motion_writes=True) as web,
    ):
        writes = tuple((name, value) for name, value, _ in ROGUE[:10])
        answers = await rogue_page(ws_url(web), writes)
        assert [a.get("error") for a in answers] == [why for _, _, why in ROGUE[:10]]


async def test_a_page_vanishing_mid_jog_stops_the_robot(
    rig: tuple[Emulator, WebServer, Client],
) -> None:
    """Dropped without a close: the server zeroes the increment at once, and the robot then
    moves for at most the jog's stop bound (3 cadences + 1 IPO, in simulated time)."""
    emu, web, kvp = rig
    robot = emu.robot
    assert robot is not None
    web.jog.hold_timeout = 5.0  # only the drop may stop this jog (a loaded machine)
    ws = await page(web)
    await hold(ws, 0.3)
    assert await kvp.read("JOG_MODE") == "1"
    robot.kernel.trace = []
    zero_at: list[float] = []
    tick = robot.clock.callback

    def sampled_tick() -> None:  # the first cycle that sees the zero increment
        if not zero_at and emu.store.get("JOG_AX")["A1"] == 0.0:  # type: ignore[index]
            zero_at.append(robot.time)
        tick()

    robot.clock.callback = sampled_tick
    dropped, t_drop = robot.time, time.monotonic()
    ws.transport.abort()
    await settled(kvp)
    robot.clock.callback = tick
    assert web.jog.last_stop is not None and "lost" in web.jog.last_stop[0]
    assert web.jog.last_stop[1] - t_drop < 1.0  # the server noticed the drop at once
    moving = [t for t, _, qd in robot.kernel.trace if np.any(np.abs(qd) > 1e-9)]
    assert zero_at and moving and zero_at[0] >= dropped
    assert moving[-1] - zero_at[0] <= 3 * CADENCE + robot.kernel.ipo + 1e-9


async def test_a_keep_alive_cannot_change_its_button(
    rig: tuple[Emulator, WebServer, Client],
) -> None:
    _emu, web, kvp = rig
    web.jog.hold_timeout = 5.0  # only the changed button may end this press (a loaded machine)
    ws = await page(web)
    await hold(ws, 0.1)
    assert web.jog.jog is not None and web.jog.jog.req.key == "A1"
    answer = await ask(ws, {**JOG, "key": "A2"})  # the same press, another axis
    assert answer == {
        "t": "refused",
        "press": 1,
        "reason": "a held press cannot change its button: press again",
    }
    assert web.jog.jog is None and web.jog.last_stop is not None
    assert web.jog.last_stop[0] == "the press changed its button"
    await settled(kvp)
    await hold(ws, 0.1, {**JOG, "key": "A2"})  # and that press never starts again
    assert web.jog.jog is None and await kvp.read("JOG_MODE") == "0"
    await ws.close()


async def test_the_jog_override_is_clamped_to_the_jog_speeds(
    rig: tuple[Emulator, WebServer, Client],
) -> None:
    _, web, _ = rig
    web.jog.hold_timeout = 5.0  # a loaded machine must not end these presses early
    ws = await page(web)

    async def jogging(press: int) -> bool:
        return web.jog.jog is not None and web.jog.jog.press == press

    await ws.send(json.dumps({**JOG, "ov": 1e300}))
    await until(lambda: jogging(1))
    assert web.jog.jog is not None
    assert web.jog.jog.req.override == 100.0 and web.jog.jog.plan.speed == 15.0
    await ws.send(json.dumps({**JOG, "press": 2, "ov": -5}))
    await until(lambda: jogging(2))
    assert web.jog.jog is not None and web.jog.jog.req.override == 1.0
    await ws.send(json.dumps({"t": "release"}))
    await ws.close()


# --- item: hostile HTTP and WebSocket traffic -------------------------------------------------
class _Records(logging.Handler):
    """Every record with a traceback, from any logger (uvicorn's included)."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.tracebacks: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info or record.levelno >= logging.ERROR:
            self.tracebacks.append(f"{record.name}: {record.getMessage()}")


@pytest.fixture
def tracebacks() -> Iterator[_Records]:
    handler = _Records()
    loggers = [
        logging.getLogger(),
        logging.getLogger("uvicorn"),
        logging.getLogger("uvicorn.error"),
    ]
    for logger in loggers:
        logger.addHandler(handler)
    yield handler
    for logger in loggers:
        logger.removeHandler(handler)


async def test_slowloris_from_one_address_leaves_the_page_loading(
    rig: tuple[Emulator, WebServer, Client],
) -> None:
    """80 sockets from 127.0.0.2 trickle request heads; a page from 127.0.0.1 loads at once."""
    _, web, _ = rig
    base = [await page_load("127.0.0.1", web.port) for _ in range(3)]
    assert all(status == 200 for status, _ in base)
    tally = AttackTally()
    attack = asyncio.create_task(
        slowloris("127.0.0.1", web.port, tally, sockets=80, interval=0.5, source="127.0.0.2")
    )
    try:
        async with asyncio.timeout(10):
            while tally.connections < 80:  # noqa: ASYNC110 - every attacking socket got in once
                await asyncio.sleep(0.02)
        loads = [await page_load("127.0.0.1", web.port) for _ in range(5)]
        assert 0 < len(web.guard.open["127.0.0.2"]) <= web.guard.per_address
    finally:
        attack.cancel()
        await asyncio.gather(attack, return_exceptions=True)
    assert [status for status, _ in loads] == [200] * 5
    assert max(t for _, t in loads) < 1.0
    assert tally.errors == 0 and tally.closed_by_server >= 80 - web.guard.per_address


async def test_a_request_head_must_arrive_in_time(
    rig: tuple[Emulator, WebServer, Client],
) -> None:
    _, web, _ = rig
    web.guard.head_timeout = 0.3
    reader, writer = await asyncio.open_connection("127.0.0.1", web.port)
    t0 = time.monotonic()
    answer = b""
    try:
        for c in b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n":  # one byte every 20 ms, never done
            writer.write(bytes([c]))
            with contextlib.suppress(TimeoutError):
                answer = await asyncio.wait_for(reader.read(100), 0.02)
                break  # the server answered (or closed) before the next byte
    finally:
        writer.close()
    assert answer.startswith(b"HTTP/1.1 408 ")
    # answered after the head timeout, long before the head would have been complete (the
    # upper bound leaves a loaded machine's scheduling delays room)
    assert 0.3 <= time.monotonic() - t0 < 5.0 and web.guard.timed_out == 1
    # a keep-alive connection gets the same time for its next request head, then is closed
    reader, writer = await asyncio.open_connection("127.0.0.1", web.port)
    writer.write(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
    first = await asyncio.wait_for(reader.readuntil(b"</html>"), 2.0)
    assert first.startswith(b"HTTP/1.1 200 ")
    rest = (await asyncio.wait_for(reader.read(), 2.0)).lstrip()  # closed by the server
    writer.close()
    assert rest == b"" or rest.startswith(b"HTTP/1.1 408 ")


async def test_connection_caps_per_address_and_in_all(
    rig: tuple[Emulator, WebServer, Client],
) -> None:
    _, web, _ = rig
    guard = web.guard
    guard.per_address, guard.total = 3, 5
    held = [await asyncio.open_connection("127.0.0.1", web.port, local_addr=("127.0.0.3", 0))]
    held += [await asyncio.open_connection("127.0.0.1", web.port, local_addr=("127.0.0.3", 0))
             for _ in range(2)]  # fmt: skip
    async with asyncio.timeout(2):
        while guard.count < 3:  # noqa: ASYNC110
            await asyncio.sleep(0.01)
    assert await page_load("127.0.0.1", web.port, source="127.0.0.3") == (
        503,
        pytest.approx(0, abs=1),
    )
    ws = await connect(ws_url(web))  # a page from another address: counted once, upgraded
    assert json.loads(await ws.recv())["t"] == "hello" and guard.count == 4
    held.append(await asyncio.open_connection("127.0.0.1", web.port, local_addr=("127.0.0.4", 0)))
    status, _ = await page_load("127.0.0.1", web.port, source="127.0.0.5")
    assert status == 503 and guard.refused == 2  # the total is reached
    await ws.close()
    for _, writer in held:
        writer.close()
    async with asyncio.timeout(2):
        while guard.count:  # noqa: ASYNC110
            await asyncio.sleep(0.01)
    assert guard.open == {}
    assert (await page_load("127.0.0.1", web.port, source="127.0.0.3"))[0] == 200


@pytest.mark.parametrize(
    ("name", "code", "reason"),
    [
        ("overflowing number", 1007, "number out of range: 1e999"),
        ("NaN", 1007, "not a JSON number: NaN"),
        ("Infinity", 1007, "not a JSON number: Infinity"),
        ("2000-deep arrays", 1007, "JSON nested deeper than 4"),
        ("binary frame", 1003, "binary frames are not accepted: send JSON text"),
        ("not JSON", 1007, "not JSON: Expecting property name enclosed in double quotes"),
    ],
)
async def test_crafted_messages_get_a_clean_close_with_a_reason(
    rig: tuple[Emulator, WebServer, Client],
    tracebacks: _Records,
    name: str,
    code: int,
    reason: str,
) -> None:
    _, web, _ = rig
    got_code, got_reason = await crafted(ws_url(web), CRAFTED[name])
    assert got_code == code and got_reason.startswith(reason)
    await asyncio.sleep(0.1)
    assert tracebacks.tracebacks == []
    assert (await page_load("127.0.0.1", web.port))[0] == 200  # and the server serves on


async def test_pages_going_away_mid_jog_print_no_traceback(
    rig: tuple[Emulator, WebServer, Client],
    tracebacks: _Records,
) -> None:
    _, web, kvp = rig
    for seed in range(3):
        assert await closing_pages(ws_url(web), 12, seed=seed) == 12
        async with asyncio.timeout(5):
            while web.guard.count or web.app.state.pages:  # noqa: ASYNC110 - they all left
                await asyncio.sleep(0.01)
    await settled(kvp)
    assert tracebacks.tracebacks == []
    assert web.jog.jog is None and web.guard.count == 0
