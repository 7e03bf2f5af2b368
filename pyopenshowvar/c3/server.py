"""What the server at the other end is: KUKAVARPROXY or C3 Bridge, which version, which messages.

:func:`identify` turns the answers to three ASCII reads (which every proxy can take: KVP answers
an unknown name with an empty value) into a :class:`ServerInfo`:

* ``@PROXY_TYPE`` reads ``C3 BRIDGE INTERFACE`` on C3 Bridge (spec §2.2) and nothing on KVP;
* ``@PROXY_VERSION`` reads ``<major>.<minor> (<EDITION>)`` (§2.3);
* ``@PROXY_FEATURES`` reads one ``0``/``1`` per message type, the last character type 0 (§2.4).

:meth:`ServerInfo.require` is the guard every C3 method runs before it sends anything: a KVP
server, a C3 Bridge without the message, or one older than the version the spec requires for
it (#6 needs 1.2, #7 needs 1.3: "earlier implementations did not work correctly") raises
:class:`~pyopenshowvar.c3.errors.UnsupportedError` with what to do about it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Literal

from .constants import C3_TYPE_NAME, Command
from .errors import UnsupportedError
from .replies import FeatureMap

__all__ = ["MIN_VERSION", "PROBES", "ServerInfo", "identify"]

#: The three reads :func:`identify` needs, in this order.
PROBES = ("@PROXY_TYPE", "@PROXY_VERSION", "@PROXY_FEATURES")
#: Message types the spec says not to use below a server version.
MIN_VERSION: dict[int, tuple[int, int]] = {
    Command.READ_MULTIPLE: (1, 2),
    Command.WRITE_MULTIPLE: (1, 3),
    Command.PROXY_BENCHMARK: (1, 2),
}
_VERSION = re.compile(r"^\s*(\d+)\.(\d+)(?:\.\d+)*\s*(?:\((.*)\))?\s*$")

Kind = Literal["kvp", "c3bridge"]


@dataclass(frozen=True)
class ServerInfo:
    """The identity of one server, as found by :func:`identify`."""

    kind: Kind
    #: (major, minor) of a C3 Bridge; None for KVP or an unreadable version.
    version: tuple[int, int] | None = None
    #: ``OPEN SOURCE``, ``FREEWARE``, ... ("" when unknown).
    edition: str = ""
    #: Message types the server handles (KVP: its modes 0..3).
    features: frozenset[int] = field(default_factory=lambda: frozenset({0, 1, 2, 3}))

    @property
    def is_c3(self) -> bool:
        return self.kind == "c3bridge"

    def describe(self) -> str:
        if not self.is_c3:
            return "KUKAVARPROXY"
        version = ".".join(map(str, self.version)) if self.version else "?"
        return f"C3 Bridge {version}" + (f" ({self.edition})" if self.edition else "")

    def supports(self, command: int) -> bool:
        if command not in self.features:
            return False
        need = MIN_VERSION.get(command)
        return need is None or (self.version is not None and self.version >= need)

    def require(self, command: int, what: str, endpoint: str) -> None:
        """Raise :class:`UnsupportedError` unless the server handles ``command`` properly."""
        if self.supports(command):
            return
        label = f"{what} (C3 Bridge message #{int(command)} {_name(command)})"
        if not self.is_c3:
            raise UnsupportedError(
                f"{endpoint} is KUKAVARPROXY, which has no {label}; install C3 Bridge on the "
                "controller (docs/c3bridge.md) — nothing was sent"
            )
        if command not in self.features:
            raise UnsupportedError(
                f"{endpoint} runs {self.describe()}, which does not offer {label} — nothing "
                "was sent"
            )
        need = ".".join(map(str, MIN_VERSION[command]))
        raise UnsupportedError(
            f"{endpoint} runs {self.describe()}; {label} works correctly only from C3 Bridge "
            f"{need} on (spec §3.5) — update the server; nothing was sent"
        )


def _name(command: int) -> str:
    try:
        return "".join(p.capitalize() for p in Command(command).name.split("_"))
    except ValueError:
        return f"type {command}"


def parse_version(text: str) -> tuple[tuple[int, int] | None, str]:
    """``"1.4 (OPEN SOURCE)"`` → ((1, 4), "OPEN SOURCE"); unparsable → (None, "")."""
    m = _VERSION.match(text)
    if not m:
        return None, ""
    return (int(m.group(1)), int(m.group(2))), (m.group(3) or "").strip()


def identify(proxy_type: str | None, version: str | None, features: str | None) -> ServerInfo:
    """A :class:`ServerInfo` from the three probe values (None where the read failed)."""
    if (proxy_type or "").strip().upper() != C3_TYPE_NAME:
        return ServerInfo("kvp")
    ver, edition = parse_version(version or "")
    try:
        types = FeatureMap.from_string(features or "").types
    except ValueError:
        # Every C3 Bridge since 1.0 offers these (CHANGELOG 1.0.0); ask #14 for the rest.
        types = frozenset({0, 1, 4, 5, 6, 7, 10, 11, 12, 13, 14, 63})
    return ServerInfo("c3bridge", ver, edition, types)
