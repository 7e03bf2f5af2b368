"""Case studies from the JOpenShowVar thesis, re-run against pyopenshowvar and the emulator.

Each case study is a library function taking a connected :class:`pyopenshowvar.Client` and
returning a :class:`~apps.casestudies.common.CaseResult` (metrics next to the thesis figures,
plus the CSV / PNG files it wrote). ``kvp demo`` runs them all on an embedded emulator.

* :mod:`apps.casestudies.linefollow` — follow a line drawn on a table (thesis case study 2).
* :mod:`apps.casestudies.lineimage` — generator of synthetic line images with ground truth.
* ``apps.casestudies.teleop`` / ``apps.casestudies.haptic`` — teleoperation and haptic control.

Submodules are not imported here so that ``import pyopenshowvar_apps.casestudies`` stays cheap (matplotlib
and scipy load only when a case study runs).
"""

from __future__ import annotations

from pyopenshowvar_apps.casestudies.common import (
    CaseResult,
    output_dir,
    save_plot,
    summary_table,
    write_csv,
)

__all__ = ["CaseResult", "output_dir", "save_plot", "summary_table", "write_csv"]
