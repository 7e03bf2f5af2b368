"""Log lines about what the network sends: escaped, clipped and rate-limited.

A client chooses the names and values it sends, so a name with a newline in it, logged as is,
writes a line of the client's choosing into the emulator's log, and a client that repeats a
failing request ten thousand times a second writes ten thousand log lines a second. Everything
a peer supplied goes through :func:`clip` before it reaches a log call, at every level, and
lines a peer can provoke at will go through a :class:`RateLimitedLog`.
"""

from __future__ import annotations

import logging
import time
from typing import Any

__all__ = ["CLIP", "RateLimitedLog", "clip"]

#: Characters of peer-supplied text kept in a log line.
CLIP = 80


def clip(text: str | bytes, limit: int = CLIP) -> str:
    """``text`` as one printable ASCII line: control and non-ASCII characters and backslashes
    escaped the way Python escapes them (``\\n``, ``\\x07``, ``\\xe9``, ``\\\\``), cut after
    ``limit`` characters with a note of how many more there were."""
    if isinstance(text, bytes):
        text = text.decode("latin-1")
    head = text[:limit].encode("unicode_escape").decode("ascii")
    if len(text) > limit:
        return f"{head}...(+{len(text) - limit} chars)"
    return head


class RateLimitedLog:
    """At most ``burst`` lines per message template every ``period`` seconds.

    Lines beyond that are counted, not written; the first line let through afterwards says how
    many were left out. Keys are the format strings (constants of the code, never peer text),
    so the table stays small.
    """

    def __init__(self, logger: logging.Logger, *, period: float = 10.0, burst: int = 5) -> None:
        self.logger = logger
        self.period = period
        self.burst = burst
        # template -> [window start, lines written in the window, lines suppressed]
        self._state: dict[str, list[float]] = {}

    def debug(self, msg: str, *args: object, **kwargs: Any) -> None:
        self.log(logging.DEBUG, msg, *args, **kwargs)

    def info(self, msg: str, *args: object, **kwargs: Any) -> None:
        self.log(logging.INFO, msg, *args, **kwargs)

    def warning(self, msg: str, *args: object, **kwargs: Any) -> None:
        self.log(logging.WARNING, msg, *args, **kwargs)

    def log(self, level: int, msg: str, *args: object, **kwargs: Any) -> None:
        if not self.logger.isEnabledFor(level):
            return
        now = time.monotonic()
        state = self._state.get(msg)
        if state is None or now - state[0] >= self.period:
            suppressed = int(state[2]) if state is not None else 0
            state = self._state[msg] = [now, 0.0, 0.0]
            if suppressed:
                msg = f"{msg} ({suppressed} similar lines suppressed)"
        if state[1] >= self.burst:
            state[2] += 1
            return
        state[1] += 1
        self.logger.log(level, msg, *args, stacklevel=3, **kwargs)
