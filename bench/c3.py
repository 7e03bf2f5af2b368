"""C3 Bridge benchmark: read-multiple against single reads, and upload-to-motion time.

The emulator runs in its own process as C3 Bridge (``--proxy c3bridge``, ideal plant) with the
``kvp`` latency profile (seeded): each CrossComm call costs a sampled service time, and a
read-multiple of N variables costs N of them (C3 Bridge reads them one after the other,
ulsu-tech/c3bridge-server#2). Figures, each the median of ``--repeat`` runs:

1. 20 variables (``$AXIS_ACT``, ``$POS_ACT``, ``$TORQUE_AXIS_ACT[1..6]``, ...) in one
   ``read_multiple`` (message #6) vs 20 serial ``read`` calls (one in flight, the usual loop)
   and vs one pipelined ``read_many``; also with latency ``none``, where only the round trips
   and the codec count;
2. upload-to-motion: ``program_upload`` (.src + .dat) → ``program_select`` → ``program_start``
   → the first change of ``$AXIS_ACT`` seen by a client polling with ``read_multiple``.

Run::

    .venv/bin/python bench/c3.py [--quick] [--repeat 5] [--json out.json]
"""

from __future__ import annotations

import asyncio
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import EmuProcess, Row, base_parser, median, print_rows, write_json

from pyopenshowvar import Client

NAMES = [
    "$AXIS_ACT",
    "$POS_ACT",
    *(f"$TORQUE_AXIS_ACT[{i}]" for i in range(1, 7)),
    *(f"$VEL_AXIS_ACT[{i}]" for i in range(1, 7)),
    "$OV_PRO",
    "$MODE_OP",
    "$PRO_STATE1",
    "$PRO_NAME1[]",
    "$STOPMESS",
    "$VEL_ACT",
]
SRC = b"""DEF BENCHMOVE()
  PTP_REL {A1 2}
  PTP_REL {A1 -2}
END
"""
DAT = b"""DEFDAT BENCHMOVE PUBLIC
  DECL GLOBAL INT BENCH_RUNS = 0
ENDDAT
"""


async def _reads(port: int, rounds: int) -> dict[str, float]:
    """Median seconds to get all NAMES: read_multiple, serial reads, pipelined read_many."""
    out: dict[str, list[float]] = {"multiple": [], "serial": [], "pipelined": []}
    async with Client("127.0.0.1", port, keepalive=None, timeout=5.0) as kvp:
        await kvp.server_info()
        for _ in range(rounds):
            t0 = time.perf_counter()
            got = await kvp.read_multiple(NAMES)
            out["multiple"].append(time.perf_counter() - t0)
            assert all(r.ok for r in got.values()), got
            t0 = time.perf_counter()
            for name in NAMES:
                await kvp.read(name)
            out["serial"].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            await kvp.read_many(NAMES)
            out["pipelined"].append(time.perf_counter() - t0)
    return {k: median(v) for k, v in out.items()}


async def _upload_to_motion(port: int, rounds: int) -> float:
    times = []
    async with Client("127.0.0.1", port, keepalive=None, timeout=5.0) as kvp:
        for k in range(rounds):
            state = await kvp.program_state()
            if state.state != "P_FREE":
                await kvp.program_cancel()
            before = (await kvp.read_multiple(["$AXIS_ACT"]))["$AXIS_ACT"].text
            t0 = time.perf_counter()
            path = await kvp.program_upload(SRC, "benchmove.src", DAT)
            await kvp.program_select(path)
            await kvp.program_start(allow_motion=True)
            while (await kvp.read_multiple(["$AXIS_ACT"]))["$AXIS_ACT"].text == before:
                if time.perf_counter() - t0 > 10:
                    raise RuntimeError("the robot did not move within 10 s")
            times.append(time.perf_counter() - t0)
            if k == rounds - 1:
                break
            for _ in range(1000):  # the program ends (~1 s) before the next round
                if (await kvp.program_state()).state == "P_END":
                    break
                await asyncio.sleep(0.01)
    return median(times)


def main() -> None:
    args = base_parser(__doc__).parse_args()
    rounds = 3 if args.quick else (args.repeat or 5) * 6
    rows: list[Row] = []
    extra: dict[str, float] = {}
    for latency in ("kvp",) if args.quick else ("kvp", "none"):
        emu_args = ["--proxy", "c3bridge", "--plant", "ideal", "--no-discovery"]
        with EmuProcess(*emu_args, "--latency", latency, "--seed", "1") as emu:
            t = asyncio.run(_reads(emu.port, rounds))
            motion = asyncio.run(_upload_to_motion(emu.port, 1 if args.quick else 7))
        n = len(NAMES)
        rows.append(
            Row(
                f"{n} variables, latency {latency}: read_multiple vs serial reads",
                t["multiple"] * 1e3,
                "ms",
                t["serial"] * 1e3,
                f"{n} serial read()",
                note=f"speed-up {t['serial'] / t['multiple']:.2f}x",
            )
        )
        rows.append(
            Row(
                f"{n} variables, latency {latency}: read_multiple vs pipelined read_many",
                t["multiple"] * 1e3,
                "ms",
                t["pipelined"] * 1e3,
                "read_many (pipelined)",
                note=f"speed-up {t['pipelined'] / t['multiple']:.2f}x",
            )
        )
        rows.append(
            Row(
                f"upload-to-motion (2 files, select, start), latency {latency}",
                motion * 1e3,
                "ms",
                note="upload .src+.dat, select, start, until $AXIS_ACT first changes",
            )
        )
        extra[f"speedup_serial_{latency}"] = t["serial"] / t["multiple"]
        extra[f"speedup_pipelined_{latency}"] = t["pipelined"] / t["multiple"]
    print_rows("C3 Bridge (emulated)", rows)
    write_json(args.json, "c3", rows, extra)


if __name__ == "__main__":
    main()
