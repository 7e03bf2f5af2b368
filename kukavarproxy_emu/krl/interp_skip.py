"""Skipping KRL cycles that would repeat the previous one exactly (a mixin of the interpreter).

Some cycles end where they began: the submit interpreter's pass from the end of its ``LOOP``
body back to it, or the robot program from a motion that completed at once (the robot stands
on the target) back to the same motion. If such a cycle wrote nothing (every assignment found
its target equal), what it does depends only on the variables it read, and for the robot
program on the kernel standing still at the same planned point. The store counts the changes
of each variable (:meth:`VariableStore.version`); the evaluator records the variables a cycle
reads. While none of them changed, the next cycle is skipped: it would read the same values
and again write nothing. A default robot at rest (``follow`` + ``sps.sub``) then costs
nothing here until MYAXIS or OUTPUT_VARS change, which a cell of robots needs. A cycle that
writes something every time (a counter, a running ``$TIMER``) always runs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .interp_motion import AT_ONCE, PASS

if TYPE_CHECKING:
    from ..motion.kernel import MotionKernel
    from ..store import VariableStore
    from .runtime import Evaluator, Frame

__all__ = ["AT_ONCE", "PASS", "SkipMixin"]


class SkipMixin:
    """``_cycle()`` runs one interpreter cycle (``_run``) or skips it; see the module."""

    store: VariableStore
    kernel: MotionKernel | None
    frames: list[Frame]
    ev: Evaluator

    def _run(self) -> str | None:
        raise NotImplementedError  # provided by the interpreter

    def _init_skip(self) -> None:
        #: The variables (and their versions) the last cycle read, when it ran from a repeating
        #: point to the same point and changed nothing; None otherwise.
        self._quiet: list[tuple[VariableStore, str, int]] | None = None
        self._quiet_idle: bytes | None = None
        self._at_pass: int | None = None  # the repeating point the last cycle ended at
        #: The repeating point reached last (set before yielding PASS / AT_ONCE).
        self._pass_loop: int | None = None
        #: Cycles skipped because they would have done exactly what the previous one did.
        self.skipped = 0
        #: The last cycle ran from the repeating point back to it (one whole SPS pass, or a
        #: motion completed at once), or was skipped as a repeat of such a cycle.
        self.whole_pass = False

    def _reset_skip(self) -> None:
        self._quiet = self._at_pass = None

    def _idle_at(self) -> bytes | None:
        """The robot interpreter's kernel state a repeated cycle depends on: the planned end
        point while nothing moves or waits (None while something does)."""
        kernel = self.kernel
        if kernel is None:
            return b""
        if kernel.moving or kernel.queued:
            return None
        return bytes(kernel.planned_q.tobytes())

    def _cycle(self) -> None:
        """One cycle, skipped when it would repeat the previous one exactly.

        A cycle that ran from a repeating point to the same point — the end of the submit
        interpreter's LOOP body, or a robot program's motion that completed at once (``LOOP PTP
        MYAXIS C_PTP ENDLOOP`` with the robot on MYAXIS) — and wrote nothing (every assignment
        found its target equal) depends only on what it read and, for the robot interpreter,
        on the kernel standing still at the same planned point. While none of those variables
        changed, the next cycle would read the same values and again write nothing. A default
        robot at rest (follow + sps.sub) then costs nothing here until something changes,
        which a cell of robots needs.
        """
        quiet = self._quiet
        if quiet is not None:
            if self._idle_at() == self._quiet_idle and all(
                store.version(base) == version for store, base, version in quiet
            ):
                self.skipped += 1
                self.whole_pass = True
                return
            self._quiet = None
        start = self._at_pass
        idle = self._idle_at()
        stores = [self.store, *(f.store for f in self.frames)]
        before = [st.mutations for st in stores]
        reads: set[tuple[VariableStore, str]] = set()
        self.ev.reads = reads
        try:
            reason = self._run()
        finally:
            self.ev.reads = None
        self._at_pass = self._pass_loop if reason in (PASS, AT_ONCE) else None
        self.whole_pass = start is not None and start == self._at_pass
        if (
            start is not None
            and start == self._at_pass
            and idle is not None
            and idle == self._idle_at()
            and len(self.frames) + 1 == len(stores)
            and [st.mutations for st in stores] == before
        ):
            self._quiet = [(st, base, st.version(base)) for st, base in reads]
            self._quiet_idle = idle
