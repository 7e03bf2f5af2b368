"""The web jog pad's HTTP and WebSocket server (Starlette): pages, the live stream, commands.

``GET /`` is the page, ``/static/*`` its scripts and style (all shipped in the package, no
CDN), ``/ws`` the WebSocket. Every page gets the latest state ``hz`` times a second, and sends
jog, watch-list, read and write commands as small JSON messages.

Security: when a token is required (bound beyond loopback, or ``--token`` given) the
WebSocket is refused (HTTP 403) without ``?token=``; since every read, write and jog goes
through the WebSocket, nothing moves or is written without it. The Origin header must name
this server, so a web page from elsewhere cannot drive the robot through a user's browser;
without a token (loopback) the Host header must be a loopback name too (no DNS rebinding);
and the page may not be framed (no click-jacking of the jog buttons).

Abuse is bounded per connection: a message is at most :data:`MAX_MESSAGE` bytes (the
WebSocket layer refuses larger ones), at most :data:`RATE` messages a second (a burst of
:data:`BURST`), one KVP read or write outstanding, :data:`MAX_WATCH_PER_PAGE` watched names;
a page that reads slower than the stream is sent only the newest state (nothing queues up),
and at most :data:`MAX_PAGES` pages connect at once.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import logging
import time
from pathlib import Path
from typing import Any

from starlette.applications import Starlette
from starlette.datastructures import MutableHeaders
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import FileResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send
from starlette.websockets import WebSocket, WebSocketDisconnect

from pyopenshowvar import KvpError

from .jog import JogController
from .jogplan import AXIS_SPEED, CADENCE, CART_SPEED, STEP_SIZES, JogRequest
from .link import MAX_WATCH, RobotLink

__all__ = ["MAX_MESSAGE", "MAX_PAGES", "WebConfig", "create_app"]

log = logging.getLogger(__name__)

STATIC = Path(__file__).with_name("static")
MAX_MESSAGE = 4096
MAX_PAGES = 16
RATE = 100.0
BURST = 200.0
MAX_WATCH_PER_PAGE = 16
MAX_NAME = 64
MAX_VALUE = 1024
HEADERS = {
    "Content-Security-Policy": "default-src 'self'; connect-src 'self'; img-src 'self' data:; "
    "frame-ancestors 'none'",
    "X-Frame-Options": "DENY",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-cache",
}


#: Host headers accepted when no token is required: the server is then on loopback, and a
#: web page from elsewhere that re-points its own name at 127.0.0.1 (DNS rebinding) must not
#: reach it (its requests carry its own name in Host and Origin).
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1", "[::1]")


class WebConfig:
    """What the server needs besides the robot: the token and a label for the page."""

    def __init__(self, *, token: str | None, emulated: bool = False) -> None:
        self.token = token
        self.emulated = emulated


class _Page:
    """One connected page: its latest unsent state, its watch list, its message budget."""

    def __init__(self, ws: WebSocket) -> None:
        self.ws = ws
        self.state: dict[str, Any] | None = None
        self.wake = asyncio.Event()
        self.watch: list[str] = []
        self.tokens = BURST
        self.stamp = time.monotonic()
        self.busy = False
        self.outbox: list[dict[str, Any]] = []  # replies; at most one per outstanding request

    def allow(self) -> bool:
        now = time.monotonic()
        self.tokens = min(BURST, self.tokens + (now - self.stamp) * RATE)
        self.stamp = now
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True


def create_app(link: RobotLink, jog: JogController, config: WebConfig) -> Starlette:
    """The Starlette application (the caller runs it with uvicorn and runs ``link``/``jog``)."""
    pages: set[_Page] = set()
    tasks: set[asyncio.Task[None]] = set()  # KVP requests of the pages, referenced until done

    def on_state(state: dict[str, Any]) -> None:
        for page in pages:
            page.state = state
            page.wake.set()

    link.listeners.append(on_state)

    def watch_union() -> None:
        names: set[str] = set()
        for page in pages:
            names.update(page.watch)
        link.watch = set(sorted(names)[:MAX_WATCH])

    async def index(request: Request) -> Response:
        return FileResponse(STATIC / "index.html")

    def authorised(ws: WebSocket) -> str | None:
        origin = ws.headers.get("origin")
        host = ws.headers.get("host", "")
        if origin is not None and origin not in (f"http://{host}", f"https://{host}"):
            return "wrong origin"
        if config.token is not None:
            given = ws.query_params.get("token", "")
            if not hmac.compare_digest(given.encode(), config.token.encode()):
                return "token missing or wrong"
        return None

    async def sender(page: _Page) -> None:
        try:
            await send_loop(page)
        except Exception:  # a bug here must not leave the page connected but silent
            log.exception("sending to a page failed")
            await page.ws.close(code=1011)

    async def send_loop(page: _Page) -> None:
        while True:
            await page.wake.wait()
            page.wake.clear()
            for reply in page.outbox:
                await page.ws.send_text(json.dumps(reply))
            page.outbox.clear()
            state = page.state
            if state is not None:
                page.state = None
                out = dict(state)
                out["watch"] = {n: v for n, v in state.get("watch", {}).items() if n in page.watch}
                out["jog"] = jog.describe(page)
                await page.ws.send_text(json.dumps(out))

    async def stream(ws: WebSocket) -> None:
        refused = authorised(ws)
        if refused is not None:
            log.warning("refused a WebSocket from %s: %s", ws.client, refused)
            await ws.close(code=1008)  # before accept: the client sees HTTP 403
            return
        if len(pages) >= MAX_PAGES:
            await ws.close(code=1013)
            return
        await ws.accept()
        page = _Page(ws)
        pages.add(page)
        task = asyncio.create_task(sender(page))
        await ws.send_text(json.dumps(hello()))
        page.state = link.snapshot
        page.wake.set()
        try:
            while True:
                text = await ws.receive_text()
                if not page.allow():
                    await ws.close(code=1008, reason="too many messages")
                    break
                await handle(page, text)
        except WebSocketDisconnect:
            pass
        finally:
            pages.discard(page)
            task.cancel()
            await jog.release(page, "the page's connection was lost")
            jog.forget(page)
            watch_union()

    def hello() -> dict[str, Any]:
        return {
            "t": "hello",
            "emulated": config.emulated,
            "axis_speed": AXIS_SPEED,
            "cart_speed": CART_SPEED,
            "steps": STEP_SIZES,
            "cadence": CADENCE,
            "max_watch": MAX_WATCH_PER_PAGE,
        }

    def reply(page: _Page, message: dict[str, Any]) -> None:
        page.outbox.append(message)
        page.wake.set()

    async def handle(page: _Page, text: str) -> None:
        try:
            msg = json.loads(text)
            if not isinstance(msg, dict):
                raise ValueError("a message is a JSON object")
            kind = msg.get("t")
            if kind == "jog":
                req = JogRequest(
                    frame=msg["frame"],
                    key=str(msg["key"]),
                    direction=int(msg["dir"]),
                    step=float(msg["step"]) if msg.get("step") else None,
                    override=float(msg.get("ov", 50)),
                )
                refused = await jog.press(page, int(msg["press"]), req)
                if refused is not None:
                    reply(page, {"t": "refused", "press": msg["press"], "reason": refused})
            elif kind == "release":
                await jog.release(page, str(msg.get("why", "released"))[:40])
            elif kind == "watch":
                names = [_name(n) for n in msg["names"]][:MAX_WATCH_PER_PAGE]
                page.watch = names
                watch_union()
            elif kind in ("read", "write", "restart"):
                request(page, msg)
            else:
                raise ValueError(f"unknown message type {kind!r}")
        except (KeyError, TypeError, ValueError) as exc:
            reply(page, {"t": "error", "message": str(exc)[:200]})

    def request(page: _Page, msg: dict[str, Any]) -> None:
        if page.busy:
            reply(page, {"t": "result", "id": msg.get("id"), "error": "busy: one at a time"})
            return
        kind = msg["t"]
        if kind == "restart":
            name, value = "EMU_RESTART", "TRUE"
        else:
            name = _name(msg["name"])
            value = str(msg.get("value", ""))
            if len(value) > MAX_VALUE:
                raise ValueError(f"value longer than {MAX_VALUE} characters")
        page.busy = True

        async def run() -> None:
            out: dict[str, Any] = {"t": "result", "id": msg.get("id"), "name": name}
            try:
                if kind == "read":
                    out["text"] = await link.client.read(name)
                else:
                    out["text"] = await link.client.write(name, value)
            except KvpError as exc:
                out["error"] = str(exc)
            finally:
                page.busy = False
            reply(page, out)

        task = asyncio.get_running_loop().create_task(run())
        tasks.add(task)
        task.add_done_callback(tasks.discard)

    routes = [
        Route("/", index),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
        WebSocketRoute("/ws", stream),
    ]
    middleware = [Middleware(_SecurityHeaders)]
    if config.token is None:
        middleware.append(Middleware(TrustedHostMiddleware, allowed_hosts=list(LOOPBACK_HOSTS)))
    return Starlette(routes=routes, middleware=middleware)


class _SecurityHeaders:
    """Adds :data:`HEADERS` to every HTTP response (pages, scripts, errors)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                MutableHeaders(scope=message).update(HEADERS)
            await send(message)

        await self.app(scope, receive, send_with_headers)


def _name(value: object) -> str:
    name = str(value).strip()
    if not name or len(name) > MAX_NAME or any(c.isspace() for c in name):
        raise ValueError(f"bad variable name {name[:MAX_NAME]!r}")
    return name
