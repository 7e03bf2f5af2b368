"""asyncua's server connections with the gateway's login rules (:class:`~.security.LoginGuard`).

asyncua checks a user's password inside its ActivateSession handling, synchronously, on the
event loop: a PBKDF2 check of 200 000 iterations there stalls every robot's polls for a tenth
of a second and more, once per login attempt. So the gateway's connections are asyncua's own
with two hooks:

* a connection from a client address that is locked out (too many failed logins) gets an
  OPC UA Error message (BadSecurityChecksFailed) and is closed as soon as it is accepted,
  before any message costs a cryptographic operation;
* before asyncua handles an ActivateSession request, its user token is decrypted and the
  login decided by :meth:`LoginGuard.login <.security.LoginGuard.login>` (off the event loop,
  with the channel's client certificate); asyncua's synchronous call of the user manager then
  only reads that verdict (:data:`~.security.VERDICT`). A login the hook did not see is
  refused, so a change inside asyncua fails closed.

:class:`GatewayServer` is an asyncua ``Server`` whose ``start()`` builds the binary server
with these connections; it refuses to serve if it could not.
"""

from __future__ import annotations

import logging
from typing import Any

from asyncua.server import server as _server_module
from asyncua.server.binary_server_asyncio import BinaryServer, OPCUAProtocol
from asyncua.server.uaprocessor import UaProcessor
from asyncua.ua.ua_binary import struct_from_binary

from . import ua
from .security import VERDICT, LoginGuard, Verdict, _digest
from .ua import Server

__all__ = ["GatewayServer"]

log = logging.getLogger(__name__)

_ACTIVATE = ua.node_id(ua.ObjectIds.ActivateSessionRequest_Encoding_DefaultBinary)
#: what a locked-out client is told before its connection is closed
_LOCKED = ua.StatusCodes.BadSecurityChecksFailed


def _address(peer: Any) -> str:
    """The client's IP address (asyncio's peername is (host, port[, ...]))."""
    return str(peer[0]) if isinstance(peer, tuple) and peer else str(peer)


class _Processor(UaProcessor):
    guard: LoginGuard

    async def _process_message(self, typeid: Any, requesthdr: Any, seqhdr: Any, body: Any) -> Any:
        if typeid != _ACTIVATE:
            # asyncua's UaProcessor._process_message has no annotations
            return await super()._process_message(typeid, requesthdr, seqhdr, body)  # type: ignore[no-untyped-call]
        verdict = await self._verdict(requesthdr, body.copy())
        token = VERDICT.set(verdict)
        try:
            return await super()._process_message(typeid, requesthdr, seqhdr, body)  # type: ignore[no-untyped-call]
        finally:
            VERDICT.reset(token)

    async def _verdict(self, requesthdr: Any, body: Any) -> Verdict | None:
        """The login of this ActivateSession, decided off the loop; None when it has no user
        token (anonymous) or one asyncua will refuse anyway."""
        session = self.session or self.iserver.lookup_external_session(
            requesthdr.AuthenticationToken
        )
        if session is None:
            return None
        try:
            params = struct_from_binary(ua.ActivateSessionParameters, body)
            token = params.UserIdentityToken
            if not isinstance(token, ua.UserNameIdentityToken):
                return None
            username, password = self.iserver.decrypt_user_token(session, token)
        except Exception:  # asyncua refuses the same token with its own status
            return None
        peer_certificate = self._connection.security_policy.peer_certificate
        user = await self.guard.login(_address(self.name), username, password, peer_certificate)
        return Verdict(username, _digest(password), user)


class _Protocol(OPCUAProtocol):
    guard: LoginGuard
    _refused: Any = None

    def connection_made(self, transport: Any) -> None:
        address = _address(transport.get_extra_info("peername"))
        if self.guard.locked(address):
            log.warning("refused a connection from %s: too many failed logins", address)
            self._refused = transport  # answered at its first message (data_received)
            return
        super().connection_made(transport)
        if self.processor is not None:  # asyncua's own, replaced before it saw a message
            processor = _Processor(self.iserver, transport, self.limits)
            processor.guard = self.guard
            processor.set_policies(self.policies)  # type: ignore[no-untyped-call]  # unannotated in asyncua
            self.processor = processor

    def data_received(self, data: bytes) -> None:
        if self._refused is None:
            super().data_received(data)
            return
        # an OPC UA Error message in answer to the client's Hello (sent before it, a client
        # may not be listening yet): it fails at once and says why; then the socket closes
        transport, self._refused = self._refused, None
        transport.write(ua.error_frame(_LOCKED, "too many failed logins; try later"))
        transport.close()


class _BinaryServer(BinaryServer):
    guard: LoginGuard

    def _make_protocol(self) -> OPCUAProtocol:
        protocol = _Protocol(
            iserver=self.iserver,
            policies=self._policies,
            clients=self.clients,
            closing_tasks=self.closing_tasks,
            limits=self.limits,
        )
        protocol.guard = self.guard
        return protocol


class GatewayServer(Server):
    """asyncua's Server with the gateway's connections (see the module doc)."""

    def __init__(self, guard: LoginGuard) -> None:
        # asyncua annotates user_manager as its UserManager class but only calls get_user(),
        # which LoginGuard has (a subclass would make .security import asyncua, which it defers)
        super().__init__(user_manager=guard)  # type: ignore[arg-type]
        self.guard = guard

    async def start(self) -> None:
        guard = self.guard

        class Bound(_BinaryServer):
            def __init__(self, *args: Any, **kw: Any) -> None:
                super().__init__(*args, **kw)
                self.guard = guard

        # asyncua's Server.start() builds its BinaryServer by this module-level name
        original = _server_module.BinaryServer  # type: ignore[attr-defined]  # imported, not exported
        setattr(_server_module, "BinaryServer", Bound)  # noqa: B010 - a module attribute
        try:
            await super().start()
        finally:
            setattr(_server_module, "BinaryServer", original)  # noqa: B010
        if not isinstance(self.bserver, _BinaryServer):
            await super().stop()
            raise RuntimeError("asyncua did not take the gateway's connections: not serving")
