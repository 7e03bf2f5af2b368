"""Where the compensation breaks down: the thesis' hardest sea at rising wave frequencies.

Each frequency is one short experiment (compensation off, then on, whole wave periods) on the
embedded simulators. The platform's motors are made stiff for the sweep (``SWEEP_MOTORS``):
the real platform's geared motors cannot shake the thesis amplitudes much above 0.35 Hz, and the
sweep is about the robot side — the KVP loop rate and the robot's axis speeds. The breakdown
frequency is where the world heave's RMS attenuation falls below 50 % (linear interpolation
between the two frequencies around it).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..casestudies.common import new_figure, save_figure, write_csv
from .control import ControlConfig
from .experiment import HeavePlan
from .plc import MotorLimits
from .runner import EmbeddedRig
from .waves import WaveGenerator

__all__ = ["DEFAULT_FREQUENCIES", "SWEEP_MOTORS", "SweepResult", "breakdown_frequency", "run_sweep"]

DEFAULT_FREQUENCIES = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0)
SWEEP_MOTORS = MotorLimits(speed=900.0, accel=30000.0)
#: Figures of each experiment kept in the sweep's table.
KEPT = ("attenuation", "rms", "loop", "lead", "axis_")


@dataclass
class SweepResult:
    rows: list[dict[str, float]] = field(default_factory=list)
    breakdown_hz: float = math.nan
    files: list[Path] = field(default_factory=list)


def breakdown_frequency(
    freqs: Sequence[float], attenuation: Sequence[float], level: float = 50.0
) -> float:
    """The first frequency where ``attenuation`` drops below ``level`` (interpolated); nan if never."""
    for i, (f, a) in enumerate(zip(freqs, attenuation, strict=True)):
        if a < level:
            if i == 0:
                return float(f)
            f0, a0 = freqs[i - 1], attenuation[i - 1]
            return float(f0 + (a0 - level) / (a0 - a) * (f - f0))
    return math.nan


def _window(frequency: float, minimum: float) -> float:
    period = 1.0 / frequency
    return period * max(1, math.ceil(minimum / period))


def run_sweep(
    frequencies: Sequence[float] = DEFAULT_FREQUENCIES,
    *,
    seed: int = 19,
    out_dir: Path | None = None,
    control: ControlConfig | None = None,
    minimum_window: float = 3.0,
    progress: Callable[[str], None] | None = None,
    plant: str = "dynamic",
) -> SweepResult:
    result = SweepResult()
    for f in frequencies:
        waves = WaveGenerator.thesis_max(seed, frequency=f, ramp=1.0)
        span = _window(f, minimum_window)
        plan = HeavePlan(waves, off=span, on=span, settle=0.5, control=control or ControlConfig())
        with EmbeddedRig(seed=seed, motors=SWEEP_MOTORS, plant=plant) as rig:
            res = rig.run(plan)
        m = res.metrics
        row = {
            "frequency_hz": f,
            **{k: m[k] for k in sorted(m) if k.startswith(KEPT)},
        }
        result.rows.append(row)
        if progress:
            progress(
                f"{f:.2f} Hz: heave attenuation {m['attenuation_rms_z']:.1f} % RMS, loop "
                f"{m['loop_hz']:.0f} Hz, command delay {m['lead_ms']:.0f} ms, axes at "
                f"{m.get('axis_speed_p99_pct', math.nan):.0f} % of a speed limit "
                f"(A{m.get('axis_speed_p99_axis', 0):.0f}), "
                f"{m.get('axis_accel_p99_pct', math.nan):.0f} % of an acceleration limit "
                f"(A{m.get('axis_accel_p99_axis', 0):.0f})"
            )
    freqs = [r["frequency_hz"] for r in result.rows]
    result.breakdown_hz = breakdown_frequency(freqs, [r["attenuation_rms_z"] for r in result.rows])
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        result.files.append(write_csv(out_dir / "sweep.csv", result.rows))
        result.files.append(_plot(result, out_dir))
    return result


def _plot(result: SweepResult, folder: Path) -> Path:
    fig, ax = new_figure(figsize=(8, 5))
    f = np.array([r["frequency_hz"] for r in result.rows])
    for a in "xyz":
        ax.plot(f, [r[f"attenuation_rms_{a}"] for r in result.rows], "o-", label=f"{a.upper()} RMS")
    ax.axhline(50.0, color="k", lw=0.8, ls="--")
    ax.axhline(90.0, color="tab:green", lw=0.8, ls=":")
    if math.isfinite(result.breakdown_hz):
        ax.axvline(
            result.breakdown_hz,
            color="tab:red",
            lw=0.8,
            label=f"breakdown {result.breakdown_hz:.2f} Hz",
        )
    ax.set_xscale("log")
    ax.set_xlabel("wave frequency (Hz)")
    ax.set_ylabel("attenuation of the world motion (%)")
    ax.set_ylim(-50, 100)
    ax.grid(True, alpha=0.3, which="both")
    ax.legend()
    ax.set_title("Heave compensation against wave frequency (thesis' largest amplitudes)")
    return save_figure(fig, folder / "sweep.png")


def describe(result: SweepResult) -> dict[str, Any]:
    return {
        "breakdown_hz": result.breakdown_hz,
        "sweep": result.rows,
        "files": [str(p) for p in result.files],
    }
