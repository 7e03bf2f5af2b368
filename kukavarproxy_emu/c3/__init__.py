"""The emulator's C3 Bridge personality (``kukavarproxy-emu --proxy c3bridge``).

* :mod:`~kukavarproxy_emu.c3.server` — :class:`C3Server` (shared state) and one
  :class:`C3Session` responder per connection, answering every message of C3 Bridge 1.4;
* :mod:`~kukavarproxy_emu.c3.control` — program control, motions, keys on the simulated robot;
* :mod:`~kukavarproxy_emu.c3.filemsgs`, :mod:`~kukavarproxy_emu.c3.vfs` — the file messages on a
  confined, bounded, in-memory ``KRC:\\`` file system;
* :mod:`~kukavarproxy_emu.c3.discovery` — UDP discovery with ``@PROXY_*`` queries.

The codec is :mod:`pyopenshowvar.c3`, the same the client uses. See docs/c3bridge.md.
"""

from __future__ import annotations

from .server import HANDLED, VERSION, C3Server, C3Session
from .vfs import Limits, VirtualFS

__all__ = ["HANDLED", "VERSION", "C3Server", "C3Session", "Limits", "VirtualFS"]
