"""N emulated KRCs in one process, for bench/gateway.py (not a public tool).

``python bench/_cell_emus.py N [--animate-hz 12] [--motion]`` starts N
:class:`~kukavarproxy_emu.Emulator` instances on ephemeral ports, prints ``ports P1 P2 ...``
and serves until stdin closes.

By default each robot's motion kernel is off and a cheap animator writes moving values into
``$AXIS_ACT``, ``$VEL_AXIS_ACT``, ``$TORQUE_AXIS_ACT`` and ``$CURR_ACT`` ``--animate-hz`` times
a second (phase-shifted per robot). The gateway reads and parses exactly the same texts as from
a moving robot, but 50 full robot simulations would need several cores of their own, which the
benchmark machine must keep for the process it measures. ``--motion`` runs the real motion
kernel and KRL interpreter instead (the ``joint_path`` program, for quiet machines with cores
to spare).
"""

from __future__ import annotations

import argparse
import asyncio
import math
import sys
import time

import numpy as np

from kukavarproxy_emu import Emulator, EmulatorConfig
from pyopenshowvar.krl import E6Axis

#: ``--snapshot``: the STRUC an SPS would fill on a real KRC (a snapshot group); the
#: animator writes its AX member like the motion variables, the rest stays constant.
SNAPSHOT_DAT = """DEFDAT $CONFIG
STRUC GWSNAP_T E6AXIS AX, INT OV, BOOL DR, BOOL AS, BOOL US, BOOL SM
DECL GWSNAP_T GW_SNAP={AX {A1 0.0, A2 -90.0, A3 90.0, A4 0.0, A5 0.0, A6 0.0, E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}, OV 100, DR TRUE, AS TRUE, US TRUE, SM FALSE}
ENDDAT
"""
SNAPSHOT_MEMBERS = {
    "$AXIS_ACT": "AX", "$OV_PRO": "OV", "$DRIVES_ON": "DR", "$ALARM_STOP": "AS",
    "$USER_SAF": "US", "$STOPMESS": "SM",
}  # fmt: skip


async def _animate(emus: list[Emulator], hz: float, snapshot: bool) -> None:
    period = 1.0 / hz
    due = time.monotonic()
    zeros = [0.0] * 6
    while True:
        t = time.monotonic()
        for i, emu in enumerate(emus):
            phase = t * 0.8 + i * 0.37
            q = [
                20 * math.sin(phase),
                -90 + 15 * math.sin(phase * 1.3),
                90 + 10 * math.cos(phase),
                30 * math.sin(phase * 0.7),
                25 * math.cos(phase),
                40 * math.sin(phase * 1.1),
            ]
            store = emu.store
            axes = E6Axis.from_numpy(np.array(q + zeros))
            store.set_system("GW_SNAP.AX" if snapshot else "$AXIS_ACT", axes)
            store.set_system("$VEL_AXIS_ACT", [10 * math.cos(phase + k) for k in range(6)] + zeros)
            store.set_system(
                "$TORQUE_AXIS_ACT", [5 * math.sin(phase + k) for k in range(6)] + zeros
            )
            store.set_system("$CURR_ACT", [3 * math.cos(phase - k) for k in range(6)] + zeros)
        due += period
        await asyncio.sleep(max(0.0, due - time.monotonic()))


async def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("robots", type=int)
    ap.add_argument("--animate-hz", type=float, default=12.0)
    ap.add_argument("--motion", action="store_true", help="real motion kernel (joint_path)")
    ap.add_argument("--snapshot", action="store_true", help="declare and animate GW_SNAP")
    args = ap.parse_args(argv)
    common = {"port": 0, "max_clients": 0, "idle_timeout": 0.0, "discovery": False}
    emus = [
        Emulator(
            EmulatorConfig(
                robot=args.motion,
                program="joint_path",
                dat_text=SNAPSHOT_DAT if args.snapshot else None,
                **common,  # type: ignore[arg-type]
            )
        )
        for _ in range(args.robots)
    ]
    for emu in emus:
        await emu.start()
    print("ports", *(emu.port for emu in emus), flush=True)
    animator = (
        None if args.motion else asyncio.create_task(_animate(emus, args.animate_hz, args.snapshot))
    )
    if animator is not None:  # a failing animator must not pass silently as "robots at rest"
        animator.add_done_callback(lambda t: t.cancelled() or (t.exception() and sys.exit(1)))
    loop = asyncio.get_running_loop()
    await loop.run_in_executor(None, sys.stdin.read)
    if animator is not None:
        animator.cancel()
    for emu in emus:
        await emu.close()


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1:]))
