"""Run an :class:`~kukavarproxy_emu.server.Emulator` in a background thread for synchronous code.

The ``kvp`` CLI (``--emulate``), typer's CliRunner tests and scripts that are not asyncio use it;
the emulator keeps its own event loop so it serves requests while the caller blocks.
"""

from __future__ import annotations

from pyopenshowvar.loopthread import LoopThread

from .config import EmulatorConfig
from .faults import FaultSet
from .server import Emulator, Stats
from .store import VariableStore

__all__ = ["EmulatorThread"]


class EmulatorThread(LoopThread[Emulator]):
    """An :class:`Emulator` on its own event loop in a daemon thread, for synchronous code.

    ``with EmulatorThread(EmulatorConfig(port=0)) as emu: ... emu.port ...``. The store and the
    faults may be used from the calling thread (both are plain, GIL-protected objects); use
    :meth:`call` to run something on the emulator's loop when ordering with traffic matters.
    """

    NAME = "kukavarproxy-emu"
    LABEL = "the emulator thread"

    def __init__(
        self,
        config: EmulatorConfig | None = None,
        *,
        store: VariableStore | None = None,
        start_timeout: float = 10.0,
    ) -> None:
        super().__init__(start_timeout=start_timeout)
        self.config = config if config is not None else EmulatorConfig(port=0)
        self._store = store

    def _make(self) -> Emulator:
        return Emulator(self.config, store=self._store)

    @property
    def emulator(self) -> Emulator:
        return self.service

    @property
    def host(self) -> str:
        return self.emulator.host

    @property
    def port(self) -> int:
        return self.emulator.port

    @property
    def store(self) -> VariableStore:
        return self.emulator.store

    @property
    def faults(self) -> FaultSet:
        return self.emulator.faults

    @property
    def stats(self) -> Stats:
        return self.emulator.stats
