"""The thesis' KRL programs as Python objects stepping on the motion kernel.

Until the KRL interpreter lands, each program is a small state machine whose :meth:`step` runs
once per IPO cycle, before the kernel advances. A program only plans motions and reads/writes
variables; the kernel does not know which program drives it.

**Advance run.** A motion statement reads its target variable when it is *planned*, and the
advance run may plan up to ``$ADVANCE`` statements ahead of the one executing (reference §5):
each step plans while :meth:`MotionKernel.can_plan` allows, capturing the variable's value at
that moment. ``LOOP PTP MYAXIS C_PTP ENDLOOP`` therefore queues zero-length segments while
MYAXIS is unchanged and follows a new value up to ``$ADVANCE`` segments late, exactly the lag
the real controller shows. At most ``$ADVANCE + 1`` statements run per cycle, so a loop of
zero-length motions cannot spin.

A :class:`~.kernel.MotionRefused` raised here stops the program (the robot task reports it).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pyopenshowvar.krl import KrlValue

from ..store import VariableStore
from .kernel import MotionKernel, MotionRefused, axes_of

__all__ = ["PROGRAMS", "Program", "Sps", "make_program"]


def _advance(store: VariableStore) -> int:
    value = store.get("$ADVANCE")
    return int(value) if isinstance(value, int) else 3


def _get(store: VariableStore, name: str) -> KrlValue:
    try:
        return store.get(name)
    except LookupError:
        raise MotionRefused(f"{name} is not initialised") from None


class Program:
    """Base class: ``start`` once when selected, ``step`` every cycle while running."""

    #: What ``$PRO_NAME1[]`` shows.
    krl_name = ""

    def start(self, kernel: MotionKernel) -> None:
        """Called when the program is started or restarted after a stop."""

    def step(self, kernel: MotionKernel) -> None:
        """One interpolation cycle of the program (the advance run's work)."""

    def _plan_loop(self, kernel: MotionKernel, plan: Callable[[], None]) -> None:
        """Run a one-motion ``LOOP ... ENDLOOP`` body as often as the advance run allows."""
        adv = _advance(kernel.store)
        for _ in range(max(adv, 0) + 1):  # the executing statement + $ADVANCE ahead
            if not kernel.can_plan(adv):
                break
            plan()
            if not kernel.moving:  # the robot stood on the target: the same next time round
                break


class Idle(Program):
    """``--program none``: no robot program selected (``$PRO_STATE1`` = ``#P_FREE``)."""


class Follow(Program):
    """``LOOP PTP MYAXIS C_PTP ENDLOOP``: the absolute axis follower (the default)."""

    krl_name = "FOLLOW"

    def step(self, kernel: MotionKernel) -> None:
        store = kernel.store
        self._plan_loop(
            kernel, lambda: kernel.ptp(_get(store, "MYAXIS"), approx=True, label="PTP MYAXIS")
        )


class Actuator(Program):
    """Algorithm 4.12: ``$ADVANCE=1``, ``LOOP PTP_REL MYPOS C_PTP ENDLOOP``.

    MYPOS is a Cartesian increment added to the *planned* end point of the previous motion
    (reference §5), so the robot keeps moving while MYPOS is non-zero.
    """

    krl_name = "ACTUATOR"

    def start(self, kernel: MotionKernel) -> None:
        kernel.store.set_system("$ADVANCE", 1)

    def step(self, kernel: MotionKernel) -> None:
        store = kernel.store
        self._plan_loop(
            kernel,
            lambda: kernel.ptp_rel_pose(_get(store, "MYPOS"), approx=True, label="PTP_REL MYPOS"),
        )


class ExtMoveAxis(Program):
    """Algorithm 4.13: ``$ADVANCE=1``; ``LOCAL`` = ``$AXIS_ACT``, then in a loop each
    ``LOCAL.Ai`` takes ``MYAXIS.Ai`` axis by axis and ``PTP LOCAL C_PTP`` runs.

    The printed listing adds MYAXIS to LOCAL while its text says the desired angles are
    *assigned*; with the default MYAXIS (HOME) an addition would run into the limits at once,
    so the emulator assigns, as the text and the issue say.
    """

    krl_name = "EXT_MOVE_AXIS"

    def __init__(self) -> None:
        self.local = np.zeros(6)

    def start(self, kernel: MotionKernel) -> None:
        kernel.store.set_system("$ADVANCE", 1)
        self.local = kernel.q.copy()

    def _body(self, kernel: MotionKernel) -> None:
        target = axes_of(_get(kernel.store, "MYAXIS"), "MYAXIS")
        for i in range(6):  # LOCAL.A1 = MYAXIS.A1 ... LOCAL.A6 = MYAXIS.A6
            self.local[i] = target[i]
        kernel.ptp(self.local.copy(), approx=True, label="PTP LOCAL")

    def step(self, kernel: MotionKernel) -> None:
        self._plan_loop(kernel, lambda: self._body(kernel))


class PathRunner(Program):
    """Algorithm 4.8 / 4.10 with the path handshake of docs/paths.md.

    ``WAIT FOR PATH_START``; ``PATH_DONE = FALSE``; ``PATH_BUSY = TRUE``; for ROW = 1 to
    PATH_COUNT: ``PATH_INDEX = ROW`` and the motion to row ROW, approximated except the last
    one (stops exactly); then ``PATH_BUSY = FALSE``, ``PATH_START = FALSE``, ``PATH_DONE = TRUE``.
    The flags are set when the robot has *reached* the last point (as if the KRL program had
    an advance-run stop such as ``WAIT SEC 0`` before them), so a PC waiting for PATH_DONE
    sees the robot on the last point.
    """

    array = "MYE6ARRAY"

    def __init__(self) -> None:
        self.row = 0
        self.count = 0
        self.state = "wait"

    def start(self, kernel: MotionKernel) -> None:
        if self.state != "wait":  # restarted after a stop: abandon the path
            kernel.store.set_system("PATH_BUSY", False)
        self.state = "wait"

    def move(self, kernel: MotionKernel, target: KrlValue, approx: bool, label: str) -> None:
        kernel.ptp(target, approx=approx, label=label)

    def step(self, kernel: MotionKernel) -> None:
        store = kernel.store
        if self.state == "wait":
            if store.get("PATH_START") is not True:
                return
            store.set_system("PATH_DONE", False)
            store.set_system("PATH_BUSY", True)
            count = store.get("PATH_COUNT")
            self.count = count if isinstance(count, int) else 0
            self.row, self.state = 1, "run"
        if self.state == "run":
            adv = _advance(store)
            for _ in range(max(adv, 0) + 1):
                if self.row > self.count:
                    self.state = "finish"
                    break
                if not kernel.can_plan(adv):
                    break
                store.set_system("PATH_INDEX", self.row)
                name = f"{self.array}[{self.row}]"
                self.move(kernel, _get(store, name), self.row < self.count, name)
                self.row += 1
        if self.state == "finish" and not kernel.moving:
            store.set_system("PATH_BUSY", False)
            store.set_system("PATH_START", False)
            store.set_system("PATH_DONE", True)
            self.state = "wait"


class JointPath(PathRunner):
    """Algorithm 4.8: ``PTP MYE6ARRAY[ROW] C_PTP``."""

    krl_name = "JOINT_PATH"


class CartPath(PathRunner):
    """Algorithm 4.10: ``LIN MYPOSARRAY[ROW] C_DIS`` (TCP in $BASE with $TOOL)."""

    krl_name = "CART_PATH"
    array = "MYPOSARRAY"

    def move(self, kernel: MotionKernel, target: KrlValue, approx: bool, label: str) -> None:
        kernel.lin(target, approx=approx, label=f"LIN {label}")


#: ``--program NAME`` → program class.
PROGRAMS: dict[str, type[Program]] = {
    "follow": Follow,
    "actuator": Actuator,
    "ext_move_axis": ExtMoveAxis,
    "joint_path": JointPath,
    "cart_path": CartPath,
    "none": Idle,
}


def make_program(name: str) -> Program:
    try:
        return PROGRAMS[name]()
    except KeyError:
        raise ValueError(f"unknown program {name!r} (known: {', '.join(PROGRAMS)})") from None


class Sps:
    """The submit interpreter's loop of Algorithm 4.11: ``$OUT[i] = OUTPUT_VARS[i]`` every
    cycle, for every element of OUTPUT_VARS. Only changed outputs are written."""

    def __init__(self, store: VariableStore) -> None:
        self.store = store
        self._last: list[KrlValue | None] = []

    def step(self) -> None:
        values: KrlValue | list[KrlValue | None]
        try:
            values = self.store.get("OUTPUT_VARS")
        except LookupError:  # not declared, or an element never set: copy element-wise
            values = self._elementwise()
        if not isinstance(values, list):
            return
        if len(self._last) != len(values):
            self._last = [None] * len(values)
        for i, value in enumerate(values, start=1):
            if isinstance(value, bool) and value != self._last[i - 1]:
                try:
                    self.store.set_system(f"$OUT[{i}]", value)
                except LookupError:
                    break
                self._last[i - 1] = value

    def _elementwise(self) -> list[KrlValue | None]:
        """OUTPUT_VARS with some element never set (a user $CONFIG.DAT): the set ones only."""
        if "OUTPUT_VARS" not in self.store.names():
            return []
        out: list[KrlValue | None] = []
        for i in range(1, 65):  # the bundled declaration has 16; $OUT has 4096
            try:
                out.append(self.store.get(f"OUTPUT_VARS[{i}]"))
            except LookupError:
                out.append(None)
        return out
