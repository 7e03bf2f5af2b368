"""The controller's settings as the motion kernel reads them from the variable store.

Axis speed and acceleration limits (``$VEL_AXIS``/``$ACC_AXIS`` as % of the model's), the
software limit switches (``$SOFTN_END``/``$SOFTP_END``), the approximation distances
(``$APO``) and the frames (``$TOOL``/``$BASE``). A follower plans a motion every cycle while
these change once in a while, so the arrays are rebuilt only when a variable's version in the
store changed. :class:`Settings` is mixed into :class:`~.kernel.MotionKernel`, like
:class:`~.publish.Publisher`; the value converters (:func:`axes_of`, :func:`xyzabc`) and the
refusal a KRC would print (:class:`MotionRefused`) are shared by planning and execution.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar, cast

import numpy as np

from pyopenshowvar.kinematics import RobotModel
from pyopenshowvar.krl import Struct

from ..store import VariableStore
from .profiles import FloatArray

__all__ = ["MotionRefused", "Settings", "axes_of", "xyzabc"]

T = TypeVar("T")


class MotionRefused(Exception):
    """A motion the controller refuses (software limit, unreachable pose); text = message."""


def xyzabc(value: object, what: str) -> FloatArray:
    if isinstance(value, Struct):
        try:
            return np.array([float(value[k]) for k in ("X", "Y", "Z", "A", "B", "C")])  # type: ignore[arg-type]
        except (KeyError, TypeError):
            raise MotionRefused(f"{what} is not a complete X, Y, Z, A, B, C value") from None
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (6,):
        raise MotionRefused(f"{what} needs 6 values")
    return arr


def axes_of(value: object, what: str = "target") -> FloatArray:
    """A1..A6 of an AXIS/E6AXIS struct (all six must be set) or a 6-sequence, as floats."""
    if isinstance(value, Struct):
        try:
            return np.array([float(value[f"A{i}"]) for i in range(1, 7)])  # type: ignore[arg-type]
        except (KeyError, TypeError):
            raise MotionRefused(f"{what} is not a complete axis value (A1..A6)") from None
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (6,) or not np.all(np.isfinite(arr)):
        raise MotionRefused(f"{what} needs 6 finite axis values")
    return arr


class Settings:
    """The store-reading half of the motion kernel (state lives in the kernel)."""

    store: VariableStore
    model: RobotModel
    _cache: dict[tuple[str, str], tuple[object, object]]

    def _cached(self, names: tuple[str, str], build: Callable[[], T]) -> T:
        """``build()`` of the variables ``names``, built again only when one of them changed
        (a follower plans a motion every cycle; these arrays change once in a while)."""
        key = (names, self.store.version(names[0]), self.store.version(names[1]))
        hit = self._cache.get(names)
        if hit is not None and hit[0] == key:
            return cast("T", hit[1])
        value = build()
        for arr in value if isinstance(value, tuple) else ():
            if isinstance(arr, np.ndarray):
                arr.setflags(write=False)  # shared between plans: nobody may change it
        self._cache[names] = (key, value)
        return value

    def _limits(self) -> tuple[FloatArray, FloatArray]:
        return self._cached(("$VEL_AXIS", "$ACC_AXIS"), self._read_limits)

    def _read_limits(self) -> tuple[FloatArray, FloatArray]:
        vel = self._percent("$VEL_AXIS")
        acc = self._percent("$ACC_AXIS")
        return self.model.max_speed * vel, self.model.max_accel * acc

    def _percent(self, name: str) -> FloatArray:
        values = self.store.get(name)
        assert isinstance(values, list)
        # 0 % would mean "never arrive": a KRC refuses it, we treat it as 1 %.
        return np.array([max(float(v), 1.0) for v in values[:6]]) / 100.0  # type: ignore[arg-type]

    def _soft_limits(self) -> tuple[FloatArray, FloatArray]:
        return self._cached(("$SOFTN_END", "$SOFTP_END"), self._read_soft_limits)

    def _read_soft_limits(self) -> tuple[FloatArray, FloatArray]:
        lo, hi = self.store.get("$SOFTN_END"), self.store.get("$SOFTP_END")
        assert isinstance(lo, list) and isinstance(hi, list)
        return np.array(lo[:6], dtype=np.float64), np.array(hi[:6], dtype=np.float64)

    def check_limits(self, q: FloatArray, what: str) -> None:
        """Raise :class:`MotionRefused` like a KRC when ``q`` is outside the software limits."""
        lo, hi = self._soft_limits()
        for i in range(6):
            if q[i] > hi[i] + 1e-9:
                raise MotionRefused(
                    f"Software limit switch +A{i + 1}: {what} A{i + 1} {q[i]:g} > {hi[i]:g}"
                )
            if q[i] < lo[i] - 1e-9:
                raise MotionRefused(
                    f"Software limit switch -A{i + 1}: {what} A{i + 1} {q[i]:g} < {lo[i]:g}"
                )

    def _apo(self) -> Struct:
        apo = self.store.get("$APO")
        assert isinstance(apo, Struct)
        return apo

    def _read_frames(self) -> tuple[FloatArray, FloatArray]:
        tool, base = self.store.get("$TOOL"), self.store.get("$BASE")
        return xyzabc(tool, "$TOOL"), xyzabc(base, "$BASE")
