"""Whether a bind address keeps a server on this machine.

The servers of the apps (``kvp web``, ``kvp gateway``) ask for a token or security when bound
beyond loopback; both decide what "loopback" is here. Standard library only, cheap to import.
"""

from __future__ import annotations

import ipaddress

__all__ = ["is_loopback"]


def is_loopback(host: str) -> bool:
    """Whether binding ``host`` keeps the server on this machine (``localhost`` or a loopback
    address; a host name other than ``localhost`` is not trusted to resolve to one)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
