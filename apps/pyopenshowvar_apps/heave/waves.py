"""The wave generator of eq. 4.13: random sinusoids for heave, roll and pitch (seeded).

    signal = [A_h·sin(2πf·t + Ω), A_φ·sin(2πf·t + Ω), A_θ·sin(2πf·t + Ω)]ᵀ

with A_h ~ U[0, 150] mm, A_φ ~ U[0, 100] mm, A_θ ~ U[0, 100] mm, f ~ U[0, 0.1] Hz and
Ω ~ U[−π, π] (thesis §4.2.3.1). Two readings of the printed equation, both in docs/heave.md:

* **the amplitudes are peak to peak.** A heave of ±150 mm cannot be: a leg's whole stroke
  (eq. 4.6) is 220–480 mm, ±130 mm around the neutral height. Read as peak to peak, the ranges
  fit exactly: at their upper ends the worst corner travels ±117 mm of the ±130 mm available.
  So each row is ``(A/2)·sin(…)``.
* **each row draws its own f and Ω.** The printed rows share the symbols; one draw per row makes
  heave, roll and pitch independent, as a sea is (``coherent=True`` shares them).

Roll and pitch are given in millimetres, as corner height differences: the roll signal is
Δ(h2, h3) (so φ = arcsin(s/l), eq. 4.8) and the pitch signal is h1 − (h2+h3)/2 (so
θ = arcsin(s/(m1 + m2)), eq. 4.11).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .geometry import THESIS_PLATFORM, PlatformGeometry, PlatformPose

__all__ = ["THESIS_RANGES", "WaveComponent", "WaveGenerator"]

#: (amplitude range mm, peak to peak) per row and the frequency range (Hz), thesis §4.2.3.1.
THESIS_RANGES = {"heave": (0.0, 150.0), "roll": (0.0, 100.0), "pitch": (0.0, 100.0)}
THESIS_FREQUENCY = (0.0, 0.1)
ROWS = ("heave", "roll", "pitch")


@dataclass(frozen=True)
class WaveComponent:
    """One row of eq. 4.13: peak-to-peak amplitude (mm), frequency (Hz), phase (rad)."""

    amplitude: float
    frequency: float
    phase: float = 0.0

    def __post_init__(self) -> None:
        if not (self.amplitude >= 0 and self.frequency >= 0 and math.isfinite(self.phase)):
            raise ValueError("a wave needs amplitude >= 0, frequency >= 0 and a finite phase")

    def value(self, t: float) -> float:
        return 0.5 * self.amplitude * math.sin(2.0 * math.pi * self.frequency * t + self.phase)

    def rate(self, t: float) -> float:
        w = 2.0 * math.pi * self.frequency
        return 0.5 * self.amplitude * w * math.cos(w * t + self.phase)


@dataclass(frozen=True)
class WaveGenerator:
    """Heave, roll and pitch rows; ``ramp`` seconds of raised-cosine fade-in from t = 0."""

    heave: WaveComponent
    roll: WaveComponent
    pitch: WaveComponent
    ramp: float = 0.0
    geometry: PlatformGeometry = field(default=THESIS_PLATFORM, compare=False)

    @classmethod
    def random(
        cls,
        seed: int | None,
        *,
        coherent: bool = False,
        ramp: float = 0.0,
        geometry: PlatformGeometry = THESIS_PLATFORM,
    ) -> WaveGenerator:
        """Draw every amplitude, frequency and phase from the thesis' distributions."""
        rng = np.random.default_rng(seed)
        shared = (float(rng.uniform(*THESIS_FREQUENCY)), float(rng.uniform(-math.pi, math.pi)))
        rows = []
        for name in ROWS:
            amplitude = float(rng.uniform(*THESIS_RANGES[name]))
            f, phase = shared
            if not coherent:
                f, phase = (
                    float(rng.uniform(*THESIS_FREQUENCY)),
                    float(rng.uniform(-math.pi, math.pi)),
                )
            rows.append(WaveComponent(amplitude, f, phase))
        return cls(rows[0], rows[1], rows[2], ramp=ramp, geometry=geometry)

    @classmethod
    def thesis_max(
        cls,
        seed: int | None,
        *,
        frequency: float = THESIS_FREQUENCY[1],
        scale: float = 1.0,
        ramp: float = 0.0,
        geometry: PlatformGeometry = THESIS_PLATFORM,
    ) -> WaveGenerator:
        """The hardest sea of the thesis' ranges: every amplitude at its upper end (× ``scale``),
        every row at ``frequency``, random phases (seeded)."""
        rng = np.random.default_rng(seed)
        rows = [
            WaveComponent(
                scale * THESIS_RANGES[name][1], frequency, float(rng.uniform(-math.pi, math.pi))
            )
            for name in ROWS
        ]
        return cls(rows[0], rows[1], rows[2], ramp=ramp, geometry=geometry)

    @classmethod
    def still(cls) -> WaveGenerator:
        zero = WaveComponent(0.0, 0.0, 0.0)
        return cls(zero, zero, zero)

    def _envelope(self, t: float) -> float:
        if t <= 0.0:
            return 0.0
        if t >= self.ramp:
            return 1.0
        return 0.5 * (1.0 - math.cos(math.pi * t / self.ramp))

    def signal(self, t: float) -> tuple[float, float, float]:
        """Eq. 4.13 at time ``t`` (s): heave, roll and pitch signals in mm."""
        gain = self._envelope(t)
        return (gain * self.heave.value(t), gain * self.roll.value(t), gain * self.pitch.value(t))

    def pose(self, t: float) -> PlatformPose:
        """The platform pose the signal asks for (the PLC's set-point)."""
        s_h, s_phi, s_theta = self.signal(t)
        g = self.geometry
        phi = math.degrees(math.asin(max(-1.0, min(1.0, s_phi / g.l))))
        theta = math.degrees(math.asin(max(-1.0, min(1.0, s_theta / (g.m1 + g.m2)))))
        return PlatformPose(s_h, phi, theta)

    @property
    def periods(self) -> tuple[float, ...]:
        """The rows' periods (s), inf for a still row."""
        return tuple(
            1.0 / c.frequency if c.frequency > 0 else math.inf
            for c in (self.heave, self.roll, self.pitch)
        )

    def describe(self) -> dict[str, float]:
        out: dict[str, float] = {}
        for name in ROWS:
            c: WaveComponent = getattr(self, name)
            out[f"{name}_amplitude_mm_pp"] = c.amplitude
            out[f"{name}_frequency_hz"] = c.frequency
            out[f"{name}_phase_rad"] = c.phase
        return out
