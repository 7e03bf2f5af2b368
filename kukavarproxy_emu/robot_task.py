"""The simulated robot task: IPO clock + program + SPS + motion kernel, owned by the Emulator.

Each tick, in this order and without awaiting in between (so a KVP read, served on the same
event loop, always sees one whole cycle): acknowledge ``EMU_RESTART``; the robot program's
advance run (the KRL interpreter) plans motions; the submit interpreter runs one pass of
the SPS (by default Algorithm 4.11, OUTPUT_VARS to $OUT); the kernel interpolates one
cycle and publishes $AXIS_ACT, $POS_ACT, $TORQUE_AXIS_ACT, ...

**Errors.** A refused motion (software limit switch, unreachable pose, uninitialised target)
or an axis that cannot follow (the plant's following-error monitoring: the brakes close,
``$DRIVES_ON`` = FALSE) stops the program like a KRC: the refused motion never starts, the one already running ends
exactly on its (valid) end point, ``$PRO_STATE1`` = ``#P_STOP``, ``$STOPMESS`` = TRUE and the
message text is in the read-only ``$EMU_MESSAGE[]``. Writing ``EMU_RESTART = TRUE`` (or
:meth:`Robot.restart`) acknowledges the message and starts the program again.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from pyopenshowvar.kinematics import KR6R900SIXX, RobotModel
from pyopenshowvar.krl import KrlEnum, Struct

from .krl.executor import KrlProgram, KrlSubmit
from .motion.clock import IpoClock, JitterStats
from .motion.kernel import MotionKernel, MotionRefused
from .motion.programs import Idle, Program
from .plant import Obstacle, make_plant
from .program_factory import make_program, make_submit
from .store import VariableStore

if TYPE_CHECKING:
    from .motion.dynamics import MachineData
    from .plant.params import PlantParams

__all__ = ["MESSAGE_LENGTH", "Robot"]

log = logging.getLogger(__name__)

#: Characters of ``$EMU_MESSAGE[]`` (longer messages are cut).
MESSAGE_LENGTH = 128
_WRENCH = ("FX", "FY", "FZ", "MX", "MY", "MZ")
#: Ticks per wake-up of a robot at rest (see "Coasting" in :mod:`.motion.clock`): 8 × 12 ms.
COAST = 8


class Robot:
    """One simulated KUKA arm (``model``; the KR 6 R900 sixx by default): ``emu.robot`` while
    an emulator runs with ``robot=True``. ``machine``: the controller's machine data for a
    model without its own file; ``plant_params``: the physical robot's parameters (default:
    the KR 6's model file), called only when the plant is dynamic."""

    def __init__(
        self,
        store: VariableStore,
        *,
        program: str | Path | Program = "follow",
        sps: str | Path | None = "sps",
        ipo: float = 0.012,
        speed: float = 1.0,
        phase: float = 0.0,
        model: RobotModel = KR6R900SIXX,
        noise: float | None = None,
        seed: int | None = None,
        plant: str = "ideal",
        calibration_error: int | None = None,
        torque_noise: float | None = None,
        obstacles: Sequence[Obstacle] = (),
        coast: int = COAST,
        machine: MachineData | None = None,
        plant_params: Callable[[], PlantParams] | None = None,
    ) -> None:
        self.store = store
        ideal_noise = (noise or 0.0) if plant == "ideal" else 0.0
        self.kernel = MotionKernel(
            store, model, ipo=ipo, noise=ideal_noise, seed=seed, machine=machine
        )
        self.kernel.on_fault = self.fault
        #: The physical robot (``plant="dynamic"``), None for the ideal plant: see
        #: :mod:`kukavarproxy_emu.plant`; ``robot.plant.truth`` is the ground truth.
        self.plant = make_plant(
            plant,
            store,
            model,
            ipo=ipo,
            calibration_seed=calibration_error,
            encoder_noise=noise,
            torque_noise=torque_noise,
            seed=seed,
            obstacles=obstacles,
            params=plant_params() if plant_params is not None else None,
        )
        self.kernel.plant = self.plant
        if self.plant is not None:
            self.plant.on_fault = self._drive_fault
        else:
            self.kernel.publish_torque()  # the model's start-up torques (both plants)
        if isinstance(program, Program):
            self.program = program
        else:
            self.program = make_program(program, store)
        #: The submit interpreter running the SPS (Algorithm 4.11 by default); None: no SPS.
        self.sps: KrlSubmit | None = make_submit(sps, store, ipo=ipo)
        self.clock = IpoClock(
            self.tick, ipo=ipo, speed=speed, phase=phase, coast=coast, quiet=self._is_quiet
        )
        self._ticking = False
        self._quiet = False
        store.on_write = self._outside_write
        #: True while the robot program runs (False after a stop or with no program).
        self.running = False
        #: The last error message ("" when none).
        self.message = ""

    # --- life cycle --------------------------------------------------------------------------
    def start(self) -> None:
        """Select and start the program and start the IPO clock (on the running loop)."""
        self._begin()
        self.clock.start()

    async def stop(self) -> None:
        await self.clock.stop()

    def begin(self) -> None:
        """Select and start the program without starting the clock: for a robot driven by
        hand, one :meth:`tick` at a time (a twin of a running robot, an offline run)."""
        self._begin()

    def _begin(self) -> None:
        self._set("$PRO_NAME1[]", self.program.krl_name)
        self._set("$DRIVES_ON", True)
        idle = isinstance(self.program, Idle)
        self.running = not idle
        if not idle:
            try:
                self.program.start(self.kernel)
            except MotionRefused as exc:
                self.fault(str(exc))
                return
        self._set("$PRO_STATE1", KrlEnum("P_FREE" if idle else "P_ACTIVE"))

    def tick(self) -> None:
        """One interpolation cycle (the clock calls it; tests may call it directly)."""
        store = self.store
        changes = store.mutations - store.stale_marks
        skips = self._skips()
        self._ticking = True
        try:
            self._check_restart()
            if self.running:
                try:
                    self.program.step(self.kernel)
                except MotionRefused as exc:
                    self.fault(str(exc))
            sps_changes = 0
            if self.sps is not None:
                before = store.mutations - store.stale_marks
                # not lazily with a latency profile (a clock gate): making a waiting pass
                # when a reply reads it would make that reply late (see _light_sps)
                self.sps.step(lazy=self.clock.gate is None)
                if self._light_sps():  # its writes do not keep the clock awake (see below)
                    sps_changes = store.mutations - store.stale_marks - before
            self.kernel.tick()
            # the texts clients poll every cycle, formatted here rather than in their replies
            store.warm()
        finally:
            self._ticking = False
        # Quiet: nothing wall time could show changed, so the clock may coast (run the next
        # ticks late, batched, or when someone looks). The kernel and the plant rest, the robot
        # program's pass was skipped as a repeat, and nothing else was written, but for a
        # light SPS pass: one short pass (an SPS snapshot copying the readings, its counter
        # counting) changes variables every cycle and is still cheap to run late, and whoever
        # reads them brings the clock up to date first.
        plant = self.plant
        now = self._skips()
        self._quiet = (
            store.mutations - store.stale_marks - sps_changes == changes
            and self.kernel.at_rest
            and (plant is None or plant.resting or plant.braked)
            and skips is not None
            and now is not None
            and now[0] == skips[0] + skips[2]
            and (now[1] == skips[1] + skips[3] or self._light_sps())
        )

    def _light_sps(self) -> bool:
        """The SPS made a light pass and may let the clock coast (see :meth:`tick`); not with
        a latency profile (a clock gate): a coast's catch-up would make a reply late."""
        return self.sps is not None and self.sps.light and self.clock.gate is None

    def _skips(self) -> tuple[int, int, int, int] | None:
        """The KRL passes skipped as exact repeats so far (program, SPS) and how many a quiet
        tick adds to each (0 for an interpreter that does not run); None: a program whose
        passes cannot be told apart (a Python program other than Idle)."""
        program = self.program
        if not self.running or isinstance(program, Idle):
            p, dp = 0, 0
        elif isinstance(program, KrlProgram):
            interp = program.interp
            if interp is None or interp.finished or interp.halted:
                p, dp = 0, 0
            else:
                p, dp = interp.skipped, 1
        else:
            return None
        sps = self.sps
        if sps is None or not sps.running:
            return p, 0, dp, 0
        return p, sps.interp.skipped, dp, 1

    def _is_quiet(self) -> bool:
        return self._quiet

    def _outside_write(self) -> None:
        """A store write from outside the tick (a request, an app, a test): a coasting clock
        runs its due ticks first and ends the coast."""
        if not self._ticking and self.clock._coasting:
            self.sync()

    def sync(self) -> None:
        """Bring a coasting clock up to date (see :meth:`.clock.IpoClock.poll`) when called on
        the robot's event loop; from another thread it does nothing (ticks never run there)."""
        wheel = self.clock._wheel
        if wheel is None:
            return
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            return
        if running is wheel.loop:
            self.clock.poll()

    # --- errors ------------------------------------------------------------------------------
    def fault(self, message: str) -> None:
        """Stop the program with ``message`` (refused motion): see the module docstring."""
        log.warning("robot program stopped: %s", message)
        self.kernel.stop()
        self.running = False
        self.message = message
        text = message.encode("latin-1", "replace").decode("latin-1")[:MESSAGE_LENGTH]
        self._set("$EMU_MESSAGE[]", text.replace('"', "'"))
        self._set("$STOPMESS", True)
        self._set("$PRO_STATE1", KrlEnum("P_STOP"))

    def _drive_fault(self, message: str) -> None:
        """An axis could not follow: the plant's brakes have closed. The set-point jumps to
        where the arm stands (drives off, as on a KRC after a following error) and the program
        stops with the message."""
        assert self.plant is not None
        self.kernel.reset_to(self.plant.position)
        self.fault(message)
        self._set("$DRIVES_ON", False)

    def restart(self) -> None:
        """Acknowledge the message and start the program again (from the current position)."""
        if self.plant is not None and self.plant.braked:
            self.kernel.reset_to(self.plant.release())  # drives on where the arm stands
        self.message = ""
        self._set("$EMU_MESSAGE[]", "")
        self._set("$STOPMESS", False)
        if self.sps is not None and not self.sps.running:
            self.sps.start()
        self._begin()

    def _check_restart(self) -> None:
        try:
            flag = self.store.get("EMU_RESTART")
        except LookupError:
            return
        if flag is True:
            self.store.set_system("EMU_RESTART", False)
            self.restart()

    # --- in-process API ----------------------------------------------------------------------
    def apply_wrench(self, wrench: Sequence[float]) -> None:
        """Set the external wrench [FX, FY, FZ (N), MX, MY, MZ (Nm)] the TCP exerts on the
        environment ($ROBROOT axes, about the TCP); it is also the variable EMU_WRENCH."""
        values = [float(v) for v in wrench]
        if len(values) != 6 or not all(np.isfinite(values)):
            raise ValueError("a wrench is 6 finite numbers: FX FY FZ MX MY MZ")
        # set_system brings a coasting clock up to date (store.on_write) before the change
        self.store.set_system("EMU_WRENCH", Struct(None, dict(zip(_WRENCH, values, strict=True))))

    @property
    def time(self) -> float:
        """Simulated seconds since the robot started (up to date: a coasting clock catches up)."""
        self.sync()
        return self.kernel.time

    @property
    def q(self) -> npt.NDArray[np.float64]:
        """Current set-point axes A1..A6 (deg) (up to date: a coasting clock catches up)."""
        self.sync()
        return self.kernel.q.copy()

    def jitter(self) -> JitterStats:
        """IPO tick lateness statistics (see :class:`~.motion.clock.IpoClock`)."""
        return self.clock.stats()

    def _set(self, name: str, value: object) -> None:
        try:
            self.store.set_system(name, value)
        except LookupError:  # a store built without that variable: nothing to report into
            log.debug("robot: no variable %s in the store", name)
