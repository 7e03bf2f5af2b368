"""The heave section of ``kvp demo``: half a wave period off, half on, at the thesis' hardest sea.

Half a period is enough for the RMS and the peak of a sine (the mean of sin² over any half period
is exactly ½, and any half period holds one crest). Runs in real time whatever the demo's
``--speed`` (the KVP latency and the platform's motors are wall-clock physics) and adds about
15 s to the demo: 1 s ramp, 5 s off, 0.5 s settle, 5 s on, start-up and plots.
"""

from __future__ import annotations

from pathlib import Path

from ..casestudies.common import CaseResult
from .experiment import HeavePlan
from .operator import ScriptedOperator, square
from .runner import EmbeddedRig

__all__ = ["demo_case"]


def demo_case(
    out: Path, speed: float = 1.0, quick: bool = False, *, plant: str = "dynamic", seed: int = 19
) -> CaseResult:
    """``kvp demo``'s heave section: the thesis' hardest sea drawn with ``seed`` (its phases;
    also the emulator's and the platform's noise), half a wave period off, half on."""
    plan = HeavePlan.thesis(seed, periods=1, ramp=1.0, settle=0.5, park=False)
    plan.off = plan.on = 0.5 / plan.waves.heave.frequency
    plan.operator = ScriptedOperator(
        square(plan.waves.ramp + plan.off + plan.settle + 0.5, leg=1.0)
    )
    with EmbeddedRig(seed=seed, plant=plant) as rig:
        res = rig.run(plan, out_dir=out)
    result = CaseResult("heave compensation")
    for a in "xyz":
        result.metrics[f"attenuation_rms_{a}_pct"] = res.metrics[f"attenuation_rms_{a}"]
    for a in "xyz":
        result.metrics[f"attenuation_peak_{a}_pct"] = res.metrics[f"attenuation_peak_{a}"]
    result.metrics["world_z_rms_on_mm"] = res.metrics["rms_on_mm_z"]
    result.metrics["loop_hz"] = res.metrics["loop_hz"]
    result.thesis["attenuation_rms_z_pct"] = "almost suppressed"
    result.files.extend(res.files)
    return result
