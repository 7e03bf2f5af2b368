"""The universal control loop: rate, and end-to-end latency from the input to the arm's motion.

For each arm behind the server — the in-process simulation, the external simulator over the
protobuf link (the stand-in), and the emulated KR 6 over KVP (KVP_JOG, the emulator in its own
thread with its dynamic plant) — the server runs in real time at 50 Hz with a scripted input
that presses and releases (0.5 s held, 0.5 s released, ``--presses`` times). Per press:

* **latency** — from the first poll that sees the press to the first control cycle whose
  *measured* θ_a (the simulation's state, the simulator's ToAAUC, the robot's ``$AXIS_ACT``)
  has moved more than ``MOVED`` in the pressed direction's joint-space direction;
* **loop rate** — control cycles per second, and the cycle period's p50 / p99.

    nice -n 10 .venv/bin/python bench/universal_loop.py [--runs 3] [--presses 10]
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "apps"))

from pyopenshowvar_apps.universal.backend import ArmBackend
from pyopenshowvar_apps.universal.inputs import ScriptedInput
from pyopenshowvar_apps.universal.server import ControlServer, Tick

from pyopenshowvar.arms import load_arm

#: θ_a has moved when it left the press's start by this much (deg; 10× the emulator's noise).
MOVED = 0.02


def square_wave(period: float = 1.0) -> Any:
    return lambda t: (0.5, 0.0, 0.0) if (t % period) < period / 2 else (0.0, 0.0, 0.0)


def latencies(ticks: list[Tick]) -> list[float]:
    out = []
    for i in range(1, len(ticks)):
        if ticks[i].signal[0] > 0 and ticks[i - 1].signal[0] == 0:
            start, q0 = ticks[i].t, ticks[i].q
            for later in ticks[i + 1 :]:
                if later.signal[0] == 0:
                    break
                if np.max(np.abs(later.q - q0)) > MOVED:
                    out.append(later.t - start)
                    break
    return out


async def measure(backend: ArmBackend, presses: int, solver: str) -> dict[str, float]:
    device = ScriptedInput(square_wave(), duration=presses * 1.0)
    server = ControlServer(backend, device, solver=solver, mode="velocity", rate_hz=50.0)
    await server.start()
    try:
        await server.run(presses * 1.0 + 0.3)
    finally:
        await server.close()
    ticks = list(server.ticks)
    dts = np.array([t.dt for t in ticks[1:]])
    lat = np.array(latencies(ticks)) * 1e3
    return {
        "rate": float(1.0 / np.mean(dts)), "p50": float(np.median(dts) * 1e3),
        "p99": float(np.percentile(dts, 99) * 1e3),
        "lat50": float(np.median(lat)) if len(lat) else float("nan"),
        "lat_max": float(np.max(lat)) if len(lat) else float("nan"), "n": float(len(lat)),
    }  # fmt: skip


async def simulated(presses: int) -> dict[str, float]:
    from pyopenshowvar_apps.universal.sim import SimulatedArm

    return await measure(SimulatedArm(load_arm("knuckle_boom_crane")), presses, "closed-form")


async def protobuf(presses: int) -> dict[str, float]:
    from pyopenshowvar_apps.universal.protolink import ProtoArm, StandInSimulator

    backend = ProtoArm(load_arm("knuckle_boom_crane"))
    port = await backend.listen()
    sim = asyncio.create_task(StandInSimulator("127.0.0.1", port).run())
    try:
        return await measure(backend, presses, "closed-form")
    finally:
        await asyncio.wait_for(sim, 5.0)


async def kvp(presses: int) -> dict[str, float]:
    from pyopenshowvar_apps.universal.kvparm import KvpArm
    from pyopenshowvar_apps.web.runner import KRL_DIR

    from kukavarproxy_emu import EmulatorConfig, EmulatorThread
    from pyopenshowvar import Client

    emu = EmulatorThread(EmulatorConfig(port=0, latency="kvp", discovery=False,
                                        program=str(KRL_DIR / "kvp_jog.src"),
                                        config_files=(KRL_DIR / "kvp_jog_config.dat",))).start()  # fmt: skip
    try:
        async with Client("127.0.0.1", emu.port) as c:
            while (await c.read("$PRO_STATE1")).strip() != "#P_ACTIVE":  # noqa: ASYNC110
                await asyncio.sleep(0.05)
        return await measure(KvpArm(load_arm("kr6_r900_sixx"), "127.0.0.1", emu.port), presses,
                             "closed-form")  # fmt: skip
    finally:
        emu.stop()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--presses", type=int, default=10)
    args = p.parse_args()
    import os

    print("| arm behind the server | run | loop rate (Hz) | period p50 / p99 (ms) | "
          "input → motion p50 / max (ms) | presses | load |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for label, fn in (("simulated crane (kinematic)", simulated),
                      ("crane over protobuf (stand-in)", protobuf),
                      ("emulated KR 6 over KVP (KVP_JOG)", kvp)):  # fmt: skip
        for run in range(1, args.runs + 1):
            r = asyncio.run(fn(args.presses))
            print(f"| {label} | {run} | {r['rate']:.1f} | {r['p50']:.1f} / {r['p99']:.1f} | "
                  f"{r['lat50']:.0f} / {r['lat_max']:.0f} | {r['n']:.0f} | "
                  f"{os.getloadavg()[0]:.1f} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
