"""How much of the shared event loop one robot may take.

Every robot's replies are parsed on the gateway's one event loop, so a robot (or anything that
listens on its port) answering with huge values could starve the others: a 60 KB nested
STRUC takes a tenth of a second and more to parse. Three bounds keep one robot's work from
delaying the rest of the cell:

* **a size cap per value** (``max_value_chars`` in the cell file, default
  :data:`MAX_VALUE_CHARS`): a longer reply is never parsed; the robot is treated as
  misbehaving (:class:`ValueTooLongError`: its nodes turn Bad and it is reconnected with the
  usual backoff), since a KRC's own variables are a few hundred characters;
* **slices**: parsing hands the event loop back (``await asyncio.sleep(0)``) whenever it has
  run :data:`SLICE` seconds of CPU in one go, so other robots' polls and OPC UA requests get
  their turn between two values, never after a whole poll;
* **a budget**: the CPU time a poll spent parsing (``time.thread_time``, so a loaded machine
  does not count against a robot) may be at most :data:`SHARE` of the time until the robot's
  next poll; a robot over budget polls later (:meth:`WorkBudget.earliest_next`), and that is
  logged once per connection.

A robot that behaves spends well under a millisecond per poll and never meets these bounds.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from pyopenshowvar import KvpError

__all__ = ["MAX_VALUE_CHARS", "SHARE", "SLICE", "ValueTooLongError", "WorkBudget"]

log = logging.getLogger(__name__)

#: The longest value text parsed by default (a KRC4's $AXIS_ACT is about 170 characters).
MAX_VALUE_CHARS = 4096
#: The share of the event loop's time one robot's parsing may take.
SHARE = 0.05
#: CPU seconds of parsing after which the event loop is handed back.
SLICE = 0.002


class ValueTooLongError(KvpError):
    """A robot answered with a value longer than its ``max_value_chars``; not parsed."""


class WorkBudget:
    """One robot's parsing time: :meth:`charge` each parse, ask :meth:`should_yield` between
    values and :meth:`earliest_next` after the poll (see the module doc)."""

    def __init__(
        self,
        name: str,
        *,
        share: float = SHARE,
        slice_: float = SLICE,
        clock: Callable[[], float] = time.thread_time,
    ) -> None:
        self.name = name
        self.share = share
        self.slice = slice_
        self.clock = clock
        #: CPU seconds spent parsing in the current poll
        self.used = 0.0
        self._since_yield = 0.0
        self._warned = False

    def begin(self) -> None:
        """A new poll (or a new connection's identity read) starts."""
        self.used = 0.0
        self._since_yield = 0.0

    def charge(self, seconds: float) -> None:
        self.used += seconds
        self._since_yield += seconds

    def should_yield(self) -> bool:
        """True (and the slice starts anew) when the event loop is due back."""
        if self._since_yield < self.slice:
            return False
        self._since_yield = 0.0
        return True

    def earliest_next(self, started: float, period: float) -> float:
        """The earliest time (the caller's clock) of the next poll of a poll that ``started``."""
        spread = self.used / self.share
        if spread <= period:
            return started
        if not self._warned:
            self._warned = True
            log.warning(
                "robot %s: a poll took %.0f ms of CPU to parse, over its budget (%.0f %% of the"
                " event loop): it is polled every %.2f s instead of every %.2f s",
                self.name, self.used * 1e3, self.share * 100, spread, period,
            )  # fmt: skip
        return started + spread

    def reset_warning(self) -> None:
        """A new connection: warn again if it is over budget too."""
        self._warned = False
