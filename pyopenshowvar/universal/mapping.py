"""From the input device's signal to the arm's target: position and velocity mode (eqs. 2.7, 2.8).

The universal input device sends "a vector signal with no semantic", ``s``: here three numbers
in [−1, 1] (a stick's deflection, a hand's offset from the centre of its space, a held key),
zero when the device is released. The control server reads it as

* **position mode** (eq. 2.7): ``x_ds = k_p·s + x_w`` — the device's small workspace scaled by
  ``k_p`` (mm at full deflection) and shifted to ``x_w``, the tip's position when the mode was
  entered; releasing the device (s = 0) brings the tip back to where it started;
* **velocity mode** (eq. 2.8): ``ẋ_ds = k_v·s`` — ``k_v`` is the tip speed (mm/s) at full
  deflection; releasing stops the arm, which keeps its last position.

The default scales follow the arm's size: ``k_p`` a fifth of the workspace box's largest side
(±393 mm on a KR 6, ±4.2 m on the thesis' crane), ``k_v`` a tenth of it per second.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from ..kinematics.frames import FloatArray
from .workspace import Workspace

__all__ = ["MODES", "InputMapping", "Mode"]

Mode = Literal["position", "velocity"]
MODES: tuple[Mode, ...] = ("position", "velocity")
#: Default scales as fractions of the workspace box's largest side (and per second).
KP_FRACTION = 0.2
KV_FRACTION = 0.1


@dataclass
class InputMapping:
    """Eqs. 2.7 and 2.8 for one arm: ``k_p`` (mm), ``k_v`` (mm/s), the shift ``x_w`` (mm)."""

    k_p: float
    k_v: float
    x_w: FloatArray

    @classmethod
    def for_workspace(
        cls, box: Workspace, x_w: npt.ArrayLike, *, k_p: float | None = None,
        k_v: float | None = None,
    ) -> InputMapping:  # fmt: skip
        """Scales from the arm's workspace box unless given."""
        kp = KP_FRACTION * box.scale if k_p is None else float(k_p)
        kv = KV_FRACTION * box.scale if k_v is None else float(k_v)
        if not (kp > 0 and kv > 0):
            raise ValueError(f"k_p and k_v must be > 0, got {kp}, {kv}")
        return cls(kp, kv, np.array(x_w, dtype=np.float64))

    @staticmethod
    def signal(s: npt.ArrayLike) -> FloatArray:
        """The device's vector as three finite values clipped to [−1, 1] (NaN counts as 0)."""
        arr = np.nan_to_num(np.asarray(s, dtype=np.float64).reshape(-1)[:3])
        if arr.shape != (3,):
            raise ValueError(f"an input signal has 3 components, got {arr.shape[0]}")
        return np.asarray(np.clip(arr, -1.0, 1.0))

    def position(self, s: npt.ArrayLike) -> FloatArray:
        """Eq. 2.7: the scaled, shifted desired position (mm)."""
        return np.asarray(self.k_p * self.signal(s) + self.x_w)

    def velocity(self, s: npt.ArrayLike) -> FloatArray:
        """Eq. 2.8: the scaled desired velocity (mm/s)."""
        return np.asarray(self.k_v * self.signal(s))
