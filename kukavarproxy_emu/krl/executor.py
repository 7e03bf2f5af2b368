"""KRL programs on the simulated controller: the robot interpreter and the submit interpreter.

* :func:`load_module` — a ``.src``/``.sub`` file (and its ``.dat``) or the name of a shipped
  program (``follow``, ``actuator``, ``ext_move_axis``, ``joint_path``, ``cart_path``, ``sps``)
  parsed to a :class:`~.ast.Module`; syntax errors raise :class:`KrlSyntaxError`
  (``file:line:column: message`` + the source line).
* :class:`KrlProgram` — a :class:`~..motion.programs.Program` running a module in the robot
  interpreter (``$PRO_STATE1``/``$PRO_NAME1[]``); a runtime error becomes a
  :class:`~..motion.kernel.MotionRefused` with ``FILE:LINE:COL:`` in front, so the robot stops
  it like any refused motion (``#P_STOP``, ``$STOPMESS``, ``$EMU_MESSAGE[]``).
* :class:`KrlSubmit` — the submit interpreter (``$PRO_STATE0``/``$PRO_NAME0[]``): runs an SPS
  module beside the robot program, its ``LOOP`` body once per cycle. A runtime error stops
  only the SPS (``$PRO_STATE0`` = ``#P_STOP``, message in ``$EMU_MESSAGE[]`` if it is free).

A module's data list is declared into the global store once, when the program is loaded, so
its variables are readable and writable over KUKAVARPROXY and keep their values over a restart
(as a KRC keeps ``.dat`` values).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from importlib import resources
from pathlib import Path

from pyopenshowvar.krl import KrlEnum

from ..motion.kernel import MotionKernel, MotionRefused
from ..motion.programs import Program
from ..store import VariableStore
from . import ast
from .interp import DEFAULT_BUDGET, Interpreter
from .lazy_pass import LazyPass
from .parser import KrlSyntaxError, parse_src, read_src
from .runtime import KrlRuntimeError

__all__ = [
    "SHIPPED",
    "KrlProgram",
    "KrlSubmit",
    "KrlSyntaxError",
    "load_module",
    "shipped_path",
]

log = logging.getLogger(__name__)

#: ``--program NAME`` / ``--sps NAME`` of a shipped file → file in ``kukavarproxy_emu/programs``.
SHIPPED = {
    "follow": "follow.src",
    "actuator": "actuator.src",
    "ext_move_axis": "ext_move_axis.src",
    "joint_path": "joint_path.src",
    "cart_path": "cart_path.src",
    "sps": "sps.sub",
}
_MESSAGE = 128
#: Statements of a "light" SPS pass: one the robot's IPO clock may run late, batched with
#: others, while the robot rests (see Robot.tick); an SPS snapshot of a few dozen variables is
#: one, a pass computing for its whole budget is not.
LIGHT_PASS = 64


def shipped_path(name: str) -> Path:
    """The path of a shipped program (``follow`` → ``.../programs/follow.src``)."""
    return Path(str(resources.files("kukavarproxy_emu") / "programs" / SHIPPED[name]))


def load_module(program: str | Path) -> ast.Module:
    """Parse a shipped program name or a ``.src``/``.sub`` path (plus its ``.dat``).

    Raises :class:`KrlSyntaxError` (a ``ValueError``) or ``OSError`` for a missing file.
    """
    if isinstance(program, str) and program in SHIPPED:
        program = shipped_path(program)
    path = Path(program)
    if not path.is_file():
        raise FileNotFoundError(f"KRL program not found: {path}")
    module = read_src(path)
    if not module.routines:
        raise KrlSyntaxError("no DEF in the file", filename=str(path), line=1, column=1, text="")
    return module


def _declare_dat(
    module: ast.Module, store: VariableStore, checkpoint: Callable[[], None] | None = None
) -> None:
    if module.dat is not None:
        # Module data are visible to the program; we make them global so a PC can reach them.
        store.load_dat(module.dat, all_global=True, checkpoint=checkpoint)


def _short_name(module: ast.Module) -> str:
    return Path(module.filename).name


def _set(store: VariableStore, name: str, value: object) -> None:
    try:
        store.set_system(name, value)
    except LookupError:
        log.debug("no variable %s in the store", name)


def _ensure_timers(store: VariableStore) -> None:
    """``$TIMER_STOP[1..32]`` (TRUE = stopped), declared if the store lacks it."""
    if "$TIMER_STOP" not in store.names():
        store.declare("$TIMER_STOP", "BOOL", (32,), "TRUE")


def advance_timers(store: VariableStore, dt: float) -> None:
    """Count every running ``$TIMER[i]`` (``$TIMER_STOP[i]`` FALSE) up by ``dt`` seconds."""
    stops = store.get("$TIMER_STOP")
    if not isinstance(stops, list) or all(s is True for s in stops):
        return
    ms = round(dt * 1000.0)
    for i, stopped in enumerate(stops, start=1):
        if stopped is False:
            value = store.get(f"$TIMER[{i}]")
            if isinstance(value, int):
                store.set_system(f"$TIMER[{i}]", value + ms)


class KrlProgram(Program):
    """A KRL module run by the robot interpreter (``--program PROG.src``)."""

    def __init__(
        self,
        module: ast.Module,
        store: VariableStore,
        budget: int = DEFAULT_BUDGET,
        *,
        checkpoint: Callable[[], None] | None = None,
    ):
        """``checkpoint`` is called before every declaration of the data list (a long list
        lets other work in, see kukavarproxy_emu.slices)."""
        self.module = module
        self.krl_name = module.name[:24]
        self.filename = _short_name(module)
        self.budget = budget
        self.interp: Interpreter | None = None
        _declare_dat(module, store, checkpoint)
        _ensure_timers(store)

    def start(self, kernel: MotionKernel) -> None:
        self.interp = Interpreter(self.module, kernel.store, kernel, budget=self.budget)
        self.interp.start()

    def step(self, kernel: MotionKernel) -> None:
        interp = self.interp
        if interp is None or interp.finished or interp.halted:
            return
        advance_timers(kernel.store, kernel.ipo)
        try:
            interp.step()
        except KrlRuntimeError as exc:
            raise MotionRefused(exc.located(self.filename)) from None
        except MotionRefused:
            raise
        except Exception as exc:  # an interpreter bug must stop the program, not the server
            log.exception("KRL interpreter failed")
            raise MotionRefused(f"{self.filename}: internal error: {exc}") from None
        store = kernel.store
        if interp.finished:
            _set(store, "$PRO_STATE1", KrlEnum("P_END"))
        elif interp.halted:
            _set(store, "$PRO_STATE1", KrlEnum("P_STOP"))
            _set(store, "$EMU_MESSAGE[]", f"{self.filename}: HALT"[:_MESSAGE])


class KrlSubmit:
    """The submit interpreter: an SPS module beside the robot program, one LOOP pass a cycle."""

    def __init__(
        self,
        module: ast.Module,
        store: VariableStore,
        *,
        ipo: float = 0.012,
        budget: int = DEFAULT_BUDGET,
    ) -> None:
        self.module = module
        self.store = store
        self.ipo = ipo
        self.filename = _short_name(module)
        _declare_dat(module, store)
        _ensure_timers(store)
        self.interp = Interpreter(module, store, None, submit=True, budget=budget)
        self.running = False
        #: The message that stopped the SPS ("" while it runs).
        self.message = ""
        #: The last cycle was one whole, short pass (see :attr:`light`).
        self.light = False
        #: Run passes lazily where nothing can tell (:mod:`.lazy_pass`); False: always eagerly.
        self.lazy = True
        self._lazy: LazyPass | None = None
        self._lazy_loop: int | None = None

    def start(self) -> None:
        """(Re)start the submit program from its first statement."""
        self.interp.start()
        self.running = True
        self.message = ""
        _set(self.store, "$PRO_NAME0[]", self.module.name[:24])
        _set(self.store, "$PRO_STATE0", KrlEnum("P_ACTIVE"))

    def step(self, *, lazy: bool = True) -> None:
        """One interpolation cycle of the submit interpreter; ``lazy``: its pass may run
        lazily (:mod:`.lazy_pass`) if :attr:`lazy` allows it too."""
        self.light = False
        if not self.running:
            return
        self.interp.sim_time += self.ipo
        try:
            if not (lazy and self.lazy and self._lazy_pass()):
                self.interp.step()
        except KrlRuntimeError as exc:
            self._stop(exc.located(self.filename), "P_STOP")
            return
        except Exception as exc:  # never let the SPS take the robot task down
            log.exception("KRL submit interpreter failed")
            self._stop(f"{self.filename}: internal error: {exc}", "P_STOP")
            return
        if self.interp.finished or self.interp.halted:
            self._stop("", "P_END" if self.interp.finished else "P_STOP")
            return
        interp = self.interp
        self.light = interp.whole_pass and interp.count <= LIGHT_PASS

    def _lazy_pass(self) -> bool:
        """Run this cycle's pass lazily (:mod:`.lazy_pass`) if it may be; False otherwise."""
        at = self.interp._at_pass
        if at is None:
            return False
        if at != self._lazy_loop:  # compiled once per LOOP the pass ends at
            self._lazy_loop = at
            self._lazy = LazyPass.compile(self.interp, at)
        return self._lazy is not None and self._lazy.run()

    def _stop(self, message: str, state: str) -> None:
        self.running = False
        self.message = message
        _set(self.store, "$PRO_STATE0", KrlEnum(state))
        if message:
            log.warning("submit program stopped: %s", message)
            try:
                free = self.store.get("$EMU_MESSAGE[]") == ""
            except LookupError:
                free = False
            if free:
                _set(self.store, "$EMU_MESSAGE[]", f"SPS {message}"[:_MESSAGE].replace('"', "'"))


def parse_text(text: str, filename: str = "<src>") -> ast.Module:
    """Parse KRL source text (tests, in-process use); raises :class:`KrlSyntaxError`."""
    return parse_src(text, filename)
