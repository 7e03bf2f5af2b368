"""The exception hierarchy of pyopenshowvar, in one place.

Every error a user can meet derives from :class:`KvpError`. Where a builtin exception fits,
the class also derives from it, so generic handlers keep working::

    KvpError
    ├── KvpConnectionError (ConnectionError)   cannot connect, connection lost or closed
    │   └── KvpStalledError                    the server stopped answering; connection closed
    ├── KvpTimeoutError (TimeoutError)         no reply within the call's timeout
    ├── ProtocolError (ValueError)             malformed frame, unexpected reply
    ├── VariableError                          a problem with one named variable
    │   ├── UnknownVariableError (LookupError) empty value with success status (KVP's "unknown")
    │   ├── ReadFailedError                    the proxy answered a read with failure status
    │   └── WriteRefusedError                  the proxy answered a write with failure status
    └── KrlValueError (ValueError)             text that is not a KRL value, or a value of the wrong type

Messages name the variable and the host/port whenever they are known, because in a control loop
talking to several controllers "read failed" alone is useless.
"""

from __future__ import annotations

__all__ = [
    "KrlValueError",
    "KvpConnectionError",
    "KvpError",
    "KvpStalledError",
    "KvpTimeoutError",
    "ProtocolError",
    "ReadFailedError",
    "UnknownVariableError",
    "VariableError",
    "WriteRefusedError",
]


class KvpError(Exception):
    """Base class of every pyopenshowvar error."""


class KvpConnectionError(KvpError, ConnectionError):
    """The TCP connection could not be opened, was lost, or is closed."""


class KvpStalledError(KvpConnectionError):
    """Timed-out requests fill the in-flight window: the server stopped answering.

    The connection was marked unhealthy and closed. ``sent_nothing`` is True when the call that
    noticed had not sent anything yet, so retrying it on a new connection cannot apply a write
    twice (the client does that when ``auto_reconnect`` is on).
    """

    def __init__(self, message: str, *, sent_nothing: bool = False) -> None:
        super().__init__(message)
        self.sent_nothing = sent_nothing


class KvpTimeoutError(KvpError, TimeoutError):
    """A request got no reply within its timeout. The connection stays usable."""


class ProtocolError(KvpError, ValueError):
    """Bytes that do not follow the KUKAVARPROXY framing (bad lengths, oversize, garbage)."""


class VariableError(KvpError):
    """An error about one variable; ``name`` and ``endpoint`` say which and where."""

    def __init__(self, message: str, *, name: str = "", endpoint: str = "") -> None:
        where = f" on {endpoint}" if endpoint else ""
        super().__init__(f"{message}: {name!r}{where}" if name else f"{message}{where}")
        self.name = name
        self.endpoint = endpoint


class UnknownVariableError(VariableError, LookupError):
    """The proxy answered an empty value with success status.

    KUKAVARPROXY 9.0 does this for variables that do not exist, are not global, or cannot be
    read (the CrossComm error is swallowed by the proxy). It is never a legitimate empty value:
    an empty CHAR array still reads as ``""`` (two quote characters).
    """


class ReadFailedError(VariableError):
    """The proxy answered a read with failure status (e.g. no CrossComm connection)."""


class WriteRefusedError(VariableError):
    """The proxy answered a write with failure status: read-only, unknown or wrong type.

    ``value`` holds the text that was sent.
    """

    def __init__(
        self, message: str, *, name: str = "", endpoint: str = "", value: str = ""
    ) -> None:
        super().__init__(message, name=name, endpoint=endpoint)
        self.value = value


class KrlValueError(KvpError, ValueError):
    """Text that cannot be parsed as a KRL value, or a value that does not fit its type."""
