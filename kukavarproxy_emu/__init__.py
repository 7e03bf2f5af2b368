"""A faithful KUKAVARPROXY 9.0 emulator: the KRC4 side of the protocol, for tests and demos.

``kukavarproxy-emu --port 0`` on the command line, or in process::

    async with Emulator(EmulatorConfig(port=0)) as emu:
        ...  # connect to emu.host, emu.port

See docs/emulator.md for the behaviours, latency profiles and fault injection.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from pyopenshowvar import lazy

if TYPE_CHECKING:
    from .cell import Cell, cell_configs
    from .config import EmulatorConfig
    from .emulator_thread import EmulatorThread
    from .faults import Fault, FaultSet
    from .latency import PROFILES, LatencyProfile, ServiceTime
    from .plant import Obstacle
    from .responder import Responder, build_store
    from .server import ConnectionInfo, Emulator, Stats

# Imported on first use, so `import kukavarproxy_emu.store` does not pull in
# asyncio and the server.
_LAZY = {
    "Cell": "cell",
    "cell_configs": "cell",
    "EmulatorConfig": "config",
    "Fault": "faults",
    "FaultSet": "faults",
    "PROFILES": "latency",
    "LatencyProfile": "latency",
    "ServiceTime": "latency",
    "Obstacle": "plant",
    "ConnectionInfo": "server",
    "Emulator": "server",
    "EmulatorThread": "emulator_thread",
    "Responder": "responder",
    "Stats": "server",
    "build_store": "responder",
}


def __getattr__(name: str) -> Any:
    return lazy.load(__name__, _LAZY, globals(), name)


__all__ = [
    "PROFILES",
    "Cell",
    "ConnectionInfo",
    "Emulator",
    "EmulatorConfig",
    "EmulatorThread",
    "Fault",
    "FaultSet",
    "LatencyProfile",
    "Obstacle",
    "Responder",
    "ServiceTime",
    "Stats",
    "build_store",
    "cell_configs",
]
