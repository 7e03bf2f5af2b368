"""pyopenshowvar: an asyncio client for KUKAVARPROXY, the variable server of KUKA KRC controllers.

Layers (dependencies point down only)::

    client / robot helpers      Client, connect, read_joint_angles, paths, outputs
    connection                  asyncio socket, message ids, pipelining, timeouts, keep-alive
    krl                         typed KRL values: one parser, one formatter (KRC4-exact)
    protocol                    sans-IO codec shared with the emulator
    errors                      the exception tree

Quick start::

    import asyncio
    from pyopenshowvar import Client

    async def main() -> None:
        async with Client("127.0.0.1", 7000) as kvp:
            print(await kvp.read_joint_angles())

    asyncio.run(main())
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from . import lazy
from .core import ReadResult
from .errors import (
    KrlValueError,
    KvpConnectionError,
    KvpError,
    KvpStalledError,
    KvpTimeoutError,
    ProtocolError,
    ReadFailedError,
    UnknownVariableError,
    VariableError,
    WriteRefusedError,
)
from .krl import (
    Axis,
    E6Axis,
    E6Pos,
    Frame,
    KrlEnum,
    KrlValue,
    Pos,
    Struct,
    format_krc4,
    format_value,
    parse_array,
    parse_value,
)
from .robot import PathHandshake
from .stats import AccessStats, StatsSnapshot

if TYPE_CHECKING:
    from .client import Client, connect, run
    from .snapshot import Snapshot, SnapshotLimits, SnapshotReading, SnapshotTornError

#: Public names imported on first use (module ``__getattr__``), so that ``import
#: pyopenshowvar`` costs only what reading and writing variables needs: the asyncio client (and
#: asyncio) is not loaded by a program that uses the blocking one (``pyopenshowvar.sync``, ``kvp
#: read``); numpy and the kinematics are imported by the code that uses them, never here.
_LAZY = {
    "Client": "client",
    "connect": "client",
    "run": "client",
    **dict.fromkeys(
        ("Snapshot", "SnapshotLimits", "SnapshotReading", "SnapshotTornError"), "snapshot"
    ),
}

__version__ = "0.1.0"

__all__ = [
    "AccessStats",
    "Axis",
    "Client",
    "E6Axis",
    "E6Pos",
    "Frame",
    "KrlEnum",
    "KrlValue",
    "KrlValueError",
    "KvpConnectionError",
    "KvpError",
    "KvpStalledError",
    "KvpTimeoutError",
    "PathHandshake",
    "Pos",
    "ProtocolError",
    "ReadFailedError",
    "ReadResult",
    "Snapshot",
    "SnapshotLimits",
    "SnapshotReading",
    "SnapshotTornError",
    "StatsSnapshot",
    "Struct",
    "UnknownVariableError",
    "VariableError",
    "WriteRefusedError",
    "__version__",
    "connect",
    "format_krc4",
    "format_value",
    "parse_array",
    "parse_value",
    "run",
]


def __getattr__(name: str) -> Any:
    return lazy.load(__name__, _LAZY, globals(), name)


def __dir__() -> list[str]:
    return lazy.names(_LAZY, globals())
