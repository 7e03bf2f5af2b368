"""Kinematics of the thesis' 3-DOF wave platform (heave, roll, pitch), §4.2.3.1, eq. 4.6–4.11.

The platform (Figure 4.21) is an equilateral top triangle (side ``l`` = 1075 mm) carried at its
corners by three slider-crank legs: a motor turns a crank ``a1`` = 150 mm, a rod ``a2`` = 330 mm
lifts the corner vertically. Frames (world = the platform's top centre at the neutral pose):

* corner 1 on the −x side at ``x = −m2`` (``m2`` = 620.7 mm, the centroid-to-vertex distance),
  corners 2 and 3 at ``x = +m1`` (``m1`` = 310.3 mm), ``y = +l/2`` and ``−l/2``;
* pose ``(z, φ, θ)``: heave ``z`` (mm, up from the neutral height ``H0``), roll ``φ`` about x and
  pitch ``θ`` about y (degrees), so the platform's transform is T_z·T_θ·T_φ (eq. 4.14);
* joint angle ``β`` of each motor in 0…125°, 125° with the crank straight up (the corner at its
  highest, as the thesis says); eq. 4.6 measures its α from the vertical: α = 125° − β.

Derivation (docs/heave.md has it in full). A body point (x, y, 0) of the top plate rises by
``−x·sinθ + y·cosθ·sinφ`` under Rot_y(θ)·Rot_x(φ), so the corner heights are

    h1 = H0 + z + m2·sinθ,   h2,3 = H0 + z − m1·sinθ ± (l/2)·cosθ·sinφ          (eq. 4.7, 4.9, 4.10)

and, inverting (the plate's centre lies on the line from corner 1 to the midpoint of 2–3):

    z = (m1·h1 + m2·(h2 + h3)/2) / (m1 + m2) − H0     (the corners' mean when m2 = 2·m1)
    θ = arcsin((h1 − (h2 + h3)/2) / (m1 + m2))                                   (eq. 4.11, corrected)
    φ = arcsin((h2 − h3) / (l·cosθ))                                              (eq. 4.8, corrected)

Eq. 4.8 as printed, arcsin(Δ)/l, takes the arcsine of a length; eq. 4.11 as printed has a
garbled numerator with the opposite sign of eq. 4.9/4.10. Like the thesis we treat the corners
as moving vertically (the universal joints absorb the few-tenths-of-a-millimetre sideways drift
of a tilted plate).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = [
    "THESIS_PLATFORM",
    "FloatArray",
    "PlatformGeometry",
    "PlatformPose",
    "UnreachablePose",
    "platform_matrix",
    "rot_x",
    "rot_y",
    "translation",
]

FloatArray = npt.NDArray[np.float64]


class UnreachablePose(ValueError):
    """A platform pose or corner height outside the legs' stroke."""


@dataclass(frozen=True)
class PlatformPose:
    """Heave ``z`` (mm above neutral), roll ``phi`` and pitch ``theta`` (degrees)."""

    z: float = 0.0
    phi: float = 0.0
    theta: float = 0.0

    def as_array(self) -> FloatArray:
        return np.array([self.z, self.phi, self.theta], dtype=np.float64)


def translation(x: float, y: float, z: float) -> FloatArray:
    t = np.eye(4)
    t[:3, 3] = (x, y, z)
    return t


def rot_x(deg: float) -> FloatArray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    t = np.eye(4)
    t[1:3, 1:3] = ((c, -s), (s, c))
    return t


def rot_y(deg: float) -> FloatArray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    t = np.eye(4)
    t[0, 0], t[0, 2], t[2, 0], t[2, 2] = c, s, -s, c
    return t


def platform_matrix(pose: PlatformPose) -> FloatArray:
    """T_z·T_θ·T_φ of eq. 4.14: the platform's top-centre frame in the world (4×4, mm)."""
    return translation(0.0, 0.0, pose.z) @ rot_y(pose.theta) @ rot_x(pose.phi)


@dataclass(frozen=True)
class PlatformGeometry:
    """Dimensions (mm) and joint range (deg) of the platform; defaults are Figure 4.21's."""

    a1: float = 150.0
    a2: float = 330.0
    l: float = 1075.0  # noqa: E741 - the thesis' name
    m1: float = 310.3
    m2: float = 620.7
    beta_max: float = 125.0

    def __post_init__(self) -> None:
        if not (0 < self.a1 < self.a2 and self.l > 0 and self.m1 > 0 and self.m2 > 0):
            raise ValueError("platform dimensions must be positive with a1 < a2")
        if not 0 < self.beta_max <= 180:
            raise ValueError("beta_max must be in (0, 180] degrees")

    # --- one leg (eq. 4.6) -------------------------------------------------------------------
    def leg_height(self, beta: npt.ArrayLike) -> FloatArray:
        """Corner height above the crank pivot for joint angle(s) ``beta`` (eq. 4.6)."""
        alpha = np.radians(self.beta_max - np.asarray(beta, dtype=np.float64))
        return np.asarray(
            self.a1 * np.cos(alpha) + np.sqrt(self.a2**2 - (self.a1 * np.sin(alpha)) ** 2),
            dtype=np.float64,
        )

    def leg_angle(self, h: npt.ArrayLike) -> FloatArray:
        """Joint angle(s) β for corner height(s) ``h`` (eq. 4.6 solved: the law of cosines)."""
        hh = np.asarray(h, dtype=np.float64)
        lo, hi = self.stroke
        if np.any(hh < lo - 1e-9) or np.any(hh > hi + 1e-9):
            raise UnreachablePose(
                f"corner height {np.round(hh, 2).tolist()} mm outside the stroke "
                f"{lo:.1f}…{hi:.1f} mm"
            )
        cos_alpha = (hh**2 + self.a1**2 - self.a2**2) / (2.0 * hh * self.a1)
        alpha = np.degrees(np.arccos(np.clip(cos_alpha, -1.0, 1.0)))
        return np.asarray(self.beta_max - alpha, dtype=np.float64)

    @property
    def stroke(self) -> tuple[float, float]:
        """Lowest and highest corner height (mm) over the joint range."""
        lo, hi = self.leg_height([0.0, self.beta_max])
        return float(lo), float(hi)

    @property
    def neutral_height(self) -> float:
        """H0: the corner height of the neutral pose, the middle of the stroke."""
        lo, hi = self.stroke
        return (lo + hi) / 2.0

    # --- the plate ---------------------------------------------------------------------------
    def corners_xy(self) -> FloatArray:
        """Horizontal positions of corners 1, 2, 3 in the platform frame, shape (3, 2)."""
        return np.array([[-self.m2, 0.0], [self.m1, self.l / 2], [self.m1, -self.l / 2]])

    def corner_heights(self, pose: PlatformPose) -> FloatArray:
        """h1, h2, h3 above the crank pivots for a pose (eq. 4.7, 4.9, 4.10 combined)."""
        st, ct = math.sin(math.radians(pose.theta)), math.cos(math.radians(pose.theta))
        sp = math.sin(math.radians(pose.phi))
        xy = self.corners_xy()
        rise = -xy[:, 0] * st + xy[:, 1] * ct * sp
        return self.neutral_height + pose.z + rise

    def pose_from_heights(self, h: npt.ArrayLike) -> PlatformPose:
        """The pose whose corners stand at ``h`` (eq. 4.8 and 4.11, corrected)."""
        h1, h2, h3 = (float(v) for v in np.asarray(h, dtype=np.float64).reshape(3))
        z = (self.m1 * h1 + self.m2 * (h2 + h3) / 2.0) / (self.m1 + self.m2)
        z -= self.neutral_height
        s_theta = (h1 - (h2 + h3) / 2.0) / (self.m1 + self.m2)
        if abs(s_theta) > 1.0:
            raise UnreachablePose(f"corner heights {h1:.1f}, {h2:.1f}, {h3:.1f} give no pitch")
        theta = math.asin(s_theta)
        s_phi = (h2 - h3) / (self.l * math.cos(theta))
        if abs(s_phi) > 1.0:
            raise UnreachablePose(f"corner heights {h1:.1f}, {h2:.1f}, {h3:.1f} give no roll")
        return PlatformPose(z, math.degrees(math.asin(s_phi)), math.degrees(theta))

    def inverse(self, pose: PlatformPose) -> FloatArray:
        """Joint angles β1..β3 (deg) for a pose; :class:`UnreachablePose` outside the stroke."""
        return self.leg_angle(self.corner_heights(pose))

    def forward(self, beta: npt.ArrayLike) -> PlatformPose:
        """The pose for joint angles β1..β3 (deg)."""
        return self.pose_from_heights(self.leg_height(beta))

    def clamp_heights(self, h: npt.ArrayLike) -> FloatArray:
        """Corner heights clipped into the stroke (what a saturating PLC does)."""
        lo, hi = self.stroke
        return np.clip(np.asarray(h, dtype=np.float64), lo, hi)


THESIS_PLATFORM = PlatformGeometry()
