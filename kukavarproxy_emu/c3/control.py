"""C3 Bridge program control (#10), motions (#11), smartPAD keys (#12) and Confirm All (#63)
on the emulator's simulated robot.

Selecting a module parses its ``.src`` (and the ``.dat`` beside it) from the virtual file system
and hands it to the robot interpreter exactly as ``--program`` does
(:class:`~kukavarproxy_emu.krl.executor.KrlProgram`): same parser, same data list declared into
the store, same ``$PRO_STATE1``/``$PRO_NAME1[]``/``$STOPMESS``/``$EMU_MESSAGE[]``. Parsing and
declaring run in slices between other clients' requests (:meth:`RobotControl.select`); selects,
starts, motions and keys that come meanwhile wait for it. The states follow the KRC's robot
interpreter:

=========  ==========================================================================
P_FREE     nothing selected; select (5) or run (6) a module
P_RESET    selected, at its first line; start (2) runs it
P_ACTIVE   running; stop (3) brakes on the path (the override ramps to 0) and keeps the
           motion, start resumes it
P_STOP     stopped (by stop, HALT or an error); start resumes — after an error only once
           the message was acknowledged (#63), and then from the first line
P_END      reached END; reset (1) returns to P_RESET
=========  ==========================================================================

Reset and cancel (4) need a program that is not running. Every refusal answers ErrorGeneral
(the COM E_FAIL the real server maps), with the reason in the emulator's ``$EMU_MESSAGE[]``
for select errors (a KRL syntax error names ``file:line:column``).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable
from functools import partial
from typing import TYPE_CHECKING

from pyopenshowvar.c3.constants import ErrorCode, Interpreter, KcpKey, MotionType, ProgramCommand
from pyopenshowvar.errors import KrlValueError
from pyopenshowvar.krl import KrlEnum, Struct, parse_value

from ..krl import ast
from ..krl.executor import KrlProgram
from ..krl.interp_motion import MotionMixin
from ..krl.parser import KrlSyntaxError, parse_dat, parse_src
from ..krl.runtime import KrlRuntimeError
from ..motion.kernel import MotionRefused
from ..motion.programs import Idle
from ..slices import Checkpoint, run_sliced
from .vfs import VfsError, VirtualFS

if TYPE_CHECKING:
    from ..robot_task import Robot
    from ..store import VariableStore

__all__ = ["MAX_MODULE", "RobotControl"]

log = logging.getLogger(__name__)

#: Largest module (``.src`` + ``.dat``) the emulator selects: parsing takes ~3 µs a byte,
#: spread over loop iterations (a 64 KiB module is about 0.2 s of work).
MAX_MODULE = 64 * 1024
#: Seconds one #11 motion may spend planning (a long LIN near a singularity takes longest).
PLAN_BUDGET = 0.25
_NODE = ast.Name("C3", line=0, column=0)
_MOTION_KIND = {
    MotionType.PTP: "PTP",
    MotionType.LIN: "LIN",
    MotionType.PTP_REL: "PTP_REL",
    MotionType.LIN_REL: "LIN_REL",
}


def _load_module(
    src: tuple[str, str],
    dat: tuple[str, str] | None,
    store: VariableStore,
    checkpoint: Checkpoint,
) -> KrlProgram:
    """Parse a module (``(path, text)`` of its ``.src`` and ``.dat``) and declare its data
    list, calling ``checkpoint`` all along: the sliced part of a select."""
    module = parse_src(src[1], src[0], checkpoint=checkpoint)
    if not module.routines:
        raise KrlSyntaxError("no DEF in the file", filename=src[0], line=1, column=1, text="")
    if dat is not None:
        parsed = parse_dat(dat[1], dat[0], checkpoint=checkpoint)
        module = ast.Module(module.filename, module.routines, parsed, line=1, column=1)
    return KrlProgram(module, store, checkpoint=checkpoint)


class _Planner(MotionMixin):
    """The KRL interpreter's motion planning (partial targets, REL, IK) for #11 motions."""


class RobotControl:
    """Program, motion and key commands on one emulator's robot (None: no robot → code 8)."""

    def __init__(self, robot: Robot | None, vfs: VirtualFS) -> None:
        self.robot = robot
        self.vfs = vfs
        #: The KRC path of the selected module's ``.src`` ("" when none was selected by C3).
        self.selected = ""
        #: Set while a select parses and loads its module, done when it has ended.
        self._loading: asyncio.Future[None] | None = None
        self._select_task: asyncio.Task[int] | None = None

    # ------------------------------------------------------------------ state

    def _state(self, name: str = "$PRO_STATE1") -> str:
        assert self.robot is not None
        value = self.robot.store.get(name)
        return value.name if isinstance(value, KrlEnum) else str(value)

    def _set(self, name: str, value: object) -> None:
        assert self.robot is not None
        self.robot.store.set_system(name, value)

    def _message(self, text: str) -> None:
        self._set("$EMU_MESSAGE[]", text.replace('"', "'")[:128])

    # ------------------------------------------------------------------ #10

    def program(self, command: int, interpreter: int) -> int:
        """Run one #10 command other than select and run; returns the error code to answer."""
        if self.robot is None:
            return ErrorCode.NO_INTERFACE
        try:
            if command not in (1, 2, 3, 4):
                return ErrorCode.NOT_IMPLEMENTED
            if interpreter == Interpreter.SUBMIT:
                return self._submit(command)
            if interpreter != Interpreter.ROBOT:
                return ErrorCode.ARGUMENT
            return {1: self._reset, 2: self._start, 3: self._stop, 4: self._cancel}[command]()
        except (MotionRefused, KrlRuntimeError) as exc:  # starting ran into a refused motion
            self.robot.fault(str(exc))
            return ErrorCode.GENERAL

    def select(self, name: str, *, run: bool = False) -> int | Callable[[], Awaitable[int]]:
        """#10 select (5) or run (6): the error code at once when refused, else the rest of
        the select to await — parsing the module and declaring its data list a few ms per
        event-loop iteration (:func:`~kukavarproxy_emu.slices.run_sliced`), then making it the
        robot's program — whose result is the code. Meanwhile other selects, starts, motions
        and keys wait for it (:meth:`after_select`), as they would behind C3 Bridge's one
        thread."""
        robot = self.robot
        if robot is None:
            return ErrorCode.NO_INTERFACE
        if self.selecting:
            return partial(self.after_select, partial(self.select, name, run=run))
        if self._state() == "P_ACTIVE" or not self._standstill():
            self._message("select refused: stop the running program first")
            return ErrorCode.GENERAL
        try:
            key = self.vfs.resolve_module(name)
            src = self.vfs.files[key]
            dat = self.vfs.files.get(key[: key.rfind(".")] + ".DAT")
        except VfsError as exc:
            self._message(f"select {name}: {exc}")
            return exc.code if exc.code != ErrorCode.ARGUMENT else ErrorCode.GENERAL
        size = len(src.data) + (len(dat.data) if dat else 0)
        if size > MAX_MODULE:
            self._message(
                f"select {name}: module of {size} bytes, the emulator selects {MAX_MODULE}"
            )
            return ErrorCode.MEMORY
        load = partial(
            _load_module,
            (src.path, src.data.decode("latin-1")),
            (dat.path, dat.data.decode("latin-1")) if dat is not None else None,
            robot.store,
        )
        loop = asyncio.get_running_loop()
        loaded = self._loading = loop.create_future()

        async def finish() -> int:
            try:
                program = await run_sliced(load)
            except (KrlSyntaxError, ValueError) as exc:
                self._message(str(exc).splitlines()[0])
                return ErrorCode.GENERAL
            finally:
                self._loading = None
                loaded.set_result(None)  # its waiters run after the select is complete
            code = self._selected(program, src.path)
            if code == ErrorCode.SUCCESS and run:
                try:
                    code = self._start()
                except (MotionRefused, KrlRuntimeError) as exc:
                    robot.fault(str(exc))
                    code = ErrorCode.GENERAL
            return code

        # A task of its own: the select completes even if its client goes away at once (as
        # the server's COM call does), and the waiters behind it are always released.
        self._select_task = loop.create_task(finish())
        return partial(asyncio.shield, self._select_task)

    @property
    def selecting(self) -> bool:
        """A select is parsing and loading its module (see :meth:`select`)."""
        return self._loading is not None

    async def after_select(self, action: Callable[[], int | Callable[[], Awaitable[int]]]) -> int:
        """The code of ``action()``, run once no select is loading any more."""
        while self._loading is not None:
            await asyncio.shield(self._loading)  # a waiter that goes away cancels only itself
        result = action()
        return result if isinstance(result, int) else await result()

    def _selected(self, program: KrlProgram, path: str) -> int:
        """Make ``program`` (parsed and loaded) the robot's program."""
        robot = self.robot
        assert robot is not None
        if self._state() == "P_ACTIVE" or not self._standstill():  # starts and motions wait
            self._message("select refused: stop the running program first")  # for selects
            return ErrorCode.GENERAL
        robot.kernel.stop(hard=True)
        robot.kernel.hold = False
        robot.running = False
        robot.program = program
        self.selected = path
        self._set("$PRO_NAME1[]", program.krl_name)
        self._set("$PRO_STATE1", KrlEnum("P_RESET"))
        self._message("")
        log.info("C3: selected %s", path)
        return ErrorCode.SUCCESS

    def _start(self) -> int:
        robot = self.robot
        assert robot is not None
        state = self._state()
        if state == "P_ACTIVE":
            return ErrorCode.SUCCESS
        if state in ("P_FREE", "P_END") or isinstance(robot.program, Idle):
            self._message("start refused: " + ("no program selected" if state == "P_FREE" else
                                               "the program ended; reset it first"))  # fmt: skip
            return ErrorCode.GENERAL
        if state == "P_STOP" and robot.message:  # stopped by an error
            if robot.store.get("$STOPMESS") is True:
                return ErrorCode.GENERAL  # acknowledge first (#63), as on the smartPAD
            robot.message = ""
            state = "P_RESET"
        self._message("")  # a refusal's reason no longer holds (an error sets its own below)
        robot.kernel.hold = False
        if state == "P_RESET":
            robot._begin()  # a fresh interpreter from the first line, as --program starts
        else:
            robot.running = True  # resume: the held motion continues where it braked
            self._set("$PRO_STATE1", KrlEnum("P_ACTIVE"))
        return ErrorCode.SUCCESS if self._state() == "P_ACTIVE" else ErrorCode.GENERAL

    def _stop(self) -> int:
        robot = self.robot
        assert robot is not None
        state = self._state()
        if state == "P_STOP":
            return ErrorCode.SUCCESS
        if state != "P_ACTIVE":
            return ErrorCode.GENERAL
        robot.running = False
        robot.kernel.hold = True
        self._set("$PRO_STATE1", KrlEnum("P_STOP"))
        return ErrorCode.SUCCESS

    def _standstill(self) -> bool:
        assert self.robot is not None
        kernel = self.robot.kernel
        return not kernel.moving or (kernel.hold and kernel.rate == 0.0)

    def _reset(self) -> int:
        robot = self.robot
        assert robot is not None
        if self._state() in ("P_ACTIVE", "P_FREE") or not self._standstill():
            return ErrorCode.GENERAL
        robot.kernel.stop(hard=True)
        robot.kernel.hold = False
        robot.running = False
        robot.message = ""
        self._set("$PRO_STATE1", KrlEnum("P_RESET"))
        return ErrorCode.SUCCESS

    def _cancel(self) -> int:
        robot = self.robot
        assert robot is not None
        if self._state() == "P_ACTIVE" or not self._standstill():
            return ErrorCode.GENERAL
        robot.kernel.stop(hard=True)
        robot.kernel.hold = False
        robot.running = False
        robot.program = Idle()
        self.selected = ""
        self._set("$PRO_NAME1[]", "")
        self._set("$PRO_STATE1", KrlEnum("P_FREE"))
        return ErrorCode.SUCCESS

    def _submit(self, command: int) -> int:
        sps = self.robot.sps if self.robot is not None else None
        if sps is None:
            return ErrorCode.GENERAL
        state = self._state("$PRO_STATE0")
        if command == ProgramCommand.START:
            if state in ("P_RESET", "P_END", "P_FREE"):
                sps.start()
            else:
                sps.running = True
                self._set("$PRO_STATE0", KrlEnum("P_ACTIVE"))
            return ErrorCode.SUCCESS
        sps.running = False
        new = {3: "P_STOP", 1: "P_RESET"}.get(command, "P_FREE")
        self._set("$PRO_STATE0", KrlEnum(new))
        return ErrorCode.SUCCESS

    def is_selected(self, key: str) -> bool:
        """True when ``key`` is the selected module's .src or .dat (the KRC locks both)."""
        if not self.selected or self.robot is None or isinstance(self.robot.program, Idle):
            return False
        stem = self.vfs.key(self.selected).rsplit(".", 1)[0]
        return key.rsplit(".", 1)[0] == stem

    # ------------------------------------------------------------------ #11, #12, #63

    def motion(self, kind: int, position: str) -> int:
        """A manual PTP/LIN(_REL) motion; only while no program runs or holds a motion."""
        robot = self.robot
        if robot is None:
            return ErrorCode.NO_INTERFACE
        label = _MOTION_KIND.get(MotionType(kind)) if kind in (1, 2, 3, 4) else None
        if label is None:
            return ErrorCode.NOT_IMPLEMENTED
        if robot.running or robot.kernel.moving:
            self._message(
                f"{label} refused: the robot is busy (a program runs or a motion is active)"
            )
            return ErrorCode.GENERAL
        try:
            target = parse_value(position)
            if not isinstance(target, Struct):
                raise KrlValueError(f"{position!r} is not an aggregate")
            planner = _Planner()
            job = planner._plan(robot.kernel, label, target, False, f"{label} {position}", _NODE)
            # A LIN is planned in slices (the interpreter spreads them over cycles); one
            # message may hold the loop for PLAN_BUDGET at most. The job queues the motion only
            # in its last slice, so one left unfinished leaves nothing behind.
            if job is not None and not job.step(time.perf_counter() + PLAN_BUDGET):
                raise MotionRefused(f"planning took longer than {PLAN_BUDGET:g} s")
        except (KrlValueError, KrlRuntimeError, MotionRefused, ArithmeticError) as exc:
            # ArithmeticError: a number no float holds ({A1 <400 digits>}); CrossComm's
            # motion refuses such a target, which the server maps to ErrorGeneral (E_FAIL)
            self._message(f"{label} {position[:60]}: {exc}")
            return ErrorCode.GENERAL
        return ErrorCode.SUCCESS

    def key(self, key: int, target: int, released: bool) -> int:
        """The start and stop keys act on press; jog keys and the 6D mouse are not emulated."""
        if self.robot is None:
            return ErrorCode.NO_INTERFACE
        if key in (KcpKey.JOG, KcpKey.MOUSE_6D):
            return ErrorCode.NOT_IMPLEMENTED
        if key not in (KcpKey.START, KcpKey.STOP):
            return ErrorCode.NOT_IMPLEMENTED
        if released:
            return ErrorCode.SUCCESS
        command = ProgramCommand.START if key == KcpKey.START else ProgramCommand.STOP
        return self.program(command, target)

    def confirm_all(self) -> int:
        """Acknowledge: ``$STOPMESS`` FALSE, ``$EMU_MESSAGE[]`` empty (the program stays put)."""
        if self.robot is None:
            return ErrorCode.NO_INTERFACE
        self._set("$STOPMESS", False)
        self._message("")
        return ErrorCode.SUCCESS
