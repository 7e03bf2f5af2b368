"""A cell of robots in one process: N independent emulators on consecutive ports.

``kukavarproxy-emu --robots N`` (or :class:`Cell` in process) serves N KR 6 R900 sixx robots,
each behind its own KUKAVARPROXY: its own variable store, program, submit interpreter, plant,
latency worker and connections, on ports ``port, port + 1, ... port + N - 1`` (every one
ephemeral with ``port = 0``). They share the process and its event loop, so a cell is cheap:
the IPO clocks run on one timer (:mod:`.motion.clock`) with their deadlines spread over the
period (``ipo_phase``), and a robot at rest costs little more than its timer
(docs/emulator.md, "A cell of robots").

:func:`cell_configs` derives robot ``k``'s configuration from one: port ``port + k``, seed
``seed + k`` (the robots' sensor noise and latency draws differ, reproducibly), phase
``k / N`` of the IPO period, and UDP discovery only on the first robot (they cannot all bind
UDP 6999). Pass your own list of configurations to :class:`Cell` for robots that differ more
(another program or ``$CONFIG.DAT`` each).
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence
from dataclasses import replace
from types import TracebackType
from typing import Self

from .config import EmulatorConfig
from .server import Emulator

__all__ = ["MAX_ROBOTS", "PHASE_GROUPS", "Cell", "cell_configs"]

#: Robots one process serves at most (each needs its own port and a share of one core).
MAX_ROBOTS = 200
#: The robots' IPO deadlines fall on this many instants per period (1 ms apart at 12 ms):
#: robots of one instant tick in one timer callback (one loop wake-up for several robots),
#: while the instants spread the work, so one instant's burst stays short.
PHASE_GROUPS = 12


def cell_configs(config: EmulatorConfig, robots: int) -> list[EmulatorConfig]:
    """The configurations of ``robots`` robots made from ``config`` (see the module docstring).

    Raises ``ValueError`` for a count out of 1..MAX_ROBOTS or ports beyond 65535.
    """
    if not 1 <= robots <= MAX_ROBOTS:
        raise ValueError(f"--robots must be in 1..{MAX_ROBOTS}, not {robots}")
    if config.port and config.port + robots - 1 > 0xFFFF:
        raise ValueError(f"ports {config.port}..{config.port + robots - 1} exceed 65535")
    if robots == 1:
        return [config]
    seed = config.seed if config.seed is not None else secrets.randbits(31)
    period = config.ipo / config.speed
    groups = min(robots, PHASE_GROUPS)
    out = []
    for k in range(robots):
        out.append(
            replace(
                config,
                port=config.port + k if config.port else 0,
                seed=seed + k,
                ipo_phase=period * (k % groups) / groups,
                discovery=config.discovery if k == 0 else False,
            )
        )
    return out


class Cell:
    """``async with Cell(configs) as cell:`` starts every emulator; ``cell.emulators[k]``.

    A robot that cannot start (port in use, KRL syntax error) stops the ones already started
    and raises.
    """

    def __init__(self, configs: Sequence[EmulatorConfig]) -> None:
        if not configs:
            raise ValueError("a cell needs at least one robot")
        self.configs = list(configs)
        self.emulators: list[Emulator] = []

    async def start(self) -> Self:
        try:
            for config in self.configs:
                emu = Emulator(config)
                await emu.start()
                self.emulators.append(emu)
        except BaseException:
            await self.close()
            raise
        return self

    async def close(self) -> None:
        emulators, self.emulators = self.emulators, []
        for emu in reversed(emulators):
            await emu.close()

    async def __aenter__(self) -> Self:
        return await self.start()

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()
