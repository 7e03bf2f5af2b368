"""Password hashes of the gateway's users: how they are made, checked and verified.

The cell file holds ``pbkdf2-sha256$ITERATIONS$SALT$HASH`` per user (``kvp gateway
--hash-password`` makes one with :func:`hash_password`); :mod:`.cell` checks its format when it
reads the file, :mod:`.security` verifies logins against it. Kept apart from both so the cell
file reader and the login rules share the user type without importing each other.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import secrets
from dataclasses import dataclass

__all__ = ["UserEntry", "check_hash_format", "hash_password", "verify_password"]


@dataclass(frozen=True)
class UserEntry:
    name: str
    password_hash: str


SCHEME = "pbkdf2-sha256"
ITERATIONS = 200_000
# Bounds keep a hostile cell file from making every login take minutes.
_MIN_ITERATIONS, _MAX_ITERATIONS = 10_000, 2_000_000
MAX_PASSWORD = 1024


def hash_password(password: str, *, iterations: int = ITERATIONS) -> str:
    salt = secrets.token_bytes(16)
    digest = hashlib.pbkdf2_hmac("sha256", password.encode(), salt, iterations)
    return "$".join([SCHEME, str(iterations), b64(salt), b64(digest)])


def check_hash_format(text: str) -> str | None:
    """None when ``text`` is a hash :func:`hash_password` could have made, else why not."""
    parts = text.split("$")
    if len(parts) != 4 or parts[0] != SCHEME:
        return f"expected {SCHEME}$ITERATIONS$SALT$HASH"
    if not parts[1].isdigit() or not _MIN_ITERATIONS <= int(parts[1]) <= _MAX_ITERATIONS:
        return f"iterations must be within {_MIN_ITERATIONS}..{_MAX_ITERATIONS}"
    try:
        salt, digest = unb64(parts[2]), unb64(parts[3])
    except ValueError:
        return "salt and hash must be base64"
    if len(salt) < 8 or len(digest) != 32:
        return "salt of at least 8 bytes and a 32-byte hash expected"
    return None


def verify_password(password: str, stored: str) -> bool:
    if check_hash_format(stored) is not None or len(password) > MAX_PASSWORD:
        return False
    _, iterations, salt, digest = stored.split("$")
    mine = hashlib.pbkdf2_hmac("sha256", password.encode(), unb64(salt), int(iterations))
    return hmac.compare_digest(mine, unb64(digest))


def b64(data: bytes) -> str:
    return base64.b64encode(data).decode().rstrip("=")


def unb64(text: str) -> bytes:
    try:
        return base64.b64decode(text + "=" * (-len(text) % 4), validate=True)
    except (ValueError, TypeError) as exc:
        raise ValueError("bad base64") from exc
