"""Robot-level helpers on top of raw reads and writes (JOpenShowVar parity, then better).

Mixed into :class:`~pyopenshowvar.client.Client`:

* ``read_joint_angles()`` / ``read_joint_torques()`` / ``read_pose()`` — numpy arrays and typed
  poses. Torques come from ONE read of ``$TORQUE_AXIS_ACT[]`` (JOpenShowVar makes six round
  trips); proxies that cannot read the whole array get six *pipelined* element reads.
* ``write_joint_path()`` / ``write_cartesian_path()`` — thesis Algorithms 4.7–4.10 plus a
  handshake so a KRL program knows how many points are valid and when to start
  (see ``docs/paths.md`` for the variables and the matching KRL program).
* ``set_output()`` — binary outputs through a global BOOL array the SPS copies to ``$OUT``
  (Algorithm 4.11), because ``$OUT`` itself is not writable over KVP.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from .errors import KrlValueError, KvpTimeoutError, UnknownVariableError
from .krl import E6Axis, E6Pos, KrlValue, Struct, parse_array, parse_value

if TYPE_CHECKING:
    from .client import ReadResult

__all__ = ["PathHandshake", "RobotHelpers"]

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

_AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
_CART = ("X", "Y", "Z", "A", "B", "C")


@dataclass(frozen=True, slots=True)
class PathHandshake:
    """Names of the globals a path-running KRL program shares with the PC.

    The defaults are declared by the emulator's default ``$CONFIG.DAT``; declare the same names
    on a real controller (``docs/paths.md``).
    """

    count: str = "PATH_COUNT"  # INT: number of valid points, written before start
    start: str = "PATH_START"  # BOOL: PC sets TRUE; the program clears it when finished
    busy: str = "PATH_BUSY"  # BOOL: TRUE while the program runs the path
    done: str = "PATH_DONE"  # BOOL: TRUE when the last point was reached
    index: str = "PATH_INDEX"  # INT: point being executed (progress)


class RobotHelpers:
    """Helpers that need only read/write/read_many; mixed into the Client."""

    _torque_whole_array: bool | None = None

    @property
    def endpoint(self) -> str:
        raise NotImplementedError

    # The client implements these; declared here so the helpers type-check on their own.
    async def read(self, name: str, *, timeout: float | None = None) -> str:
        raise NotImplementedError

    async def write(self, name: str, value: KrlValue | str, *, timeout: float | None = None) -> str:
        raise NotImplementedError

    async def read_many(
        self, names: Iterable[str], *, typed: bool = False, timeout: float | None = None
    ) -> dict[str, ReadResult]:
        raise NotImplementedError

    async def write_many(
        self, items: Sequence[tuple[str, KrlValue | str]], *, timeout: float | None = None
    ) -> None:
        raise NotImplementedError

    async def read_joint_angles(self, *, timeout: float | None = None) -> FloatArray:
        """A1..A6 of ``$AXIS_ACT`` in degrees, as a numpy array of shape (6,)."""
        text = await self.read("$AXIS_ACT", timeout=timeout)
        axis = parse_value(text, "E6AXIS")
        assert isinstance(axis, Struct)
        return _members_array(axis, _AXES, "$AXIS_ACT", self.endpoint)

    async def read_pose(self, *, timeout: float | None = None) -> E6Pos:
        """``$POS_ACT`` (TCP of ``$TOOL`` in ``$BASE``) as an :class:`E6Pos`; ``.to_numpy()`` gives X..C."""
        value = parse_value(await self.read("$POS_ACT", timeout=timeout), "E6POS")
        assert isinstance(value, E6Pos)
        return value

    async def read_joint_torques(self, *, timeout: float | None = None) -> FloatArray:
        """Torques of A1..A6 in Nm from ``$TORQUE_AXIS_ACT``, shape (6,).

        One read of the whole array when the proxy supports it, otherwise six pipelined element
        reads (still one round-trip time, not six). The choice is remembered per client.
        """
        io = self
        if self._torque_whole_array is not False:
            try:
                values = parse_array(await io.read("$TORQUE_AXIS_ACT[]", timeout=timeout), "REAL")
                if len(values) >= 6:
                    self._torque_whole_array = True
                    return np.asarray(values[:6], dtype=np.float64)
            except (UnknownVariableError, KrlValueError):
                pass
            log.info("%s cannot read $TORQUE_AXIS_ACT[] whole; using element reads", io.endpoint)
            self._torque_whole_array = False
        names = [f"$TORQUE_AXIS_ACT[{i}]" for i in range(1, 7)]
        results = await io.read_many(names, timeout=timeout)
        return np.asarray([_real(parse_value(results[n].unwrap(), "REAL")) for n in names])

    # ------------------------------------------------------------------ paths

    async def write_joint_path(
        self,
        points: Iterable[Sequence[float] | E6Axis],
        *,
        array: str = "MYE6ARRAY",
        capacity: int = 512,
        handshake: PathHandshake | None = PathHandshake(),
        start: bool = True,
        timeout: float | None = None,
    ) -> int:
        """Write a joint-space path (degrees) into ``array[1..n]`` and start it.

        Each point is written as ``{A1 .., ..., A6 ..}`` (external axes keep their values),
        pipelined. Then the handshake's count is set and, if ``start``, its start flag. Returns n.
        """
        values = [p if isinstance(p, Struct) else _partial(_AXES, p) for p in points]
        return await self._write_path(values, array, capacity, handshake, start, timeout)

    async def write_cartesian_path(
        self,
        points: Iterable[Sequence[float] | Struct],
        *,
        array: str = "MYPOSARRAY",
        capacity: int = 512,
        handshake: PathHandshake | None = PathHandshake(),
        start: bool = True,
        timeout: float | None = None,
    ) -> int:
        """Write a Cartesian path (X Y Z in mm, A B C in degrees) into a POS array and start it.

        Plain 6-sequences are written as ``{X .., Y .., Z .., A .., B .., C ..}`` so S and T keep
        the values in the array (KRL partial-aggregate semantics); pass :class:`Pos` objects to
        set S and T explicitly.
        """
        values = [p if isinstance(p, Struct) else _partial(_CART, p) for p in points]
        return await self._write_path(values, array, capacity, handshake, start, timeout)

    async def _write_path(
        self,
        values: list[Struct],
        array: str,
        capacity: int,
        handshake: PathHandshake | None,
        start: bool,
        timeout: float | None,
    ) -> int:
        io = self
        if not values:
            raise ValueError("a path needs at least one point")
        if len(values) > capacity:
            raise ValueError(f"path of {len(values)} points exceeds the array capacity {capacity}")
        if handshake is not None:
            # Never overwrite points the robot is still executing.
            if await _read_bool(io, handshake.busy, timeout):
                raise RuntimeError(
                    f"{handshake.busy} is TRUE on {io.endpoint}: a path is still running"
                )
            await io.write(handshake.start, False, timeout=timeout)
            await io.write(handshake.done, False, timeout=timeout)
        await io.write_many(
            [(f"{array}[{i}]", v) for i, v in enumerate(values, 1)], timeout=timeout
        )
        if handshake is not None:
            await io.write(handshake.count, len(values), timeout=timeout)
            if start:
                await io.write(handshake.start, True, timeout=timeout)
        return len(values)

    async def wait_path_done(
        self,
        handshake: PathHandshake = PathHandshake(),
        *,
        poll: float = 0.024,
        timeout: float = 60.0,
    ) -> float:
        """Poll until the program reports the path finished; returns the seconds waited."""
        io = self
        t0 = time.monotonic()
        while time.monotonic() - t0 < timeout:
            if await _read_bool(io, handshake.done, None):
                return time.monotonic() - t0
            await asyncio.sleep(poll)
        raise KvpTimeoutError(
            f"path on {io.endpoint} not done after {timeout:g} s ({handshake.done} still FALSE)"
        )

    # ------------------------------------------------------------------ outputs

    async def set_output(
        self, index: int, value: bool, *, array: str = "OUTPUT_VARS", timeout: float | None = None
    ) -> None:
        """Set binary output ``index`` through the global BOOL array the SPS copies to ``$OUT``."""
        io = self
        await io.write(f"{array}[{index}]", bool(value), timeout=timeout)

    async def set_outputs(
        self,
        values: Mapping[int, bool],
        *,
        array: str = "OUTPUT_VARS",
        timeout: float | None = None,
    ) -> None:
        """Set several outputs in one pipelined burst."""
        io = self
        await io.write_many(
            [(f"{array}[{i}]", bool(v)) for i, v in values.items()], timeout=timeout
        )

    async def read_output(self, index: int, *, timeout: float | None = None) -> bool:
        """The real output ``$OUT[index]`` (readable, though not writable over KVP)."""
        io = self
        return await _read_bool(io, f"$OUT[{index}]", timeout)


def _real(value: KrlValue) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise KrlValueError(f"expected a REAL, got {value!r}")
    return float(value)


async def _read_bool(io: RobotHelpers, name: str, timeout: float | None) -> bool:
    value = parse_value(await io.read(name, timeout=timeout), "BOOL")
    return bool(value)


def _partial(keys: Sequence[str], point: Sequence[float] | Any) -> Struct:
    values = [float(v) for v in point]
    if len(values) != len(keys):
        raise ValueError(f"expected {len(keys)} values ({' '.join(keys)}), got {len(values)}")
    if not all(np.isfinite(values)):
        raise ValueError(f"path point contains NaN or infinity: {values}")
    return Struct(None, dict(zip(keys, values, strict=True)))


def _members_array(value: Struct, keys: Sequence[str], name: str, endpoint: str) -> FloatArray:
    try:
        return np.asarray([_real(value[k]) for k in keys], dtype=np.float64)
    except (KeyError, TypeError) as exc:
        raise KrlValueError(f"{name!r} on {endpoint} lacks a member: {exc}") from exc
