"""The ship crane that carries the crane head (Henriksen et al. §7, Table 3, eqs. 38–48).

The D-H table is the catalogue arm ``supply_vessel_crane`` (pyopenshowvar.arms, standard
D-H, lengths in metres there, millimetres in the arms API): CO → crane foot (fixed row) →
slew β0 → boom β1 (L_1) → jib β2 (L_2) → the TAC's frame {t}. This module adds what the
paper adds on top of the table: the elbow-manipulator inverse kinematics of eqs. 42–44 and
the set-up of the compensation (where the head sits, in metres).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt

from pyopenshowvar.arms import Arm, load_arm

__all__ = ["STATIONARY", "ShipCrane"]

FloatArray = npt.NDArray[np.float64]

#: eq. 60: the crane pointing to starboard, the jib level
STATIONARY = (-math.pi / 2, math.pi / 4, -math.pi / 4)


@dataclass(frozen=True)
class ShipCrane:
    """The crane of Table 3/4: ``L0``, ``L1``, ``L2`` (m) and the foot at (L_sx, 0, −L_sz) in {b}."""

    arm_name: str = "supply_vessel_crane"

    @cached_property
    def arm(self) -> Arm:
        return load_arm(self.arm_name)

    @cached_property
    def foot(self) -> FloatArray:
        """{b} → frame 0 (the crane's foot, z up): the fixed first row, in metres."""
        t = self.arm.joints[0].origin.copy()
        t[:3, 3] /= 1000.0
        return np.asarray(t)

    @cached_property
    def lengths(self) -> tuple[float, float, float]:
        """L_0, L_1, L_2 (m), read back from the table."""
        j = self.arm.joints
        l0 = float(np.linalg.norm(j[1].origin[:3, 3])) / 1000.0
        l1 = float(np.linalg.norm(j[2].origin[:3, 3])) / 1000.0
        l2 = float(np.linalg.norm(self.arm.flange[:3, 3])) / 1000.0
        return l0, l1, l2

    def head_frame(self, beta: npt.ArrayLike = STATIONARY) -> FloatArray:
        """T_t^b (eq. 41): the TAC's frame {t} in {b}, metres; β in radians."""
        t = self.arm.fk(np.degrees(np.asarray(beta, dtype=np.float64)))
        t = t.copy()
        t[..., :3, 3] /= 1000.0
        return np.asarray(t)

    def ik(self, o_b: npt.ArrayLike, *, l2_extra: float = 0.0, elbow_up: bool = True) -> FloatArray:
        """β for the point ``o_b`` (m, in {b}) at the jib's tip plus ``l2_extra`` (eqs. 42–44).

        §8 places the TCP at x_d along the jib by "substituting L_2 with L_2 + x_d";
        ``l2_extra`` is that x_d. Elbow up (the paper's choice) takes β_2 ≤ 0.
        """
        l0, l1, l2 = self.lengths
        l2 = l2 + l2_extra
        p = np.asarray(o_b, dtype=np.float64)
        inv = np.linalg.inv(self.foot)
        x, y, z = (inv[:3, :3] @ p + inv[:3, 3]).T  # eq. 42
        delta = (x * x + y * y + (z - l0) ** 2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)  # eq. 44
        if np.any(np.abs(delta) > 1.0):
            raise ValueError(f"point {p.tolist()} is out of the crane's reach")
        s2 = -np.sqrt(1.0 - delta * delta) if elbow_up else np.sqrt(1.0 - delta * delta)
        b0 = np.arctan2(y, x)
        b2 = np.arctan2(s2, delta)
        b1 = np.arctan2(z - l0, np.hypot(x, y)) - np.arctan2(l2 * s2, l1 + l2 * np.cos(b2))
        return np.stack([b0, b1, b2], axis=-1)
