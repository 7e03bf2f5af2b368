"""The jog pad's server (:mod:`pyopenshowvar_apps.web.server`): pages, the WebSocket's rules.

Over real TCP: an emulator, :class:`WebServer` in the test's process, and the test speaking
HTTP and WebSocket to it like the page does. Each rule is its own short test (the jogs
themselves, with the robot moving, are in tests/test_web_jog.py); the controller behind the
``jog`` messages is tested in tests/test_web_jog_control.py.
"""

from __future__ import annotations

import asyncio
import json
import socket
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import pytest
import websockets
from pyopenshowvar_apps.web.jogplan import AXIS_SPEED, CADENCE, CART_SPEED, STEP_SIZES
from pyopenshowvar_apps.web.robotlink import MAX_WATCH
from pyopenshowvar_apps.web.runner import KRL_DIR, WebServer
from pyopenshowvar_apps.web.server import HEADERS, MAX_PAGES, STATIC, WebConfig, build_page
from websockets.asyncio.client import ClientConnection, connect

from kukavarproxy_emu import Emulator, EmulatorConfig
from kukavarproxy_emu.faults import Fault
from kukavarproxy_emu.testing import wait_until

TOKEN = "server-test-token"
JOG = {"t": "jog", "press": 1, "frame": "axis", "key": "A1", "dir": 1, "ov": 100}


class Rig:
    """``await rig(jog=True, token=..., emulated=..., allow_motion_writes=...)``: an emulator
    (running KVP_JOG with ``jog``) and the pad's server for it, once the pad sees the robot;
    ``rig.emulator(web)`` is that server's emulator."""

    def __init__(self) -> None:
        self.made: list[tuple[Emulator, WebServer]] = []

    def emulator(self, web: WebServer) -> Emulator:
        return next(emu for emu, w in self.made if w is web)

    async def __call__(self, *, jog: bool = False, **kw: Any) -> WebServer:
        files: dict[str, Any] = {"program": str(KRL_DIR / "kvp_jog.src"),
                 "config_files": (KRL_DIR / "kvp_jog_config.dat",)} if jog else {}  # fmt: skip
        emu = Emulator(
            EmulatorConfig(port=0, latency="none", discovery=False, plant="ideal", **files)
        )
        await emu.start()
        kw.setdefault("token", TOKEN)
        web = WebServer("127.0.0.1", emu.port, **kw)
        self.made.append((emu, web))
        await web.__aenter__()
        web.jog.hold_timeout = 5.0  # only the test's own release ends a jog here

        async def seen() -> bool:
            return web.link.connected and (not jog or web.link.jog_ready() is None)

        await wait_until(seen, timeout=10)
        return web


@pytest.fixture
async def rig() -> AsyncIterator[Rig]:
    made = Rig()
    yield made
    for emu, web in made.made:
        await web.__aexit__(None, None, None)
        await emu.close()


async def page(web: WebServer, token: str | None = TOKEN, **kw: Any) -> ClientConnection:
    query = f"?token={token}" if token is not None else ""
    ws = await connect(f"ws://127.0.0.1:{web.port}/ws{query}", max_queue=None, **kw)
    async with asyncio.timeout(5):
        hello = json.loads(await ws.recv())
    assert hello["t"] == "hello"
    return ws


async def answer(ws: ClientConnection, msg: dict[str, Any] | None = None) -> dict[str, Any]:
    """Send ``msg`` (if any) and return the next reply that is not a state."""
    if msg is not None:
        await ws.send(json.dumps(msg))
    async with asyncio.timeout(5):
        while True:
            got = json.loads(await ws.recv())
            if got["t"] != "state":
                return dict(got)


async def state(ws: ClientConnection, check: Callable[[dict[str, Any]], bool]) -> dict[str, Any]:
    """The first state that passes ``check``."""
    async with asyncio.timeout(5):
        while True:
            got = json.loads(await ws.recv())
            if got["t"] == "state" and check(got):
                return dict(got)


async def closed(ws: ClientConnection) -> tuple[int, str]:
    """How the server closed ``ws`` (code, reason)."""
    with pytest.raises(websockets.exceptions.ConnectionClosed) as info:
        async with asyncio.timeout(5):
            while True:
                await ws.recv()
    assert info.value.rcvd is not None
    return info.value.rcvd.code, info.value.rcvd.reason


async def http_get(
    web: WebServer, path: str, host: str = "127.0.0.1"
) -> tuple[str, dict[str, str], bytes]:
    """Status line, headers (lower-case names) and body of one GET."""
    reader, writer = await asyncio.open_connection("127.0.0.1", web.port)
    try:
        writer.write(f"GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n".encode())
        async with asyncio.timeout(5):
            data = await reader.read()
    finally:
        writer.close()
    head, _, body = data.partition(b"\r\n\r\n")
    status, *lines = head.decode().split("\r\n")
    headers = {k.lower(): v.strip() for k, _, v in (line.partition(":") for line in lines)}
    return status, headers, body


# --- pages over HTTP --------------------------------------------------------------------------
def test_build_page_puts_title_and_styles_in_the_shared_head(tmp_path: Path) -> None:
    body = tmp_path / "body.html"
    body.write_text("<body>hello</body>\n", encoding="utf-8")
    page_bytes = build_page("My <pad>", body, ["a.css", "/b.css"])
    text = page_bytes.decode()
    assert isinstance(page_bytes, bytes)
    assert "<title>My <pad></title>" in text
    assert '<link rel="stylesheet" href="a.css">\n<link rel="stylesheet" href="/b.css">\n' in text
    assert text.endswith("<body>hello</body>\n")
    assert text.startswith((STATIC / "head.html").read_text(encoding="utf-8")[:15])
    assert 'rel="stylesheet" href="a.css"' not in build_page("x", body).decode()


def test_config_defaults_allow_nothing_extra() -> None:
    config = WebConfig(token=None)
    assert (config.token, config.emulated, config.allow_motion_writes) == (None, False, False)


async def test_page_assets_and_errors_carry_the_security_headers(rig: Rig) -> None:
    web = await rig(token=None)  # loopback without a token: loopback Host names only
    status, headers, body = await http_get(web, "/")
    assert status == "HTTP/1.1 200 OK"
    assert headers["content-type"].startswith("text/html")
    assert body == build_page("kvp web", STATIC / "index.html")
    for name, value in HEADERS.items():
        assert headers[name.lower()] == value, name
    status, headers, _ = await http_get(web, "/static/index.html")
    assert status == "HTTP/1.1 200 OK" and headers["x-frame-options"] == "DENY"
    status, headers, _ = await http_get(web, "/nope")
    assert status.startswith("HTTP/1.1 404") and headers["x-frame-options"] == "DENY"
    status, _, _ = await http_get(web, "/", host="evil.example")  # DNS rebinding
    assert status.startswith("HTTP/1.1 400")
    status, _, _ = await http_get(web, "/", host="localhost:8080")
    assert status == "HTTP/1.1 200 OK"


async def test_with_a_token_any_host_name_gets_the_page(rig: Rig) -> None:
    """Bound beyond loopback the server is reached by its LAN name: the token guards it."""
    web = await rig()
    status, headers, _ = await http_get(web, "/", host="192.168.1.20:8080")
    assert status == "HTTP/1.1 200 OK" and headers["x-content-type-options"] == "nosniff"


def _warnings(caplog: pytest.LogCaptureFixture) -> list[str]:
    """What the server logged as warnings (a refusal is logged: who, and why)."""
    return [
        r.getMessage()
        for r in caplog.records
        if r.name == "pyopenshowvar_apps.web.server" and r.levelname == "WARNING"
    ]


# --- admission -----------------------------------------------------------------------------
async def test_hello_then_the_live_state(rig: Rig) -> None:
    web = await rig(emulated=True, allow_motion_writes=True)
    ws = await connect(f"ws://127.0.0.1:{web.port}/ws?token={TOKEN}", max_queue=None)
    assert json.loads(await ws.recv()) == {
        "t": "hello", "emulated": True, "motion_writes": True,
        "axis_speed": list(AXIS_SPEED), "cart_speed": list(CART_SPEED),
        "steps": list(STEP_SIZES), "cadence": CADENCE, "max_watch": 16,
    }  # fmt: skip
    live = await state(ws, lambda s: s["link"]["connected"])
    assert live["watch"] == {} and live["axes"] is not None
    assert live["jog"] == {"active": False, "mine": False, "label": None}
    await ws.close()
    web2 = await rig()
    ws = await connect(f"ws://127.0.0.1:{web2.port}/ws?token={TOKEN}")
    hello = json.loads(await ws.recv())
    assert hello["emulated"] is False and hello["motion_writes"] is False
    await ws.close()


async def test_a_new_page_gets_hello_and_the_last_state_at_once(rig: Rig) -> None:
    """A page does not wait for the next poll (here 10 s away) for its first messages."""
    web = await rig(hz=0.1)
    ws = await connect(f"ws://127.0.0.1:{web.port}/ws?token={TOKEN}")
    async with asyncio.timeout(4):
        assert json.loads(await ws.recv())["t"] == "hello"
        first = json.loads(await ws.recv())
    assert first["t"] == "state" and first["link"]["connected"] is True
    assert first["seq"] == web.link.snapshot["seq"]
    await ws.close()


@pytest.mark.parametrize(
    ("token", "headers"),
    [(None, {}), ("wrong-token-123", {}), (TOKEN, {"Origin": "http://evil.example"})],
)
async def test_refused_without_the_token_or_from_another_origin(
    rig: Rig, token: str | None, headers: dict[str, str], caplog: pytest.LogCaptureFixture
) -> None:
    web = await rig()
    with pytest.raises(websockets.exceptions.InvalidStatus) as info:
        await page(web, token, additional_headers=headers)
    assert info.value.response.status_code == 403
    why = "wrong origin" if "Origin" in headers else "token missing or wrong"
    assert f"refused a WebSocket from 127.0.0.1: {why}" in _warnings(caplog)
    # the log is rate-limited per address: another address is logged too
    with pytest.raises(websockets.exceptions.InvalidStatus):
        await page(web, token, additional_headers=headers, local_addr=("127.0.0.2", 0))
    assert f"refused a WebSocket from 127.0.0.2: {why}" in _warnings(caplog)
    assert not web.app.state.pages
    ws = await page(web, TOKEN, additional_headers={"Origin": f"http://127.0.0.1:{web.port}"})
    await ws.close()


async def test_at_most_max_pages_at_once(rig: Rig) -> None:
    web = await rig()
    pages = [await page(web) for _ in range(MAX_PAGES)]
    # from another address: one address may hold only as many connections (httpguard). The
    # refusal comes before the WebSocket is accepted, which the client sees as HTTP 403
    with pytest.raises(websockets.exceptions.InvalidStatus) as info:
        await connect(f"ws://127.0.0.1:{web.port}/ws?token={TOKEN}", local_addr=("127.0.0.2", 0))
    assert info.value.response.status_code == 403
    assert len(web.app.state.pages) == MAX_PAGES
    await pages.pop().close()
    await wait_until(lambda: len(web.app.state.pages) < MAX_PAGES, timeout=5)
    pages.append(await page(web, local_addr=("127.0.0.2", 0)))  # a free place is taken again
    for ws in pages:
        await ws.close()


# --- messages ------------------------------------------------------------------------------
async def test_every_page_gets_the_state_with_its_own_watch_list(rig: Rig) -> None:
    web = await rig()
    one, two, three = await page(web), await page(web), await page(web)
    await one.send(json.dumps({"t": "watch", "names": ["MYINT", " MYREAL "]}))
    await two.send(json.dumps({"t": "watch", "names": ["MYBOOL"]}))
    await wait_until(lambda: web.link.watch == {"MYINT", "MYREAL", "MYBOOL"}, timeout=5)
    got = await state(one, lambda s: set(s["watch"]) == {"MYINT", "MYREAL"})
    assert got["watch"]["MYINT"]["error"] is None
    await state(two, lambda s: set(s["watch"]) == {"MYBOOL"})
    # a page that watches nothing gets none of the others' values
    seen = [await state(three, lambda s: s["link"]["connected"]) for _ in range(3)]
    assert all(s["watch"] == {} for s in seen)
    seqs = [s["seq"] for s in seen]
    assert seqs == sorted(set(seqs))  # each state once, in order
    await three.close()
    await two.close()  # a page that goes away leaves the union
    await wait_until(lambda: web.link.watch == {"MYINT", "MYREAL"}, timeout=5)
    await one.close()


async def test_the_union_of_watch_lists_is_bounded(rig: Rig) -> None:
    web = await rig()
    pages = [await page(web) for _ in range(3)]
    names = [[f"V{p}_{i:02d}" for i in range(16)] for p in range(3)]
    for ws, mine in zip(pages, names, strict=True):
        assert await answer(ws, {"t": "watch", "names": [*mine, "X"]}) == {
            "t": "error", "message": "names: a list of at most 16 names",
        }  # fmt: skip
        await ws.send(json.dumps({"t": "watch", "names": mine}))
    everything = sorted(n for mine in names for n in mine)
    await wait_until(lambda: web.link.watch == set(everything[:MAX_WATCH]), timeout=5)
    for ws in pages:
        await ws.close()


@pytest.mark.parametrize(
    ("msg", "error"),
    [
        ({"t": "watch", "names": "MYINT"}, "names: a list of at most 16 names"),
        ({"t": "watch"}, "names: a list of at most 16 names"),
        ({"t": "watch", "names": ["A B"]}, "bad variable name 'A B'"),
        ({"t": "nope"}, "unknown message type 'nope'"),
        ({"t": "x" * 50}, f"unknown message type {'x' * 20!r}"),
        ({}, "unknown message type 'None'"),
        ({"t": "read", "id": 1, "name": "x" * 500}, f"bad variable name {'x' * 64!r}"),
        ({**JOG, "key": "Q9"}, "axis jog keys are A1, A2, A3, A4, A5, A6, not 'Q9'"),
        ({**JOG, "press": -1}, "press must be an integer in 0..2147483647"),
        ({"t": "restart"}, "restart is only for the embedded emulator"),
        ({"t": "write", "id": 1, "name": "MYINT", "value": 5}, "value: a KRL literal of at most 1024 characters"),
        ({"t": "write", "id": 1, "name": "MYINT", "value": "1" * 1025}, "value: a KRL literal of at most 1024 characters"),
    ],
)  # fmt: skip
async def test_a_message_a_page_should_not_send_gets_an_error(
    rig: Rig, msg: dict[str, Any], error: str
) -> None:
    web = await rig()
    ws = await page(web)
    assert await answer(ws, msg) == {"t": "error", "message": error}
    assert await answer(ws, {"t": "read", "id": 2, "name": "MYINT"}) == {
        "t": "result", "id": 2, "name": "MYINT", "text": "0",
    }  # fmt: skip  # and the page is served on
    await ws.close()


async def test_an_error_message_is_cut_to_200_characters(rig: Rig) -> None:
    web = await rig()
    ws = await page(web)
    got = await answer(ws, {"t": "read", "id": 1, "name": "\x01" * 100})  # repr: 4 each
    assert got["t"] == "error" and len(got["message"]) == 200
    assert got["message"].startswith("bad variable name '\\x01\\x01")
    await ws.close()


async def test_reads_writes_and_their_refusals(rig: Rig, caplog: pytest.LogCaptureFixture) -> None:
    web = await rig(emulated=True)
    ws = await page(web)
    assert await answer(ws, {"t": "write", "id": 1, "name": "MYINT", "value": "41"}) == {
        "t": "result", "id": 1, "name": "MYINT", "text": "41",
    }  # fmt: skip
    assert await answer(ws, {"t": "read", "id": "r", "name": "MYINT"}) == {
        "t": "result", "id": "r", "name": "MYINT", "text": "41",
    }  # fmt: skip
    got = await answer(ws, {"t": "read", "id": 3, "name": "NOPE_VAR"})
    assert got["id"] == 3 and got["name"] == "NOPE_VAR" and "NOPE_VAR" in got["error"]
    assert "text" not in got
    assert await answer(ws, {"t": "write", "id": 4, "name": "JOG_UNTIL", "value": "9"}) == {
        "t": "result", "id": 4, "name": "JOG_UNTIL",
        "error": "JOG_UNTIL belongs to the jog program: only the server's jog logic writes it",
    }  # fmt: skip
    assert (
        "refused a page's write of JOG_UNTIL: JOG_UNTIL belongs to the jog program: only the"
        " server's jog logic writes it" in _warnings(caplog)
    )
    got = await answer(ws, {"t": "write", "id": 5, "name": "$OV_PRO", "value": "10"})
    assert got["error"].startswith("writing $OV_PRO can move the robot")
    value = "{A1 " + "1" * 100
    got = await answer(ws, {"t": "write", "id": 8, "name": "MYINT", "value": value})
    assert got["message"].startswith(f"{value[:40]!r} is not a KRL literal: ")  # its start
    assert await answer(ws, {"t": "write", "id": 7, "name": "MYINT"}) == {
        "t": "error", "message": "'' is not a KRL literal: empty text '' is not a KRL value",
    }  # fmt: skip
    assert await web.link.client.read("$OV_PRO") == "100"
    long_ok = '"' + "a" * 1022 + '"'  # 1024 characters: the longest value taken
    got = await answer(ws, {"t": "write", "id": 6, "name": "MYINT", "value": long_ok})
    assert got["t"] == "result" and got["id"] == 6 and got["error"].startswith("write refused")
    await ws.close()


async def test_motion_writes_with_the_flag_and_the_restart_button(rig: Rig) -> None:
    web = await rig(emulated=True, allow_motion_writes=True)
    ws = await page(web)
    assert await answer(ws, {"t": "write", "id": 1, "name": "$OV_PRO", "value": "10"}) == {
        "t": "result", "id": 1, "name": "$OV_PRO", "text": "10",
    }  # fmt: skip
    got = await answer(ws, {"t": "write", "id": 3, "name": "MYAXIS", "value": "{A1 9999}"})
    assert got["text"] == "{A1 9999}" and got["id"] == 3 and got["name"] == "MYAXIS"
    assert got["stop"].startswith("$PRO_STATE1 #P_STOP, $STOPMESS TRUE: ")
    assert "Software limit switch +A1" in got["stop"]
    assert await answer(ws, {"t": "restart", "id": 2}) == {
        "t": "result", "id": 2, "name": "EMU_RESTART", "text": "TRUE",
    }  # fmt: skip
    await ws.close()


async def test_one_request_at_a_time_per_page(rig: Rig) -> None:
    web = await rig()
    ws = await page(web)
    # the link's connection (the emulator's first) holds its next reply back: the first read
    # (that one or one queued behind it) is still out when the second arrives
    emu = rig.emulator(web)
    emu.faults.add(Fault("delay", connection=1, seconds=0.3))
    await ws.send(json.dumps({"t": "read", "id": 1, "name": "MYINT"}))
    await ws.send(json.dumps({"t": "read", "id": 2, "name": "MYINT"}))
    assert await answer(ws) == {"t": "result", "id": 2, "error": "busy: one at a time"}
    assert await answer(ws) == {"t": "result", "id": 1, "name": "MYINT", "text": "0"}
    assert (await answer(ws, {"t": "read", "id": 3, "name": "MYINT"}))["text"] == "0"
    await ws.close()


async def test_a_flood_and_a_binary_frame_close_the_page(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    web = await rig()
    ws = await page(web)  # a page that closes normally is no violation: nothing logged
    await ws.close()
    await wait_until(lambda: not web.app.state.pages, timeout=5)
    assert _warnings(caplog) == []
    for address in ("127.0.0.1", "127.0.0.2"):  # logged once per address at most
        ws = await page(web, local_addr=(address, 0))
        await ws.send(b"\x00binary")
        assert await closed(ws) == (1003, "binary frames are not accepted: send JSON text")
        assert (
            f"closed a WebSocket of {address}: binary frames are not accepted: send JSON text"
            in _warnings(caplog)
        )
    ws = await page(web)
    await ws.send("{nope")
    code, reason = await closed(ws)
    assert code == 1007 and reason.startswith("not JSON: ")
    ws = await page(web)
    for _ in range(400):  # twice the burst, faster than the budget refills
        await ws.send('{"t": "watch", "names": []}')
    assert await closed(ws) == (1008, "too many messages")


async def test_a_page_that_cannot_be_sent_to_is_closed(rig: Rig) -> None:
    """A bug in sending (here a state that is not JSON) must not leave the page connected
    but silent: it is closed with 1011 and the others are served on. (The link polls every
    10 s here: no good state replaces the bad one before it is sent.)"""
    web = await rig(hz=0.1)
    ws = await page(web)
    web.link.listeners[0]({"t": "state", "bad": object()})
    assert await closed(ws) == (1011, "internal error")
    ws = await page(web)
    await state(ws, lambda s: s["link"]["connected"])
    await ws.close()


# --- jog messages --------------------------------------------------------------------------
async def test_a_jog_the_robot_cannot_take_is_refused_with_its_press(rig: Rig) -> None:
    web = await rig()  # the emulator runs no KVP_JOG
    ws = await page(web)
    got = await answer(ws, {**JOG, "press": 7})
    assert got == {"t": "refused", "press": 7, "reason": web.link.jog_ready()}
    assert got["reason"] == "the KVP_JOG globals are not on this controller (see docs/web.md)"
    await ws.close()


async def test_jog_release_and_a_lost_page(rig: Rig) -> None:
    web = await rig(jog=True)
    ws, other = await page(web), await page(web)
    await ws.send(json.dumps(JOG))
    mine = await state(ws, lambda s: s["jog"]["active"])
    assert mine["jog"]["mine"] is True and mine["jog"]["label"] == "axis A1+"
    theirs = await state(other, lambda s: s["jog"]["active"])
    assert theirs["jog"]["mine"] is False
    await ws.send(json.dumps({"t": "release", "why": "w" * 60}))
    await wait_until(lambda: web.jog.jog is None, timeout=5)
    assert web.jog.last_stop is not None and web.jog.last_stop[0] == "w" * 40
    await ws.send(json.dumps({**JOG, "press": 2}))
    await wait_until(lambda: web.jog.jog is not None, timeout=5)
    await ws.send(json.dumps({"t": "release"}))
    await wait_until(lambda: web.jog.jog is None, timeout=5)
    assert web.jog.last_stop is not None and web.jog.last_stop[0] == "released"
    await ws.send(json.dumps({**JOG, "press": 3}))
    await wait_until(lambda: web.jog.jog is not None, timeout=5)
    await ws.close()  # the page goes away mid-jog
    await wait_until(lambda: web.jog.jog is None, timeout=5)
    assert web.jog.last_stop is not None
    assert web.jog.last_stop[0] == "the page's connection was lost"
    await other.close()


async def test_pages_that_left_leave_nothing_behind(rig: Rig) -> None:
    """Bounded memory: a page that pressed a jog and went away leaves no sending task and no
    record of its presses in the server."""
    web = await rig(jog=True)
    for _ in range(5):
        ws = await page(web)
        await ws.send(json.dumps(JOG))
        await wait_until(lambda: web.jog.jog is not None, timeout=5)
        await ws.close()
    await wait_until(lambda: not web.app.state.pages and web.jog.jog is None, timeout=5)

    def senders() -> list[asyncio.Task[Any]]:
        return [
            t for t in asyncio.all_tasks() if getattr(t.get_coro(), "__name__", "") == "_sender"
        ]

    await wait_until(lambda: not senders(), timeout=5)
    assert web.jog._done == {}


async def test_a_robot_that_is_not_there_is_a_state_too() -> None:
    """The link's state while it connects (or after it lost the robot) has no values: a page
    gets it, and stays connected and answered."""
    with socket.socket() as free:  # a port nobody listens on
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    async with WebServer("127.0.0.1", port, token=TOKEN, timeout=0.5) as web:
        ws = await page(web)
        got = await state(ws, lambda s: True)
        assert got["link"]["connected"] is False and got["link"]["error"]
        assert got["watch"] == {} and got["jog"]["active"] is False
        reply = await answer(ws, {"t": "read", "id": 1, "name": "MYINT"})
        assert reply["id"] == 1 and reply["error"]
        await ws.close()
