"""The web jog pad's HTTP and WebSocket server (Starlette): pages, the live stream, commands.

``GET /`` is the page, ``/static/*`` its scripts and style (all shipped in the package, no
CDN), ``/ws`` the WebSocket. Every page gets the latest state ``hz`` times a second, and sends
jog, watch-list, read and write commands as small JSON messages.

Security (the rules themselves are :mod:`.policy`): when a token is required (bound beyond
loopback, or ``--token`` given) the WebSocket is refused (HTTP 403) without ``?token=``; since
every read, write and jog goes through the WebSocket, nothing moves or is written without it.
The Origin header must name this server, so a web page from elsewhere cannot drive the robot
through a user's browser; without a token (loopback) the Host header must be a loopback name
too (no DNS rebinding); and the page may not be framed (no click-jacking of the jog buttons).
A page never writes the jog program's variables, and writes nothing that can move the robot
unless the server runs with ``--allow-motion-writes``; its other writes get ``kvp write``'s
checks.

Abuse is bounded per connection: a message is at most :data:`MAX_MESSAGE` bytes (the
WebSocket layer refuses larger ones) of strict JSON (anything else closes the connection with
a reason), at most :data:`~.policy.RATE` messages a second (a burst of :data:`~.policy.BURST`),
one KVP read or write outstanding, :data:`MAX_WATCH_PER_PAGE` watched names; a page that reads
slower than the stream is sent only the newest state (nothing queues up), at most
:data:`MAX_PAGES` pages connect at once, and a page going away is never an error. The HTTP
side (slow or too many connections) is guarded in :mod:`.httpguard`.
"""

from __future__ import annotations

import asyncio
import contextlib
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
from starlette.responses import Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send
from starlette.websockets import WebSocket, WebSocketDisconnect, WebSocketDisconnected

from pyopenshowvar import KvpError
from pyopenshowvar_apps.writecheck import check_literal, checked_write

from .httpguard import LogLimit
from .jog import JogController
from .jogplan import AXIS_SPEED, CADENCE, CART_SPEED, STEP_SIZES
from .link import MAX_WATCH, RobotLink
from .policy import (
    RESTART_VARIABLE,
    TokenBucket,
    Violation,
    jog_request,
    parse_message,
    refuse_connection,
    variable_name,
    write_refusal,
)

__all__ = ["MAX_MESSAGE", "MAX_PAGES", "WebConfig", "create_app"]

log = logging.getLogger(__name__)

STATIC = Path(__file__).with_name("static")
MAX_MESSAGE = 4096
MAX_PAGES = 16
MAX_WATCH_PER_PAGE = 16
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
    """What the server needs besides the robot: the token, a label for the page, and whether
    the watch list may write variables that move the robot (``--allow-motion-writes``)."""

    def __init__(
        self, *, token: str | None, emulated: bool = False, allow_motion_writes: bool = False
    ) -> None:
        self.token = token
        self.emulated = emulated
        self.allow_motion_writes = allow_motion_writes


class _Page:
    """One connected page: its latest unsent state, its watch list, its message budget."""

    def __init__(self, ws: WebSocket) -> None:
        self.ws = ws
        self.state: dict[str, Any] | None = None
        self.wake = asyncio.Event()
        self.watch: list[str] = []
        self.bucket = TokenBucket(time.monotonic())
        self.busy = False
        self.outbox: list[dict[str, Any]] = []  # replies; at most one per outstanding request


#: What using a page that has gone raises. A page going away is normal, never a traceback.
_GONE = (WebSocketDisconnect, WebSocketDisconnected, OSError)
#: ... and what sending to it raises once a close was sent (Starlette's RuntimeError).
_CLOSED = (*_GONE, RuntimeError)


def create_app(link: RobotLink, jog: JogController, config: WebConfig) -> Starlette:
    """The Starlette application (the caller runs it with uvicorn and runs ``link``/``jog``)."""
    pages: set[_Page] = set()
    tasks: set[asyncio.Task[None]] = set()  # KVP requests of the pages, referenced until done
    limit = LogLimit(log)  # what pages do wrong is logged, but never floods the log

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

    page = (STATIC / "index.html").read_bytes()  # small: served from memory, no file thread

    async def index(request: Request) -> Response:
        return Response(page, media_type="text/html")

    async def close(ws: WebSocket, code: int, reason: str) -> None:
        with contextlib.suppress(*_CLOSED):
            await ws.close(code=code, reason=reason)

    async def sender(page: _Page) -> None:
        try:
            await send_loop(page)
        except _CLOSED:
            pass  # the page went away (or was closed); the receiving side cleans up
        except Exception:  # a bug here must not leave the page connected but silent
            log.exception("sending to a page failed")
            await close(page.ws, 1011, "internal error")

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
        refused = refuse_connection(
            ws.headers.get("origin"),
            ws.headers.get("host", ""),
            ws.query_params.get("token"),
            config.token,
        )
        if refused is not None:
            host = ws.client.host if ws.client else "?"
            limit.warning(f"refused {host}", "refused a WebSocket from %s: %s", host, refused)
            await close(ws, 1008, refused)  # before accept: the client sees HTTP 403
            return
        if len(pages) >= MAX_PAGES:
            await close(ws, 1013, "too many pages")
            return
        page = _Page(ws)
        try:
            await ws.accept()
            pages.add(page)
            page.state = link.snapshot
            page.outbox.append(hello())
            page.wake.set()
            task = asyncio.create_task(sender(page))
            try:
                await receive_loop(page)
            finally:
                task.cancel()
        except _GONE:
            pass
        finally:
            pages.discard(page)
            await jog.release(page, "the page's connection was lost")
            jog.forget(page)
            watch_union()

    async def receive_loop(page: _Page) -> None:
        while True:
            message = await page.ws.receive()
            if message["type"] == "websocket.disconnect":
                return
            if not page.bucket.allow(time.monotonic()):
                await close(page.ws, 1008, "too many messages")
                return
            data = message.get("text")
            try:
                msg = parse_message(data if data is not None else message.get("bytes"))
            except Violation as exc:
                host = page.ws.client.host if page.ws.client else "?"
                limit.warning(f"closed {host}", "closed a WebSocket of %s: %s", host, exc.reason)
                await close(page.ws, exc.code, exc.reason)
                return
            await handle(page, msg)
            # Queued messages would be taken without a pause: one message per turn of the
            # event loop keeps a flooding page from stalling the others (bounded work).
            await asyncio.sleep(0)

    def hello() -> dict[str, Any]:
        return {
            "t": "hello",
            "emulated": config.emulated,
            "motion_writes": config.allow_motion_writes,
            "axis_speed": AXIS_SPEED,
            "cart_speed": CART_SPEED,
            "steps": STEP_SIZES,
            "cadence": CADENCE,
            "max_watch": MAX_WATCH_PER_PAGE,
        }

    def reply(page: _Page, message: dict[str, Any]) -> None:
        page.outbox.append(message)
        page.wake.set()

    async def handle(page: _Page, msg: dict[str, Any]) -> None:
        try:
            kind = msg.get("t")
            if kind == "jog":
                press, req = jog_request(msg)
                refused = await jog.press(page, press, req)
                if refused is not None:
                    reply(page, {"t": "refused", "press": press, "reason": refused})
            elif kind == "release":
                await jog.release(page, str(msg.get("why", "released"))[:40])
            elif kind == "watch":
                names = msg.get("names")
                if not isinstance(names, list) or len(names) > MAX_WATCH_PER_PAGE:
                    raise ValueError(f"names: a list of at most {MAX_WATCH_PER_PAGE} names")
                page.watch = [variable_name(n) for n in names]
                watch_union()
            elif kind in ("read", "write", "restart"):
                request(page, msg)
            else:
                raise ValueError(f"unknown message type {str(kind)[:20]!r}")
        except ValueError as exc:
            reply(page, {"t": "error", "message": str(exc)[:200]})

    def request(page: _Page, msg: dict[str, Any]) -> None:
        kind, rid = msg["t"], msg.get("id")
        if kind == "restart":
            if not config.emulated:
                raise ValueError("restart is only for the embedded emulator")
            name, value = RESTART_VARIABLE, "TRUE"
        else:
            name = variable_name(msg.get("name"))
            value = msg.get("value", "")
            if kind == "write":
                refused = write_refusal(name, allow_motion=config.allow_motion_writes)
                if refused is not None:
                    limit.warning("write", "refused a page's write of %s: %s", name, refused)
                    reply(page, {"t": "result", "id": rid, "name": name, "error": refused})
                    return
                if not isinstance(value, str) or len(value) > MAX_VALUE:
                    raise ValueError(f"value: a KRL literal of at most {MAX_VALUE} characters")
                problem = check_literal(value)
                if problem is not None:
                    raise ValueError(f"{value[:40]!r} is not a KRL literal: {problem.reason}")
        if page.busy:
            reply(page, {"t": "result", "id": rid, "error": "busy: one at a time"})
            return
        page.busy = True

        async def run() -> None:
            out: dict[str, Any] = {"t": "result", "id": rid, "name": name}
            try:
                if kind == "read":
                    out["text"] = await link.client.read(name)
                elif kind == "restart":
                    out["text"] = await link.client.write(name, value)
                else:  # kvp write's checks: the likely reason of a refusal, a program stop
                    outcome = await checked_write(link.client, name, value)
                    out["text"] = outcome.echo
                    if outcome.stop is not None:
                        out["stop"] = outcome.stop.describe()
                    log.info("a page wrote %s = %s", name, value)
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
    app = Starlette(routes=routes, middleware=middleware)
    app.state.pages = pages  # the connected pages (tests and the abuse suite count them)
    return app


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
