"""Heave compensation on the embedded simulators: attenuation, control-loop rate, breakdown.

    .venv/bin/python bench/heave.py              # thesis sea, 2 wave periods per phase (~50 s)
    .venv/bin/python bench/heave.py --sweep      # + the frequency sweep (~2 min more)
    .venv/bin/python bench/heave.py --quick      # 4 s phases at 0.25 Hz (smoke test)

The same experiment as ``kvp --emulate heave``: the KUKAVARPROXY emulator (``kvp`` latency
profile) running heave.src and the platform simulator, each on its own thread, measured against
the simulators' ground truth. Real-time control: a loaded machine gives a slower KVP loop and
worse attenuation, so the machine's load average is printed with the figures.
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import Row, base_parser, machine_info, print_rows, write_json
from pyopenshowvar_apps.heave.experiment import HeavePlan
from pyopenshowvar_apps.heave.runner import EmbeddedRig
from pyopenshowvar_apps.heave.sweep import run_sweep


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--sweep", action="store_true", help="also find the breakdown frequency")
    ap.add_argument("--out", type=Path, default=None, help="write the CSV/PNG files here")
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    if args.quick:
        plan = HeavePlan.thesis(19, periods=1, frequency=0.25)
    else:
        plan = HeavePlan.thesis(19, periods=2)
    with EmbeddedRig(seed=19) as rig:
        res = rig.run(plan, out_dir=args.out, plots=args.out is not None)
    m = res.metrics
    rows = [
        Row(f"world {a.upper()} RMS attenuation", m[f"attenuation_rms_{a}"], "%",
            target=("ours", ">=", 90.0) if a == "z" else None,
            note=f"{m[f'rms_off_mm_{a}']:.1f} → {m[f'rms_on_mm_{a}']:.2f} mm")
        for a in "xyz"
    ]  # fmt: skip
    rows += [
        Row(f"world {a.upper()} peak attenuation", m[f"attenuation_peak_{a}"], "%",
            note=f"{m[f'peak_off_mm_{a}']:.1f} → {m[f'peak_on_mm_{a}']:.2f} mm")
        for a in "xyz"
    ]  # fmt: skip
    rows += [
        Row("control loop rate", m["loop_hz"], "Hz"),
        Row("control loop period p50", m["loop_p50_ms"], "ms"),
        Row("control loop period p99", m["loop_p99_ms"], "ms"),
        Row("measured command delay (lead)", m["lead_ms"], "ms"),
    ]
    extra = {"machine": machine_info(), "load_before": load0, "info": res.info}
    if args.sweep and not args.quick:
        sweep = run_sweep(out_dir=args.out, progress=lambda text: print(f"  sweep {text}"))
        rows.append(Row("breakdown frequency (heave attenuation < 50 %)", sweep.breakdown_hz, "Hz"))
        extra["sweep"] = sweep.rows
    title = f"Heave compensation, thesis sea at {plan.waves.heave.frequency:g} Hz"
    print_rows(title + f" (load average {load0:.1f} → {os.getloadavg()[0]:.1f})", rows)
    print(f"  KVP access ms: {res.info.get('kvp_access_ms', {})}")
    if not math.isfinite(m["attenuation_rms_z"]):
        sys.exit(1)
    write_json(args.json, "heave", rows, extra)


if __name__ == "__main__":
    main()
