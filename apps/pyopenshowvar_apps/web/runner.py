"""Run the web jog pad: bind the socket, start the KVP link, the jog watchdog and uvicorn.

:class:`WebServer` is an async context manager, used by ``kvp web`` and by the tests
(``async with WebServer("127.0.0.1", emu.port, http_port=0) as web: web.url``). The socket is
bound before uvicorn starts, so ``http_port=0`` gives a known free port at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
from pathlib import Path
from types import TracebackType

import uvicorn

from pyopenshowvar import Client

from ..armpick import ArmChoice
from .httpguard import HEAD_TIMEOUT, TOTAL, ConnectionGuard, guarded_protocols
from .jog import JogController
from .robotlink import RobotLink
from .server import MAX_MESSAGE, WebConfig, create_app

__all__ = ["KRL_DIR", "WebServer", "lan_address"]

#: The shipped KVP_JOG program and its $CONFIG.DAT globals.
KRL_DIR = Path(__file__).with_name("krl")


def lan_address() -> str:
    """This machine's address on its default route (no packet is sent), else 127.0.0.1."""
    with contextlib.suppress(OSError), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.connect(("10.255.255.255", 1))
        return str(s.getsockname()[0])
    return "127.0.0.1"


def url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


class WebServer:
    """The jog pad for the robot at ``kvp_host:kvp_port``, served on ``bind:http_port``."""

    def __init__(
        self,
        kvp_host: str,
        kvp_port: int,
        *,
        bind: str = "127.0.0.1",
        http_port: int = 0,
        token: str | None = None,
        hz: float = 20.0,
        timeout: float = 2.0,
        emulated: bool = False,
        allow_motion_writes: bool = False,
        arm: ArmChoice | None = None,
    ) -> None:
        self.bind = bind
        # the arm drawn and jogged: ``arm``, else the one the robot's $MODEL_NAME[] names
        self.link = RobotLink(kvp_host, kvp_port, timeout=timeout, hz=hz, arm=arm)
        # Its own connection: a stop is never queued behind the live view's reads.
        self.control = Client(kvp_host, kvp_port, timeout=timeout, auto_reconnect=True,
                              keepalive=None)  # fmt: skip
        self.jog = JogController(self.control, self.link)
        self.config = WebConfig(
            token=token, emulated=emulated, allow_motion_writes=allow_motion_writes
        )
        self.app = create_app(self.link, self.jog, self.config)
        family = socket.AF_INET6 if ":" in bind else socket.AF_INET
        self.sock = socket.socket(family, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.sock.bind((bind, http_port))
        except OSError:
            self.sock.close()
            raise
        self.port: int = self.sock.getsockname()[1]
        self.guard = ConnectionGuard()
        self._tasks: list[asyncio.Task[None]] = []
        self._server: uvicorn.Server | None = None

    @property
    def url(self) -> str:
        """``http://HOST:PORT/`` as bound."""
        return f"http://{url_host(self.bind)}:{self.port}/"

    def page_url(self, host: str | None = None) -> str:
        """The address to open, with the token when one is required."""
        base = f"http://{url_host(host or self.bind)}:{self.port}/"
        return base + (f"#token={self.config.token}" if self.config.token else "")

    async def __aenter__(self) -> WebServer:
        http, ws = guarded_protocols(self.guard)  # slow and greedy clients (httpguard)
        config = uvicorn.Config(
            self.app,
            log_level="warning",
            access_log=False,  # the token travels in the WebSocket's query string
            lifespan="off",
            http=http,
            ws=ws,
            ws_max_size=MAX_MESSAGE,
            ws_per_message_deflate=False,
            limit_concurrency=TOTAL,
            timeout_keep_alive=int(HEAD_TIMEOUT),
        )
        self._server = uvicorn.Server(config)
        self.sock.listen(64)
        self.sock.setblocking(False)
        self._tasks = [
            asyncio.create_task(self.link.run(), name="kvp-web-link"),
            asyncio.create_task(self.jog.run(), name="kvp-web-jog"),
            asyncio.create_task(self._server.serve(sockets=[self.sock]), name="kvp-web-http"),
        ]
        while not self._server.started:
            if self._tasks[2].done():
                self._tasks[2].result()  # raise uvicorn's start-up error
            await asyncio.sleep(0.01)
        return self

    async def wait(self) -> None:
        """Until the HTTP server stops (Ctrl-C) or a background task fails."""
        await asyncio.wait(self._tasks, return_when=asyncio.FIRST_COMPLETED)
        for task in self._tasks:
            if task.done() and not task.cancelled() and task.exception() is not None:
                raise task.exception()  # type: ignore[misc]

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self.jog.jog is not None:
            await self.jog.stop(None, "server shutting down")
        if self._server is not None:
            self._server.should_exit = True
        http = self._tasks[2] if len(self._tasks) > 2 else None
        if http is not None:
            with contextlib.suppress(asyncio.TimeoutError, asyncio.CancelledError):
                await asyncio.wait_for(http, 5.0)
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await self.link.client.close()
        await self.control.close()
        self.sock.close()
