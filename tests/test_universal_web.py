"""``kvp universal``'s page: the jog pad as the input device and the 3D view, over real HTTP and
WebSocket (no browser): hold to move, release and silence stop, one page at a time, switching,
the token and Origin checks, and the pad's assets reused from its own folder."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from typing import Any

import httpx
import numpy as np
import pytest
import websockets
from pyopenshowvar_apps.universal.server import ControlServer
from pyopenshowvar_apps.universal.sim import SimulatedArm
from pyopenshowvar_apps.universal.web import HOLD_TIMEOUT, ViewServer, WebInput
from pyopenshowvar_apps.web.policy import BURST
from websockets.asyncio.client import ClientConnection, connect

from pyopenshowvar.arms import load_arm


@pytest.fixture
async def page_rig() -> AsyncIterator[tuple[ControlServer, ViewServer]]:
    web_input = WebInput()
    backend = SimulatedArm(load_arm("adept_cobra600"), q0=(30.0, 60.0, 100.0, 0.0))
    server = ControlServer(backend, web_input, solver="dls", mode="velocity", k_v=200.0)
    await server.start()
    loop = asyncio.create_task(server.run())
    async with ViewServer(server, web_input, port=0, token=None) as view:
        try:
            yield server, view
        finally:
            loop.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await loop
            await server.close()


async def open_page(view: ViewServer, token: str | None = None) -> ClientConnection:
    url = f"ws://127.0.0.1:{view.port}/ws" + (f"?token={token}" if token else "")
    ws = await connect(url, origin=f"http://127.0.0.1:{view.port}", max_queue=None)  # type: ignore[arg-type]
    hello = json.loads(await ws.recv())
    assert hello["t"] == "hello"
    return ws


async def keep(ws: ClientConnection, seconds: float, msg: dict[str, Any]) -> None:
    """Send ``msg`` every 25 ms (the page's keep-alive) for ``seconds``."""
    loop = asyncio.get_running_loop()
    end = loop.time() + seconds
    while loop.time() < end:
        await ws.send(json.dumps(msg))
        await asyncio.sleep(0.025)


async def state(ws: ClientConnection) -> dict[str, Any]:
    async with asyncio.timeout(5):
        while True:
            msg = json.loads(await ws.recv())
            if msg["t"] == "state":
                return msg  # type: ignore[no-any-return]


JOG_X = {"t": "jog", "press": 1, "key": "X", "dir": 1, "level": 1.0}


async def test_the_page_and_the_pads_assets_are_served(page_rig: Any) -> None:
    _, view = page_rig
    async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{view.port}") as http:
        page = await http.get("/")
        assert page.status_code == 200 and "/static/view3d.js" in page.text
        assert "/static/style.css" in page.text and "/u/universal.js" in page.text
        # the pad's own files, from its folder (nothing copied)
        for path in ("/static/view3d.js", "/static/style.css", "/u/universal.js"):
            assert (await http.get(path)).status_code == 200, path
        assert page.headers["x-frame-options"] == "DENY"


async def test_hold_to_move_release_to_stop(page_rig: Any) -> None:
    server, view = page_rig
    ws = await open_page(view)
    s = await state(ws)
    assert s["arm"] == "adept_cobra600" and len(s["frames"]) == 6 and "dls" in s["solvers"]
    x0 = np.array(s["tip"])
    await keep(ws, 0.6, JOG_X)  # held for 0.6 s
    moved = server.ticks[-1].tip - x0
    assert moved[0] > 20.0 and abs(moved[1]) < 0.3 * moved[0]
    # keep-alives stop (the button is up) but the page is there: released → stopped
    released = server.ticks[-1].tip
    await keep(ws, 1.5, {"t": "alive"})
    assert server.ticks[-1].alive and np.all(server.ticks[-1].signal == 0)
    assert np.linalg.norm(server.ticks[-1].qdot) < 0.5
    # braking from 200 mm/s and the drives' lag: a few cm, not more
    assert np.linalg.norm(server.ticks[-1].tip - released) < 40.0
    await ws.close()


async def test_a_silent_page_stops_the_arm(page_rig: Any) -> None:
    server, view = page_rig
    ws = await open_page(view)
    await keep(ws, 0.3, JOG_X)
    assert server.ticks[-1].alive
    await asyncio.sleep(server.deadline + 0.2)  # the page freezes: nothing at all arrives
    assert not server.ticks[-1].alive and np.all(server.ticks[-1].command == 0)
    await ws.close()
    await asyncio.sleep(0.1)
    assert not server.ticks[-1].alive  # no page at all: disconnected


async def test_one_page_moves_the_arm_at_a_time_and_switches(page_rig: Any) -> None:
    server, view = page_rig
    a, b = await open_page(view), await open_page(view)
    holder = asyncio.create_task(keep(a, 0.5, JOG_X))
    await asyncio.sleep(0.1)
    await b.send(json.dumps({**JOG_X, "key": "Y"}))
    async with asyncio.timeout(5):
        while (msg := json.loads(await b.recv()))["t"] != "refused":
            pass
    assert "another page" in msg["reason"]
    await holder
    await b.send(json.dumps({"t": "switch", "key": "solver", "value": "pso"}))
    await keep(b, 0.3, {"t": "alive"})
    assert server.solver_name == "pso"
    await b.send(json.dumps({"t": "switch", "key": "volume", "value": "11"}))
    async with asyncio.timeout(5):
        while (msg := json.loads(await b.recv()))["t"] != "error":
            pass
    assert "unknown switch" in msg["message"]
    await a.close()
    await b.close()
    assert HOLD_TIMEOUT == 0.1


async def test_a_flooding_page_is_closed_by_its_message_budget(page_rig: Any) -> None:
    """Past the pad's burst (BURST messages, RATE a second) the page is closed with 1008."""
    _, view = page_rig
    ws = await open_page(view)
    with contextlib.suppress(websockets.ConnectionClosed):
        for _ in range(int(BURST) * 10):  # far past the burst, whatever the refill meanwhile
            await ws.send(json.dumps({"t": "alive"}))
    async with asyncio.timeout(5):
        await ws.wait_closed()
    assert ws.close_code == 1008 and ws.close_reason == "too many messages"


async def test_token_and_origin_are_required() -> None:
    web_input = WebInput()
    server = ControlServer(SimulatedArm(load_arm("adept_cobra600")), web_input)
    await server.start()
    async with ViewServer(server, web_input, port=0, token="secret-token-1") as view:
        with pytest.raises(websockets.InvalidStatus):
            await open_page(view)  # no token
        with pytest.raises(websockets.InvalidStatus):
            await connect(f"ws://127.0.0.1:{view.port}/ws?token=secret-token-1",
                          origin="http://evil.example")  # type: ignore[arg-type]  # fmt: skip
        ws = await open_page(view, "secret-token-1")
        await ws.close()
    await server.close()


@pytest.mark.parametrize(
    ("frame", "code"),
    [
        ('{"t": "jog", "key": "X", "dir": 1, "level": NaN}', 1007),
        ('{"t": "jog", "key": "X", "dir": 1, "level": 1e999}', 1007),
        ("[" * 2000 + "]" * 2000, 1007),
        (b"\x00\x01binary", 1003),
    ],
)
async def test_a_crafted_message_closes_the_page_with_a_reason(
    page_rig: Any, frame: str | bytes, code: int
) -> None:
    """The pad's message rules, from the same code: never a traceback, never a motion."""
    server, view = page_rig
    ws = await open_page(view)
    await ws.send(frame)
    async with asyncio.timeout(5):
        with pytest.raises(websockets.ConnectionClosed):
            while True:
                await ws.recv()
    assert ws.close_code == code and ws.close_reason
    assert np.all(server.ticks[-1].signal == 0)
