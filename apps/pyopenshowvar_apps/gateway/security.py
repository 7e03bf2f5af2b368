"""Who may talk to the gateway: password hashes, the login rules, the server certificate.

Passwords are never stored: the cell file holds ``pbkdf2-sha256$ITERATIONS$SALT$HASH``
(``kvp gateway --hash-password`` makes one; :mod:`.passwords` makes and verifies them). :class:`LoginGuard` decides every login: off the
event loop, at the same cost for every user name, with a limit of failed logins per client
address and, where configured, only from trusted client certificates. The server certificate
is generated once (RSA 2048, self-signed, the application URI in its subjectAltName as OPC UA
requires) and kept in the cell's PKI folder, the private key readable by its owner only;
clients pin its SHA-256 fingerprint, which the gateway logs at start.
"""

from __future__ import annotations

import asyncio
import hashlib
import ipaddress
import logging
import os
import secrets
import socket
import time
from collections import deque
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from contextvars import ContextVar
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from .passwords import (
    ITERATIONS,
    MAX_PASSWORD,
    SCHEME,
    UserEntry,
    b64,
    check_hash_format,
    hash_password,
    verify_password,
)

__all__ = [
    "VERDICT",
    "LoginGuard",
    "Verdict",
    "check_hash_format",
    "ensure_certificate",
    "hash_password",
    "trust_check",
    "verify_password",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Verdict:
    """The outcome of one login, checked before asyncua asks :meth:`LoginGuard.get_user`."""

    username: str | None
    password_digest: bytes
    #: the user let in; None: refused
    user: str | None

    def matches(self, username: str | None, password: str | None) -> bool:
        return self.username == username and self.password_digest == _digest(password)


#: The verdict of the login being activated (set by :mod:`.sessions` around asyncua's
#: ActivateSession handling, which calls the user manager synchronously on the event loop).
VERDICT: ContextVar[Verdict | None] = ContextVar("gateway_login_verdict", default=None)


def _digest(password: str | None) -> bytes:
    if password is None:
        return b""
    return hashlib.sha256(b"pw:" + password.encode("utf-8", "surrogatepass")).digest()


def _iterations(stored: str) -> int:
    return int(stored.split("$")[1])


class LoginGuard:
    """Who may log in, checked without stalling the event loop and without telling who exists.

    * :meth:`check` costs the same for every attempt: an unknown user, a missing, empty or
      oversized password are checked against a dummy hash, and every check is padded to the
      largest iteration count among the users, so the time to refuse names no user;
    * :meth:`login` runs :meth:`check` on one thread of its own (PBKDF2 releases the GIL, so
      it never holds the event loop), at most :attr:`max_pending` logins waiting at once
      (more are refused at once and logged);
    * a client address with ``max_failures`` failed logins within ``window`` seconds is
      :meth:`locked`: its logins are refused unchecked (and :mod:`.sessions` closes its new
      connections) until the oldest failure ages out; a login that succeeds clears the
      address's failures;
    * with a trust check (``trusts``, when the cell file names ``trusted_clients``), a login
      over a secure channel whose client certificate is not trusted is refused too;
    * asyncua's user-manager interface (:meth:`get_user`): an anonymous session is a plain user
      only with ``anonymous`` (loopback without security); anything that presents a user name
      or a password gets the verdict :meth:`login` reached, or is refused. Nobody gets the
      Admin role, so no client can add or delete nodes.
    """

    #: logins waiting for the password thread before more are refused outright
    max_pending = 4
    #: client addresses whose failures are remembered (the oldest are forgotten beyond it)
    max_addresses = 10_000

    def __init__(
        self,
        users: Iterable[UserEntry],
        *,
        anonymous: bool,
        max_failures: int = 5,
        window: float = 60.0,
        trusts: Callable[[bytes | None], bool] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._users = {u.name: u.password_hash for u in users}
        self.anonymous = anonymous
        self.max_failures = max_failures
        self.window = window
        self.trusts = trusts
        self.clock = clock
        self.cost = max((_iterations(h) for h in self._users.values()), default=ITERATIONS)
        # a hash of no password at all (a random digest): checking against it costs what
        # checking a real one does, and nothing matches it
        random_hash = (b64(secrets.token_bytes(16)), b64(secrets.token_bytes(32)))
        self._dummy = "$".join([SCHEME, str(self.cost), *random_hash])
        self._failures: dict[str, deque[float]] = {}
        self._pending = 0
        self._executor = ThreadPoolExecutor(1, thread_name_prefix="gateway-login")

    # ------------------------------------------------------------------ the rules

    def check(self, username: str | None, password: str | None) -> bool:
        """Whether ``password`` is ``username``'s, at the same cost whatever the answer."""
        stored = self._users.get(username) if username else None
        usable = password is not None and 0 < len(password) <= MAX_PASSWORD
        target = stored if stored is not None else self._dummy
        match = verify_password(password if usable and password else "", target)
        pad = self.cost - _iterations(target)
        if pad > 0:  # a user hashed with fewer iterations must not stand out either
            hashlib.pbkdf2_hmac("sha256", b"", b"pad", pad)
        return match and stored is not None and usable

    def locked(self, address: str) -> bool:
        """Whether ``address`` has used up its failed logins (see the class doc)."""
        failures = self._failures.get(address)
        if not failures:
            return False
        horizon = self.clock() - self.window
        while failures and failures[0] <= horizon:
            failures.popleft()
        if not failures:
            del self._failures[address]
            return False
        return len(failures) >= self.max_failures

    def failed(self, address: str) -> None:
        failures = self._failures.pop(address, None) or deque(maxlen=self.max_failures)
        failures.append(self.clock())
        self._failures[address] = failures  # re-inserted: the dict stays ordered by activity
        while len(self._failures) > self.max_addresses:
            del self._failures[next(iter(self._failures))]

    def succeeded(self, address: str) -> None:
        self._failures.pop(address, None)

    async def login(
        self,
        address: str,
        username: str | None,
        password: str | None,
        certificate: bytes | None = None,
    ) -> str | None:
        """The user ``username`` logs in as, or None; never blocks the event loop."""
        if self.locked(address):
            log.warning("refused login of %r from %s: too many failed logins", username, address)
            return None
        if self.trusts is not None and not self.trusts(certificate):
            self.failed(address)
            log.warning("refused login of %r from %s: client certificate not trusted",
                        username, address)  # fmt: skip
            return None
        if self._pending >= self.max_pending:
            log.warning("refused login of %r from %s: %d logins already waiting",
                        username, address, self._pending)  # fmt: skip
            return None
        self._pending += 1
        try:
            loop = asyncio.get_running_loop()
            ok = await loop.run_in_executor(self._executor, self.check, username, password)
        finally:
            self._pending -= 1
        if ok:
            self.succeeded(address)
            return username
        self.failed(address)
        log.warning("refused login of %r from %s", username, address)
        return None

    def close(self) -> None:
        self._executor.shutdown(wait=False, cancel_futures=True)

    # ------------------------------------------------------------------ asyncua's interface

    def get_user(
        self,
        iserver: Any,
        username: str | None = None,
        password: str | None = None,
        certificate: Any = None,
    ) -> Any:
        from asyncua.crypto.permission_rules import User, UserRole

        if username is None and password is None:
            return User(role=UserRole.User, name="anonymous") if self.anonymous else None
        verdict = VERDICT.get()
        if verdict is None or not verdict.matches(username, password):
            # asyncua activated a session without the check of .sessions: never let it in
            log.error("login of %r reached the user manager unchecked: refused", username)
            return None
        if verdict.user is None:
            return None
        return User(role=UserRole.User, name=verdict.user)


def trust_check(store: Any) -> Callable[[bytes | None], bool]:
    """``trusts`` for :class:`LoginGuard`: a DER certificate within its validity and in the
    trust store (asyncua's TrustStore, loaded from ``trusted_clients``)."""
    from cryptography import x509

    def trusts(der: bytes | None) -> bool:
        if not der:
            return False
        try:
            cert = x509.load_der_x509_certificate(der)
        except ValueError:
            return False
        now = datetime.now(UTC)
        if not cert.not_valid_before_utc <= now <= cert.not_valid_after_utc:
            return False
        return bool(store.is_trusted(cert))

    return trusts


def ensure_certificate(pki_dir: Path, app_uri: str, host: str) -> tuple[Path, Path, str]:
    """The server's (certificate DER, key PEM, SHA-256 fingerprint), generated when missing.

    A certificate whose subjectAltName lacks ``app_uri`` or ``host`` (the cell was renamed or
    moved) is replaced; the key is kept.
    """
    from asyncua.crypto import cert_gen
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import rsa
    from cryptography.x509.oid import ExtendedKeyUsageOID

    pki_dir.mkdir(parents=True, exist_ok=True)
    cert_path, key_path = pki_dir / "gateway-cert.der", pki_dir / "gateway-key.pem"
    if key_path.is_file():
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
        if not isinstance(key, rsa.RSAPrivateKey):
            raise ValueError(f"{key_path}: not an RSA key")
    else:
        key = cert_gen.generate_private_key()
        fd = os.open(key_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as f:
            f.write(cert_gen.dump_private_key_as_pem(key))
    # a wildcard bind (0.0.0.0, ::) is no name a client connects to: the host name is
    names = {socket.gethostname()} | ({host} if host not in ("0.0.0.0", "::", "") else set())
    cert = None
    if cert_path.is_file():
        cert = x509.load_der_x509_certificate(cert_path.read_bytes())
        if not _covers(cert, app_uri, names) or cert.public_key() != key.public_key():
            cert = None
    if cert is None:
        alt: list[x509.GeneralName] = [x509.UniformResourceIdentifier(app_uri)]
        alt += [_general_name(n) for n in sorted(names) if n]
        cert = cert_gen.generate_self_signed_app_certificate(
            key,
            "pyopenshowvar kvp gateway",
            {"organizationName": "pyopenshowvar"},
            alt,
            extended=[ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
            days=3650,
        )
        cert_path.write_bytes(cert.public_bytes(serialization.Encoding.DER))
        log.info("generated the gateway certificate %s", cert_path)
    fingerprint = cert.fingerprint(hashes.SHA256()).hex(":")
    return cert_path, key_path, fingerprint


def _general_name(name: str) -> Any:
    """An IP address as an iPAddress entry, anything else as a dNSName (RFC 5280)."""
    from cryptography import x509

    try:
        return x509.IPAddress(ipaddress.ip_address(name))
    except ValueError:
        return x509.DNSName(name)


def _covers(cert: Any, app_uri: str, names: set[str]) -> bool:
    from cryptography import x509

    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return False
    uris = set(san.get_values_for_type(x509.UniformResourceIdentifier))
    have = set(san.get_values_for_type(x509.DNSName))
    have |= {str(ip) for ip in san.get_values_for_type(x509.IPAddress)}
    return app_uri in uris and {n for n in names if n} <= have
