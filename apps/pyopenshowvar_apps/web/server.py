"""The web jog pad's HTTP and WebSocket server (Starlette): pages, the live stream, commands.

``GET /`` is the page (:func:`build_page`: the head ``kvp universal``'s page shares, then
``static/index.html``), ``/static/*`` its scripts and style (all shipped in the package, no
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
from collections.abc import Sequence
from pathlib import Path
from string import Template
from typing import Any

from starlette.applications import Starlette
from starlette.datastructures import MutableHeaders
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import BaseRoute, Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.types import ASGIApp, Message, Receive, Scope, Send
from starlette.websockets import WebSocket, WebSocketDisconnect, WebSocketDisconnected

from pyopenshowvar import KvpError
from pyopenshowvar_apps.writecheck import check_literal, checked_write

from .httpguard import LogLimit
from .jog import JogController
from .jogplan import AXIS_SPEED, CADENCE, CART_SPEED, STEP_SIZES
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
from .robotlink import MAX_WATCH, RobotLink

__all__ = [
    "MAX_MESSAGE",
    "MAX_PAGES",
    "WebConfig",
    "build_page",
    "close_quietly",
    "create_app",
    "guarded_app",
]

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


def build_page(title: str, body: Path, styles: Sequence[str] = ()) -> bytes:
    """A whole page: the head both pages share (``static/head.html``: viewport, theme, the
    pad's style sheet) with ``title`` and the page's own ``styles``, then ``body`` (the file
    holding the page from ``<body>`` on)."""
    links = "".join(f'<link rel="stylesheet" href="{href}">\n' for href in styles)
    head = Template((STATIC / "head.html").read_text(encoding="utf-8"))
    text = head.substitute(title=title, styles=links) + body.read_text(encoding="utf-8")
    return text.encode()


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


async def close_quietly(ws: WebSocket, code: int, reason: str) -> None:
    """Close ``ws`` with ``code``; a page that is already gone is not an error."""
    with contextlib.suppress(*_CLOSED):
        await ws.close(code=code, reason=reason)


def hello(config: WebConfig) -> dict[str, Any]:
    """The first message a page gets: what this server allows and the jog's fixed numbers."""
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


def guarded_app(routes: Sequence[BaseRoute], token: str | None) -> Starlette:
    """A Starlette app of ``routes`` with the pages' rules: :data:`HEADERS` on every response
    and, without a token (on loopback), only loopback names in the Host header."""
    middleware = [Middleware(_SecurityHeaders)]
    if token is None:
        middleware.append(Middleware(TrustedHostMiddleware, allowed_hosts=list(LOOPBACK_HOSTS)))
    return Starlette(routes=routes, middleware=middleware)


def create_app(link: RobotLink, jog: JogController, config: WebConfig) -> Starlette:
    """The Starlette application (the caller runs it with uvicorn and runs ``link``/``jog``)."""
    pad = _PadServer(link, jog, config)
    routes = [
        Route("/", pad.index),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
        WebSocketRoute("/ws", pad.stream),
    ]
    app = guarded_app(routes, config.token)
    app.state.pages = pad.pages  # the connected pages (tests and the abuse suite count them)
    return app


class _PadServer:
    """The pad's handlers and what they share: the connected pages, their pending KVP
    requests, the robot link and the jog. One per application; the methods are its routes
    (:meth:`index`, :meth:`stream`) and the steps of one page's life behind them."""

    def __init__(self, link: RobotLink, jog: JogController, config: WebConfig) -> None:
        self.link, self.jog, self.config = link, jog, config
        self.pages: set[_Page] = set()
        self.tasks: set[asyncio.Task[None]] = set()  # pages' KVP requests, kept until done
        self.limit = LogLimit(log)  # what pages do wrong is logged, but never floods the log
        self.html = build_page("kvp web", STATIC / "index.html")  # small: served from memory
        link.listeners.append(self.on_state)

    def on_state(self, state: dict[str, Any]) -> None:
        for page in self.pages:
            page.state = state
            page.wake.set()

    def watch_union(self) -> None:
        names: set[str] = set()
        for page in self.pages:
            names.update(page.watch)
        self.link.watch = set(sorted(names)[:MAX_WATCH])

    async def index(self, request: Request) -> Response:
        return Response(self.html, media_type="text/html")

    # -- one page's connection: admitted, then a sender task and the receive loop ----------

    async def stream(self, ws: WebSocket) -> None:
        refused = refuse_connection(
            ws.headers.get("origin"),
            ws.headers.get("host", ""),
            ws.query_params.get("token"),
            self.config.token,
        )
        if refused is not None:
            host = ws.client.host if ws.client else "?"
            self.limit.warning(f"refused {host}", "refused a WebSocket from %s: %s", host, refused)
            await close_quietly(ws, 1008, refused)  # before accept: the client sees HTTP 403
            return
        if len(self.pages) >= MAX_PAGES:
            await close_quietly(ws, 1013, "too many pages")
            return
        page = _Page(ws)
        try:
            await ws.accept()
            self.pages.add(page)
            page.state = self.link.snapshot
            page.outbox.append(hello(self.config))
            page.wake.set()
            task = asyncio.create_task(self._sender(page))
            try:
                await self._receive_loop(page)
            finally:
                task.cancel()
        except _GONE:
            pass
        finally:
            self.pages.discard(page)
            await self.jog.release(page, "the page's connection was lost")
            self.jog.forget(page)
            self.watch_union()

    async def _sender(self, page: _Page) -> None:
        try:
            await self._send_loop(page)
        except _CLOSED:
            pass  # the page went away (or was closed); the receiving side cleans up
        except Exception:  # a bug here must not leave the page connected but silent
            log.exception("sending to a page failed")
            await close_quietly(page.ws, 1011, "internal error")

    async def _send_loop(self, page: _Page) -> None:
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
                out["jog"] = self.jog.describe(page)
                await page.ws.send_text(json.dumps(out))

    async def _receive_loop(self, page: _Page) -> None:
        while True:
            message = await page.ws.receive()
            if message["type"] == "websocket.disconnect":
                return
            if not page.bucket.allow(time.monotonic()):
                await close_quietly(page.ws, 1008, "too many messages")
                return
            data = message.get("text")
            try:
                msg = parse_message(data if data is not None else message.get("bytes"))
            except Violation as exc:
                host = page.ws.client.host if page.ws.client else "?"
                self.limit.warning(
                    f"closed {host}", "closed a WebSocket of %s: %s", host, exc.reason
                )
                await close_quietly(page.ws, exc.code, exc.reason)
                return
            await self._handle(page, msg)
            # Queued messages would be taken without a pause: one message per turn of the
            # event loop keeps a flooding page from stalling the others (bounded work).
            await asyncio.sleep(0)

    # -- one message of a page -------------------------------------------------------------

    @staticmethod
    def _reply(page: _Page, message: dict[str, Any]) -> None:
        page.outbox.append(message)
        page.wake.set()

    async def _handle(self, page: _Page, msg: dict[str, Any]) -> None:
        try:
            kind = msg.get("t")
            if kind == "jog":
                press, req = jog_request(msg)
                refused = await self.jog.press(page, press, req)
                if refused is not None:
                    self._reply(page, {"t": "refused", "press": press, "reason": refused})
            elif kind == "release":
                await self.jog.release(page, str(msg.get("why", "released"))[:40])
            elif kind == "watch":
                names = msg.get("names")
                if not isinstance(names, list) or len(names) > MAX_WATCH_PER_PAGE:
                    raise ValueError(f"names: a list of at most {MAX_WATCH_PER_PAGE} names")
                page.watch = [variable_name(n) for n in names]
                self.watch_union()
            elif kind in ("read", "write", "restart"):
                self._request(page, msg)
            else:
                raise ValueError(f"unknown message type {str(kind)[:20]!r}")
        except ValueError as exc:
            self._reply(page, {"t": "error", "message": str(exc)[:200]})

    def _request(self, page: _Page, msg: dict[str, Any]) -> None:
        """Check a read, write or restart and start it: one outstanding per page."""
        kind, rid = msg["t"], msg.get("id")
        if kind == "restart":
            if not self.config.emulated:
                raise ValueError("restart is only for the embedded emulator")
            name, value = RESTART_VARIABLE, "TRUE"
        else:
            name = variable_name(msg.get("name"))
            value = msg.get("value", "")
            if kind == "write":
                refused = write_refusal(name, allow_motion=self.config.allow_motion_writes)
                if refused is not None:
                    self.limit.warning("write", "refused a page's write of %s: %s", name, refused)
                    self._reply(page, {"t": "result", "id": rid, "name": name, "error": refused})
                    return
                if not isinstance(value, str) or len(value) > MAX_VALUE:
                    raise ValueError(f"value: a KRL literal of at most {MAX_VALUE} characters")
                problem = check_literal(value)
                if problem is not None:
                    raise ValueError(f"{value[:40]!r} is not a KRL literal: {problem.reason}")
        if page.busy:
            self._reply(page, {"t": "result", "id": rid, "error": "busy: one at a time"})
            return
        page.busy = True
        task = asyncio.get_running_loop().create_task(self._run(page, kind, rid, name, value))
        self.tasks.add(task)
        task.add_done_callback(self.tasks.discard)

    async def _run(self, page: _Page, kind: str, rid: Any, name: str, value: Any) -> None:
        """The KVP side of one checked request; its result (or error) is the page's reply."""
        out: dict[str, Any] = {"t": "result", "id": rid, "name": name}
        try:
            if kind == "read":
                out["text"] = await self.link.client.read(name)
            elif kind == "restart":
                out["text"] = await self.link.client.write(name, value)
            else:  # kvp write's checks: the likely reason of a refusal, a program stop
                outcome = await checked_write(self.link.client, name, value)
                out["text"] = outcome.echo
                if outcome.stop is not None:
                    out["stop"] = outcome.stop.describe()
                log.info("a page wrote %s = %s", name, value)
        except KvpError as exc:
            out["error"] = str(exc)
        finally:
            page.busy = False
        self._reply(page, out)


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
