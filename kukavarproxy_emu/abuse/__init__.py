"""The abuse toolkit: attack an emulator and watch a bystander (a stable, public testing API).

The abuse suite (``tests/abuse``), the apps' abuse tests and the soak and isolation
benchmarks check the emulator's promises under attack — bounded memory, no stalls, never a
wrong value — with these tools; docs/testing.md describes them. Nothing here asserts.

* :mod:`.process` — :class:`EmulatorProcess` (the emulator in a subprocess), :class:`PeakRss`;
* :mod:`.probe` — the bystander: :func:`run_probe`, :func:`start_probe`, :class:`ProbeResult`;
* :mod:`.abusers` — the KVP-core abusers and :class:`AbuseTally`, :data:`RUNAWAY_KRL`;
* :mod:`.modes` — abusers of ``--wire kvp9`` and C3 Bridge, and :func:`run_abuse`.
"""

from __future__ import annotations

from .abusers import (
    RUNAWAY_KRL,
    AbuseTally,
    costly_pipeline,
    garbage,
    long_names,
    mode3_flood,
    non_reader,
)
from .modes import Abuser, big_module, c3_garbage, c3_selects, in_flood, run_abuse
from .probe import Probe, ProbeResult, cpu_clock, run_probe, start_probe
from .process import EmulatorProcess, PeakRss

__all__ = [
    "RUNAWAY_KRL",
    "AbuseTally",
    "Abuser",
    "EmulatorProcess",
    "PeakRss",
    "Probe",
    "ProbeResult",
    "big_module",
    "c3_garbage",
    "c3_selects",
    "costly_pipeline",
    "cpu_clock",
    "garbage",
    "in_flood",
    "long_names",
    "mode3_flood",
    "non_reader",
    "run_abuse",
    "run_probe",
    "start_probe",
]
