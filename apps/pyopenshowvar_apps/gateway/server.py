"""The gateway: one asyncua server, one :class:`~.poller.RobotPoller` task per robot.

::

    async with Gateway(load_cell("cell.toml")) as gw:
        print(gw.url)               # opc.tcp://127.0.0.1:4840 (the real port when 0 was asked)
        await gw.serve_forever()

Start-up: asyncua's standard address space, the DI/IA/Robotics NodeSets, then every robot's
nodes; :attr:`Gateway.timings` has the seconds each step took (``kvp gateway`` logs them and
bench/gateway.py reports them). Security (docs/gateway.md): on a loopback endpoint without a
[security] table the server offers None/Anonymous only; otherwise it offers nothing but
Basic256Sha256 Sign&Encrypt with user name and password, so an anonymous or unencrypted
client is refused before it sees a single node; every login is decided by
:class:`~.security.LoginGuard` (off the event loop, rate-limited per client address, only
trusted client certificates when ``trusted_clients`` is set) through :mod:`.sessions`.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import importlib.metadata
import logging
import time
from datetime import UTC, datetime
from types import TracebackType
from typing import Self

from asyncua.common.connection import TransportLimits

from . import ua
from .cell import CellConfig
from .cellnodes import CellNodes, RobotNodes
from .livenodes import Sink
from .model import GATEWAY_URI, Instantiator, load_nodesets
from .poller import RobotPoller
from .robotics import RobotBuilder, build_cell
from .security import LoginGuard, ensure_certificate, trust_check
from .sessions import GatewayServer
from .ua import Server
from .writes import WRITE_METHOD, add_write_method

__all__ = ["Gateway"]

log = logging.getLogger(__name__)

_MAX_MESSAGE = 16 * 1024 * 1024
#: The robots' polls are spread over this many slots per poll period (robot i in slot i % 5):
#: 50 robots at 10 Hz wake the event loop 50 times a second, ten polls at a time, instead of
#: 500 times, or all 50 at once (a burst that delays the last robot's values).
POLL_SLOTS = 5


class Gateway:
    """Serves a cell (see the module doc). ``start()``/``stop()`` or ``async with``."""

    def __init__(self, cell: CellConfig) -> None:
        self.cell = cell
        self.server: Server | None = None
        self.nodes: CellNodes | None = None
        self.robots: dict[str, RobotNodes] = {}
        self.pollers: dict[str, RobotPoller] = {}
        self.sink: Sink | None = None
        self.timings: dict[str, float] = {}
        self.fingerprint: str | None = None
        self.port = 0
        self._tasks: list[asyncio.Task[None]] = []
        sec = cell.security
        self.guard = LoginGuard(
            sec.users,
            anonymous=not sec.enabled,
            max_failures=sec.max_failed_logins,
            window=sec.lockout_seconds,
        )

    @property
    def url(self) -> str:
        return f"opc.tcp://{_url_host(self.cell.host)}:{self.port}"

    @property
    def application_uri(self) -> str:
        return f"{GATEWAY_URI}:{self.cell.name}"

    async def start(self) -> None:
        # Start-up allocates a few million long-lived objects (the address space): with the
        # collector on, its collections rescan them again and again, a third of the start-up
        # CPU. Nothing built here is garbage, so it is off until the server is built.
        collecting = gc.isenabled()
        gc.disable()
        try:
            await self._start()
        finally:
            if collecting:
                gc.enable()

    async def _start(self) -> None:
        cell = self.cell
        t0 = time.perf_counter()
        server = GatewayServer(self.guard)
        await server.init()
        self.timings["address_space"] = time.perf_counter() - t0
        self.server = server
        server.set_server_name(f"pyopenshowvar kvp gateway ({cell.name})")
        await server.set_application_uri(self.application_uri)
        server.product_uri = GATEWAY_URI
        server.manufacturer_name = "pyopenshowvar"
        # init() filled BuildInfo with asyncua's own product; a client must see ours
        await server.set_build_info(
            GATEWAY_URI, "pyopenshowvar", "pyopenshowvar kvp gateway", _version(), _version(),
            datetime.now(UTC),
        )  # fmt: skip
        server.allow_remote_admin(False)
        # asyncua accepts 100 MB messages by default; a SCADA's requests and our answers are
        # far below 16 MB, and a client must not make us buffer more
        server.limits = TransportLimits(
            max_chunk_count=_MAX_MESSAGE // 65535 + 1, max_message_size=_MAX_MESSAGE
        )
        server.set_endpoint(f"opc.tcp://{_url_host(cell.host)}:{cell.port}")
        await self._security(server)

        t1 = time.perf_counter()
        ns = await load_nodesets(server)
        self.timings["nodesets"] = time.perf_counter() - t1
        t2 = time.perf_counter()
        inst = Instantiator(server, ns[GATEWAY_URI])
        self.nodes = await build_cell(server, inst, ns, cell.name)
        builder = RobotBuilder(server, inst, self.nodes)
        self.sink = Sink(server)
        for index, robot in enumerate(cell.robots):
            nodes = await builder.build(robot.name, robot.exposed)
            self.robots[robot.name] = nodes
            phase = (index % POLL_SLOTS) / POLL_SLOTS
            # speeds None: the arm's, known once $MODEL_NAME[] is read (poller._identity)
            poller = RobotPoller(robot, nodes, self.nodes, self.sink, robot.max_axis_speed, phase)
            self.pollers[robot.name] = poller
            if robot.writable:
                method_id = ua.node_id(
                    f"{ua.path_of(nodes.controller)}.{WRITE_METHOD}", ns[GATEWAY_URI]
                )
                await add_write_method(
                    server.get_node(nodes.controller), method_id, ns[GATEWAY_URI], poller
                )
                nodes.write_method = method_id
        self.timings["robots"] = time.perf_counter() - t2

        await server.start()
        self._bound_port(server)
        for name, poller in self.pollers.items():
            self._tasks.append(asyncio.create_task(poller.run(), name=f"poll {name}"))
        self.timings["total"] = time.perf_counter() - t0
        log.info(
            "serving %s: %d robots; start-up %.2f s (address space %.2f, NodeSets %.2f, robots %.2f)",
            self.url,
            len(cell.robots),
            self.timings["total"],
            self.timings["address_space"],
            self.timings["nodesets"],
            self.timings["robots"],
        )

    async def _security(self, server: Server) -> None:
        sec = self.cell.security
        if not sec.enabled:
            server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
            server.set_identity_tokens([ua.AnonymousIdentityToken])
            return
        cert, key, self.fingerprint = await asyncio.to_thread(
            ensure_certificate, sec.pki_dir, self.application_uri, self.cell.host
        )
        await server.load_certificate(str(cert))
        await server.load_private_key(str(key))
        server.set_security_policy([ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt])
        server.set_identity_tokens([ua.UserNameIdentityToken])
        if sec.trusted_clients is not None:
            from asyncua.crypto.truststore import TrustStore
            from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions

            store = TrustStore([sec.trusted_clients], [])
            await store.load()
            # checked at every login, on the secure channel's own certificate (asyncua checks
            # CreateSession's copy, which a client may leave out)
            self.guard.trusts = trust_check(store)
            # time range and application URI as usual, plus: in the trust store (the default
            # options check no trust at all)
            opts = (
                CertificateValidatorOptions.BASIC_VALIDATION
                | CertificateValidatorOptions.TRUSTED
                | CertificateValidatorOptions.PEER_CLIENT
            )
            server.set_certificate_validator(CertificateValidator(opts, trust_store=store))
        log.info("server certificate %s, SHA-256 %s", cert, self.fingerprint)

    def _bound_port(self, server: Server) -> None:
        """Learn the real port (port 0 in the cell file) and advertise it in every endpoint."""
        assert server.bserver is not None
        self.port = server.bserver.port
        url = self.url
        server.set_endpoint(url)
        for edp in server.iserver.endpoints:
            edp.EndpointUrl = url
            edp.Server.DiscoveryUrls = [url]

    async def serve_forever(self) -> None:
        await asyncio.Event().wait()

    async def stop(self) -> None:
        for poller in self.pollers.values():
            poller.stop()
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        self._tasks.clear()
        if self.server is not None:
            await self.server.stop()
            self.server = None
        self.guard.close()

    async def __aenter__(self) -> Self:
        try:
            await self.start()
        except BaseException:
            await self.stop()
            raise
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.stop()


def _version() -> str:
    try:
        return importlib.metadata.version("pyopenshowvar")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - a source tree
        return "0"


def _url_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host
