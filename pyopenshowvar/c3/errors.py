"""Errors of the C3 Bridge API; all derive from :class:`~pyopenshowvar.errors.KvpError`.

::

    KvpError
    ├── C3CommandError               the server answered a C3 message with a failure footer
    ├── UnsupportedError             the server cannot do this (KVP, or a C3 Bridge without
    │                                the message): raised before anything is sent
    ├── MotionNotAllowedError        a start or motion without allow_motion=True (nothing sent)
    │   (PermissionError)
    └── ProtocolError
        └── RequestTooLargeError     a name, value, count or file over a protocol or server limit
"""

from __future__ import annotations

from ..errors import KvpError, ProtocolError
from .replies import error_name

__all__ = [
    "C3CommandError",
    "MotionNotAllowedError",
    "RequestTooLargeError",
    "UnsupportedError",
]


class C3CommandError(KvpError):
    """A C3 Bridge message answered with failure; ``code`` is the footer's error code."""

    def __init__(self, what: str, code: int, *, endpoint: str = "", detail: str = "") -> None:
        where = f" on {endpoint}" if endpoint else ""
        extra = f": {detail}" if detail else ""
        super().__init__(f"{what} failed{where}: {error_name(code)}{extra}")
        self.what = what
        self.code = code
        self.endpoint = endpoint


class UnsupportedError(KvpError):
    """The server lacks the message or feature a method needs; nothing was sent for it."""


class MotionNotAllowedError(KvpError, PermissionError):
    """Starting a program or a motion needs ``allow_motion=True``; nothing was sent."""


class RequestTooLargeError(ProtocolError):
    """A request that cannot be sent: too many names, too long a name, too big a file."""
