"""Case studies from the JOpenShowVar thesis, re-run against pyopenshowvar and the emulator.

Each case study is a library function taking a connected :class:`pyopenshowvar.Client` and
returning a :class:`~.common.CaseResult` (metrics next to the thesis figures, plus the CSV /
PNG files it wrote). ``kvp demo`` runs them all on an embedded emulator.

* :mod:`.linefollow` (+ :mod:`.linefollow_vision`) — follow a line drawn on a table (thesis
  case study 2); :mod:`.lineimage` generates line images with their true centreline.
* :mod:`.teleop` (+ :mod:`.devices`, :mod:`.pid`) — Leap-style teleoperation (case study 3).
* :mod:`.haptic` (+ :mod:`.haptic_model`, :mod:`.haptic_io`, :mod:`.haptic_report`) — haptic
  force feedback with the app's own dynamic model (case study 4).

Submodules are not imported here so that ``import pyopenshowvar_apps.casestudies`` stays cheap
(matplotlib, scipy and scikit-image load only when a case study runs).
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
