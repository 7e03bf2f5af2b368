"""The web page of ``kvp universal``: the jog pad as an input device, and the 3D view.

A page of its own (``static/universal.html``, ``static/universal.js``) that reuses the web
jog pad's assets — its head and style sheet and its 3D arm view (``/static/view3d.js`` is
served from the pad's own folder, nothing is copied) — and the pad's safety rules:

* **hold to move**: an axis button held sends ``jog`` at once and every 25 ms; the signal is
  non-zero only while those arrive (:data:`HOLD_TIMEOUT`); letting go, the pointer leaving,
  the window losing focus or the tab being hidden send ``release``;
* **a page that is there**: every open page sends ``alive`` every 100 ms; the device's sample
  is as old as the newest ``alive`` (or ``jog``), so a frozen or vanished page goes silent
  and the server stops the arm (also in position mode: no return to the start without a
  page that is there); one page moves the arm at a time;
* the same rules as the pad, from the same code: the token, Origin and Host checks
  (:func:`~pyopenshowvar_apps.web.policy.refuse_connection`), strict JSON with bounded
  nesting and finite numbers only (:func:`~pyopenshowvar_apps.web.policy.parse_message`: a
  crafted message closes the page with a reason), the message rate
  (:class:`~pyopenshowvar_apps.web.policy.TokenBucket`), and the HTTP guard against slow and
  greedy clients (:mod:`pyopenshowvar_apps.web.httpguard`).

The page shows the arm (the server's link frames, scaled to the view), the target, and lets
the user switch arm, solver and mode. :class:`ViewServer` serves it for any input device
(``--view``); with ``--input web`` its :class:`WebInput` is the device.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import socket
import time
from pathlib import Path
from typing import Any

import numpy as np
import uvicorn
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

from ..web.httpguard import HEAD_TIMEOUT, TOTAL, ConnectionGuard, LogLimit, guarded_protocols
from ..web.policy import TokenBucket, Violation, parse_message, refuse_connection
from ..web.server import (
    _CLOSED,
    MAX_MESSAGE,
    STATIC,
    build_page,
    close_quietly,
    guarded_app,
)
from .inputs import InputDevice, InputSample

__all__ = ["HOLD_TIMEOUT", "ViewServer", "WebInput", "create_app"]

log = logging.getLogger(__name__)

OWN_STATIC = Path(__file__).with_name("static")
#: A held button counts while its keep-alives (every 25 ms) arrive within this (the pad's).
HOLD_TIMEOUT = 0.1
MAX_PAGES = 8
_AXIS = {"X": 0, "Y": 1, "Z": 2}
_SWITCHES = ("arm", "solver", "mode")


class _Page:
    """One open page: its latest unsent state, its message budget, when it last spoke."""

    def __init__(self, ws: WebSocket) -> None:
        self.ws = ws
        self.state: dict[str, Any] | None = None
        self.wake = asyncio.Event()
        self.bucket = TokenBucket(time.monotonic())
        self.seen = time.monotonic()


class WebInput(InputDevice):
    """The pages' jog buttons as the universal input device (see the module docstring)."""

    name = "web"

    def __init__(self) -> None:
        self.pages: set[_Page] = set()
        self.owner: _Page | None = None
        self.signal = np.zeros(3)
        self.held_at = -1e9
        self.commands: list[tuple[str, str]] = []

    def handle(self, page: _Page, msg: dict[str, Any]) -> str | None:
        """Apply one message of ``page``; returns why it was refused, or None."""
        now = time.monotonic()
        page.seen = now
        kind = msg.get("t")
        if kind == "alive":
            return None
        if kind == "jog":
            if (
                self.owner is not None
                and self.owner is not page
                and now - self.held_at <= HOLD_TIMEOUT
            ):
                return "another page is moving the arm"
            key, direction = str(msg["key"]), int(msg["dir"])
            level = min(max(float(msg.get("level", 0.5)), 0.0), 1.0)
            if key not in _AXIS or direction not in (-1, 1):
                raise ValueError(f"bad jog {key!r} {direction}")
            self.owner, self.held_at = page, now
            self.signal = np.zeros(3)
            self.signal[_AXIS[key]] = direction * level
            return None
        if kind == "release":
            if self.owner is page:
                self.owner, self.signal = None, np.zeros(3)
            return None
        if kind == "switch":
            key, value = str(msg["key"]), str(msg["value"])[:64]
            if key not in _SWITCHES:
                raise ValueError(f"unknown switch {key!r}")
            self.commands.append((key, value))
            return None
        raise ValueError(f"unknown message type {kind!r}")

    def forget(self, page: _Page) -> None:
        self.pages.discard(page)
        if self.owner is page:
            self.owner, self.signal = None, np.zeros(3)

    def poll(self, now: float) -> InputSample | None:
        if not self.pages:
            return InputSample(now, np.zeros(3), connected=False)
        seen = max(p.seen for p in self.pages)
        held = self.owner is not None and now - self.held_at <= HOLD_TIMEOUT
        commands, self.commands = tuple(self.commands), []
        return InputSample(seen, self.signal.copy() if held else np.zeros(3), True, commands)


def create_app(
    server: Any, web_input: WebInput | None, *, token: str | None, hz: float
) -> Starlette:
    """The page, its static files, the pad's static files and the WebSocket."""
    view = _ViewPages(server, web_input, token=token, hz=hz)
    routes = [
        Route("/", view.index),
        Mount("/u", StaticFiles(directory=OWN_STATIC), name="own"),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
        WebSocketRoute("/ws", view.stream),
    ]
    app = guarded_app(routes, token)
    app.state.publish = view.publish
    return app


class _ViewPages:
    """The connected pages and the handlers behind the routes: :meth:`index`, :meth:`stream`
    (one page's connection) and :meth:`publish` (the server's state to every page)."""

    def __init__(
        self, server: Any, web_input: WebInput | None, *, token: str | None, hz: float
    ) -> None:
        self.server, self.web_input, self.token, self.hz = server, web_input, token, hz
        self.pages: set[_Page] = set()
        self.limit = LogLimit(log)  # what pages do wrong is logged, but never floods the log
        self.html = build_page("kvp universal", OWN_STATIC / "universal.html", ["/u/universal.css"])

    async def index(self, request: Request) -> Response:
        return Response(self.html, media_type="text/html")

    async def stream(self, ws: WebSocket) -> None:
        host = ws.client.host if ws.client else "?"
        why = refuse_connection(
            ws.headers.get("origin"), ws.headers.get("host", ""), ws.query_params.get("token"),
            self.token,
        )  # fmt: skip
        if why is not None:
            self.limit.warning(f"refused {host}", "refused a WebSocket from %s: %s", host, why)
            await close_quietly(ws, 1008, why)
            return
        if len(self.pages) >= MAX_PAGES:
            await close_quietly(ws, 1013, "too many pages")
            return
        await ws.accept()
        page = _Page(ws)
        self.pages.add(page)
        if self.web_input is not None:
            self.web_input.pages.add(page)
        await ws.send_text(json.dumps({"t": "hello", "input": self.web_input is not None,
                                       "hold_timeout": HOLD_TIMEOUT}))  # fmt: skip
        task = asyncio.create_task(self._sender(page))
        try:
            await self._receive_loop(page, host)
        except _CLOSED:
            pass  # a page going away is normal, never a traceback
        finally:
            self.pages.discard(page)
            if self.web_input is not None:
                self.web_input.forget(page)
            task.cancel()

    @staticmethod
    async def _sender(page: _Page) -> None:
        with contextlib.suppress(WebSocketDisconnect, RuntimeError):
            while True:
                await page.wake.wait()
                page.wake.clear()
                state, page.state = page.state, None
                if state is not None:
                    await page.ws.send_text(json.dumps(state))

    async def _receive_loop(self, page: _Page, host: str) -> None:
        ws = page.ws
        while True:
            message = await ws.receive()
            if message["type"] == "websocket.disconnect":
                return
            if not page.bucket.allow(time.monotonic()):
                await close_quietly(ws, 1008, "too many messages")
                return
            text = message.get("text")
            try:
                msg = parse_message(text if text is not None else message.get("bytes"))
            except Violation as exc:
                self.limit.warning(
                    f"closed {host}", "closed a WebSocket of %s: %s", host, exc.reason
                )
                await close_quietly(ws, exc.code, exc.reason)
                return
            self._handle(page, msg)
            # one message per turn of the event loop: a flooding page cannot stall others
            await asyncio.sleep(0)

    def _handle(self, page: _Page, msg: dict[str, Any]) -> None:
        try:
            if self.web_input is None:
                if msg.get("t") != "alive":
                    raise ValueError("this page only views: the input is another device")
                return
            why_not = self.web_input.handle(page, msg)
            if why_not is not None:
                page.state = {"t": "refused", "reason": why_not}
                page.wake.set()
        except (KeyError, TypeError, ValueError) as exc:
            page.state = {"t": "error", "message": str(exc)[:200]}
            page.wake.set()

    async def publish(self) -> None:
        while True:
            await asyncio.sleep(1.0 / self.hz)
            if not self.pages:
                continue
            state = {"t": "state", **self.server.status()}
            for page in self.pages:
                page.state = state
                page.wake.set()


class ViewServer:
    """Serves the page on ``bind:port`` (``port=0``: a free one) while the server runs."""

    def __init__(
        self, server: Any, web_input: WebInput | None, *, bind: str = "127.0.0.1",
        port: int = 0, token: str | None = None, hz: float = 20.0,
    ) -> None:  # fmt: skip
        self.app = create_app(server, web_input, token=token, hz=hz)
        self.bind, self.token = bind, token
        family = socket.AF_INET6 if ":" in bind else socket.AF_INET
        self.sock = socket.socket(family, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.sock.bind((bind, port))
        except OSError:
            self.sock.close()
            raise
        self.port: int = self.sock.getsockname()[1]
        self.guard = ConnectionGuard()
        self._tasks: list[asyncio.Task[Any]] = []
        self._server: uvicorn.Server | None = None

    @property
    def url(self) -> str:
        host = f"[{self.bind}]" if ":" in self.bind else self.bind
        return f"http://{host}:{self.port}/" + (f"#token={self.token}" if self.token else "")

    async def __aenter__(self) -> ViewServer:
        http, ws = guarded_protocols(self.guard)  # slow and greedy clients, as the pad's
        config = uvicorn.Config(
            self.app, log_level="warning", access_log=False, lifespan="off", http=http, ws=ws,
            ws_max_size=MAX_MESSAGE, ws_per_message_deflate=False, limit_concurrency=TOTAL,
            timeout_keep_alive=int(HEAD_TIMEOUT),
        )  # fmt: skip
        self._server = uvicorn.Server(config)
        self.sock.listen(32)
        self.sock.setblocking(False)
        self._tasks = [
            asyncio.create_task(self._server.serve(sockets=[self.sock]), name="universal-http"),
            asyncio.create_task(self.app.state.publish(), name="universal-view"),
        ]
        while not self._server.started:
            if self._tasks[0].done():
                self._tasks[0].result()
            await asyncio.sleep(0.01)
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self._server is not None:
            self._server.should_exit = True
            with contextlib.suppress(asyncio.TimeoutError, asyncio.CancelledError):
                await asyncio.wait_for(self._tasks[0], 5.0)
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self.sock.close()
