"""Who may talk to the gateway: password hashes, the user check, the server certificate.

Passwords are never stored: the cell file holds ``pbkdf2-sha256$ITERATIONS$SALT$HASH``
(``kvp gateway --hash-password`` makes one). The server certificate is generated once (RSA
2048, self-signed, the application URI in its subjectAltName as OPC UA requires) and kept in
the cell's PKI folder, the private key readable by its owner only; clients pin its SHA-256
fingerprint, which the gateway logs at start.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import ipaddress
import logging
import os
import secrets
import socket
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from .cell import UserEntry

__all__ = [
    "GatewayUserManager",
    "check_hash_format",
    "ensure_certificate",
    "hash_password",
    "verify_password",
]

log = logging.getLogger(__name__)

_SCHEME = "pbkdf2-sha256"
_ITERATIONS = 200_000
# Bounds keep a hostile cell file from making every login take minutes.
_MIN_ITERATIONS, _MAX_ITERATIONS = 10_000, 2_000_000
_MAX_PASSWORD = 1024


def hash_password(password: str, *, iterations: int = _ITERATIONS) -> str:
    salt = secrets.token_bytes(16)
    digest = hashlib.pbkdf2_hmac("sha256", password.encode(), salt, iterations)
    return "$".join([_SCHEME, str(iterations), _b64(salt), _b64(digest)])


def check_hash_format(text: str) -> str | None:
    """None when ``text`` is a hash :func:`hash_password` could have made, else why not."""
    parts = text.split("$")
    if len(parts) != 4 or parts[0] != _SCHEME:
        return f"expected {_SCHEME}$ITERATIONS$SALT$HASH"
    if not parts[1].isdigit() or not _MIN_ITERATIONS <= int(parts[1]) <= _MAX_ITERATIONS:
        return f"iterations must be within {_MIN_ITERATIONS}..{_MAX_ITERATIONS}"
    try:
        salt, digest = _unb64(parts[2]), _unb64(parts[3])
    except ValueError:
        return "salt and hash must be base64"
    if len(salt) < 8 or len(digest) != 32:
        return "salt of at least 8 bytes and a 32-byte hash expected"
    return None


def verify_password(password: str, stored: str) -> bool:
    if check_hash_format(stored) is not None or len(password) > _MAX_PASSWORD:
        return False
    _, iterations, salt, digest = stored.split("$")
    mine = hashlib.pbkdf2_hmac("sha256", password.encode(), _unb64(salt), int(iterations))
    return hmac.compare_digest(mine, _unb64(digest))


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode().rstrip("=")


def _unb64(text: str) -> bytes:
    try:
        return base64.b64decode(text + "=" * (-len(text) % 4), validate=True)
    except (ValueError, TypeError) as exc:
        raise ValueError("bad base64") from exc


class GatewayUserManager:
    """asyncua's user-manager interface: a User for a known name and password, else None.

    With ``anonymous`` (loopback without security) a session without credentials is let in as
    a plain user; a session that does present credentials must present valid ones. Nobody gets
    the Admin role, so no client can add or delete nodes.
    """

    def __init__(self, users: Iterable[UserEntry], *, anonymous: bool) -> None:
        self._users = {u.name: u.password_hash for u in users}
        self._anonymous = anonymous

    def get_user(
        self,
        iserver: Any,
        username: str | None = None,
        password: str | None = None,
        certificate: Any = None,
    ) -> Any:
        from asyncua.crypto.permission_rules import User, UserRole

        if username is None and password is None:
            return User(role=UserRole.User, name="anonymous") if self._anonymous else None
        stored = self._users.get(username or "")
        if stored is None or password is None or not verify_password(password, stored):
            log.warning("refused login of user %r", username)
            return None
        return User(role=UserRole.User, name=username)


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
