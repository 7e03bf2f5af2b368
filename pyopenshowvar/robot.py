"""Robot-level helpers on top of raw reads and writes (JOpenShowVar parity, then better).

Written once as operations (:mod:`pyopenshowvar.core`) and mixed into both clients, the
asyncio :class:`~pyopenshowvar.client.Client` and the blocking :class:`pyopenshowvar.sync.Client`:

* ``read_joint_angles()`` / ``read_joint_torques()`` / ``read_pose()`` — numpy arrays and typed
  poses. Torques come from ONE read of ``$TORQUE_AXIS_ACT[]`` (JOpenShowVar makes six round
  trips); proxies that cannot read the whole array get six *pipelined* element reads.
* ``write_joint_path()`` / ``write_cartesian_path()`` — thesis Algorithms 4.7–4.10 plus a
  handshake so a KRL program knows how many points are valid and when to start
  (see ``docs/paths.md`` for the variables and the matching KRL program).
* ``read_snapshot()`` — many variables copied by the controller's SPS in one pass, read in
  ONE request (:mod:`pyopenshowvar.snapshot`).
* ``set_output()`` — binary outputs through a global BOOL array the SPS copies to ``$OUT``
  (Algorithm 4.11), because ``$OUT`` itself is not writable over KVP.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeAlias, cast

from .core import (
    Call,
    LazyOps,
    Op,
    as_async_method,
    as_sync_method,
    lazy_async_method,
    lazy_sync_method,
)
from .errors import KrlValueError, KvpTimeoutError, UnknownVariableError
from .krl import E6Axis, E6Pos, KrlValue, Struct, parse_array, parse_value

__all__ = ["PathHandshake", "RobotHelpers", "SyncRobotHelpers"]

log = logging.getLogger(__name__)

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    from . import snapshot as _snapshot

    _lazy_async, _lazy_sync = as_async_method, as_sync_method
else:
    # the snapshot layout code is imported when read_snapshot is first used
    _snapshot = LazyOps(f"{__package__}.snapshot")
    _lazy_async, _lazy_sync = lazy_async_method, lazy_sync_method

# numpy is imported by the helpers that return arrays, not here: a client that only reads and
# writes variables (``kvp read``) never loads it
FloatArray: TypeAlias = "npt.NDArray[np.float64]"

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


# --------------------------------------------------------------------------- operations
# Each helper is written once, as an operation (see pyopenshowvar.core): it yields the calls it
# needs and gets their results back. The asyncio and the blocking client both run it.


def _read(name: str, timeout: float | None) -> Call:
    return ("read", (name,), {"timeout": timeout})


def _write(name: str, value: KrlValue | str, timeout: float | None) -> Call:
    return ("write", (name, value), {"timeout": timeout})


def read_joint_angles(io: Any, *, timeout: float | None = None) -> Op[FloatArray]:
    """A1..A6 of ``$AXIS_ACT`` in degrees, as a numpy array of shape (6,)."""
    axis = parse_value((yield _read("$AXIS_ACT", timeout)), "E6AXIS")
    assert isinstance(axis, Struct)
    return _members_array(axis, _AXES, "$AXIS_ACT", io.endpoint)


def read_pose(io: Any, *, timeout: float | None = None) -> Op[E6Pos]:
    """``$POS_ACT`` (TCP of ``$TOOL`` in ``$BASE``) as an :class:`E6Pos`; ``.to_numpy()`` gives X..C."""
    value = parse_value((yield _read("$POS_ACT", timeout)), "E6POS")
    assert isinstance(value, E6Pos)
    return value


def read_joint_torques(io: Any, *, timeout: float | None = None) -> Op[FloatArray]:
    """Torques of A1..A6 in Nm from ``$TORQUE_AXIS_ACT``, shape (6,).

    One read of the whole array when the proxy supports it, otherwise six pipelined element
    reads (still one round-trip time, not six). The choice is remembered per client.
    """
    if io._torque_whole_array is not False:
        try:
            values = parse_array((yield _read("$TORQUE_AXIS_ACT[]", timeout)), "REAL")
            if len(values) >= 6:
                io._torque_whole_array = True
                return _float_array(cast("list[float]", values[:6]))
        except (UnknownVariableError, KrlValueError):
            pass
        log.info("%s cannot read $TORQUE_AXIS_ACT[] whole; using element reads", io.endpoint)
        io._torque_whole_array = False
    names = [f"$TORQUE_AXIS_ACT[{i}]" for i in range(1, 7)]
    results = yield ("read_many", (names,), {"timeout": timeout})
    return _float_array([_real(parse_value(results[n].unwrap(), "REAL")) for n in names])


def write_joint_path(
    io: Any,
    points: Iterable[Sequence[float] | E6Axis],
    *,
    array: str = "MYE6ARRAY",
    capacity: int = 512,
    handshake: PathHandshake | None = PathHandshake(),
    start: bool = True,
    timeout: float | None = None,
) -> Op[int]:
    """Write a joint-space path (degrees) into ``array[1..n]`` and start it.

    Each point is written as ``{A1 .., ..., A6 ..}`` (external axes keep their values),
    pipelined. Then the handshake's count is set and, if ``start``, its start flag. Returns n.
    """
    values = [p if isinstance(p, Struct) else _partial(_AXES, p) for p in points]
    return (yield from _write_path(io, values, array, capacity, handshake, start, timeout))


def write_cartesian_path(
    io: Any,
    points: Iterable[Sequence[float] | Struct],
    *,
    array: str = "MYPOSARRAY",
    capacity: int = 512,
    handshake: PathHandshake | None = PathHandshake(),
    start: bool = True,
    timeout: float | None = None,
) -> Op[int]:
    """Write a Cartesian path (X Y Z in mm, A B C in degrees) into a POS array and start it.

    Plain 6-sequences are written as ``{X .., Y .., Z .., A .., B .., C ..}`` so S and T keep
    the values in the array (KRL partial-aggregate semantics); pass :class:`Pos` objects to
    set S and T explicitly.
    """
    values = [p if isinstance(p, Struct) else _partial(_CART, p) for p in points]
    return (yield from _write_path(io, values, array, capacity, handshake, start, timeout))


def _write_path(
    io: Any,
    values: list[Struct],
    array: str,
    capacity: int,
    handshake: PathHandshake | None,
    start: bool,
    timeout: float | None,
) -> Op[int]:
    if not values:
        raise ValueError("a path needs at least one point")
    if len(values) > capacity:
        raise ValueError(f"path of {len(values)} points exceeds the array capacity {capacity}")
    if handshake is not None:
        # Never overwrite points the robot is still executing.
        if _bool((yield _read(handshake.busy, timeout))):
            raise RuntimeError(
                f"{handshake.busy} is TRUE on {io.endpoint}: a path is still running"
            )
        yield _write(handshake.start, False, timeout)
        yield _write(handshake.done, False, timeout)
    items = [(f"{array}[{i}]", v) for i, v in enumerate(values, 1)]
    yield ("write_many", (items,), {"timeout": timeout})
    if handshake is not None:
        yield _write(handshake.count, len(values), timeout)
        if start:
            yield _write(handshake.start, True, timeout)
    return len(values)


def wait_path_done(
    io: Any,
    handshake: PathHandshake = PathHandshake(),
    *,
    poll: float = 0.024,
    timeout: float = 60.0,
) -> Op[float]:
    """Poll until the program reports the path finished; returns the seconds waited."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if _bool((yield _read(handshake.done, None))):
            return time.monotonic() - t0
        yield ("sleep", (poll,), {})
    raise KvpTimeoutError(
        f"path on {io.endpoint} not done after {timeout:g} s ({handshake.done} still FALSE)"
    )


def set_output(
    io: Any, index: int, value: bool, *, array: str = "OUTPUT_VARS", timeout: float | None = None
) -> Op[None]:
    """Set binary output ``index`` through the global BOOL array the SPS copies to ``$OUT``."""
    yield _write(f"{array}[{index}]", bool(value), timeout)


def set_outputs(
    io: Any,
    values: Mapping[int, bool],
    *,
    array: str = "OUTPUT_VARS",
    timeout: float | None = None,
) -> Op[None]:
    """Set several outputs in one pipelined burst."""
    items = [(f"{array}[{i}]", bool(v)) for i, v in values.items()]
    yield ("write_many", (items,), {"timeout": timeout})


def read_output(io: Any, index: int, *, timeout: float | None = None) -> Op[bool]:
    """The real output ``$OUT[index]`` (readable, though not writable over KVP)."""
    return _bool((yield _read(f"$OUT[{index}]", timeout)))


class RobotHelpers:
    """The robot helpers as coroutine methods; mixed into the asyncio Client."""

    read_joint_angles = as_async_method(read_joint_angles)
    read_pose = as_async_method(read_pose)
    read_joint_torques = as_async_method(read_joint_torques)
    write_joint_path = as_async_method(write_joint_path)
    write_cartesian_path = as_async_method(write_cartesian_path)
    wait_path_done = as_async_method(wait_path_done)
    set_output = as_async_method(set_output)
    set_outputs = as_async_method(set_outputs)
    read_output = as_async_method(read_output)
    read_snapshot = _lazy_async(_snapshot.read_snapshot)


class SyncRobotHelpers:
    """The same helpers as blocking methods; mixed into :class:`pyopenshowvar.sync.Client`."""

    read_joint_angles = as_sync_method(read_joint_angles)
    read_pose = as_sync_method(read_pose)
    read_joint_torques = as_sync_method(read_joint_torques)
    write_joint_path = as_sync_method(write_joint_path)
    write_cartesian_path = as_sync_method(write_cartesian_path)
    wait_path_done = as_sync_method(wait_path_done)
    set_output = as_sync_method(set_output)
    set_outputs = as_sync_method(set_outputs)
    read_output = as_sync_method(read_output)
    read_snapshot = _lazy_sync(_snapshot.read_snapshot)


def _real(value: KrlValue) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise KrlValueError(f"expected a REAL, got {value!r}")
    return float(value)


def _bool(text: str) -> bool:
    return bool(parse_value(text, "BOOL"))


def _partial(keys: Sequence[str], point: Sequence[float] | Any) -> Struct:
    values = [float(v) for v in point]
    if len(values) != len(keys):
        raise ValueError(f"expected {len(keys)} values ({' '.join(keys)}), got {len(values)}")
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"path point contains NaN or infinity: {values}")
    return Struct(None, dict(zip(keys, values, strict=True)))


def _members_array(value: Struct, keys: Sequence[str], name: str, endpoint: str) -> FloatArray:
    try:
        return _float_array([_real(value[k]) for k in keys])
    except (KeyError, TypeError) as exc:
        raise KrlValueError(f"{name!r} on {endpoint} lacks a member: {exc}") from exc


def _float_array(values: Sequence[float]) -> FloatArray:
    import numpy as np

    return np.asarray(values, dtype=np.float64)
