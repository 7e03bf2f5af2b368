"""Set-ups for the heave experiment: the embedded simulators, or a real robot and platform.

* :class:`EmbeddedRig` — a KUKAVARPROXY emulator running ``heave.src`` with the ``kvp`` latency
  profile and a platform simulator, each on its own thread and loop, as separate as the real
  controller and PLC; the ground-truth recorder rides on the platform's PLC scans and reads the
  simulated robot's axes (:func:`robot_axes`) — the one place that looks inside the emulator.
* :func:`run_session` (:meth:`EmbeddedRig.run` on the embedded rig) — connects the clients (KVP, Modbus, accelerometer), runs the experiment,
  analyses it and writes the files.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from pathlib import Path
from typing import Any, Self

from .accel import AccelReader
from .emuproc import EmulatorProcess
from .experiment import PROGRAM, GroundTruth, HeavePlan, HeaveResult, analyse, run_heave
from .geometry import FloatArray
from .master import PlatformClient
from .plc import MotorLimits
from .plots import write_outputs
from .simulator import PlatformConfig, PlatformThread

__all__ = ["EmbeddedRig", "run_session"]


class EmbeddedRig:
    """``with EmbeddedRig() as rig:`` an emulator (robot on the platform) and a platform PLC."""

    def __init__(
        self,
        *,
        seed: int | None = 19,
        latency: str = "kvp",
        motors: MotorLimits | None = None,
        accel_noise: float = 0.005,
        mount: FloatArray | None = None,
        plant: str = "dynamic",
    ) -> None:
        self.seed, self.latency, self.mount, self.plant = seed, latency, mount, plant
        self.platform_config = PlatformConfig(
            port=0, seed=seed, motors=motors or MotorLimits(), accel_noise=accel_noise
        )
        self.emulator: Any = None
        self.platform: PlatformThread | None = None
        self.truth: GroundTruth | None = None

    def __enter__(self) -> Self:
        self.emulator = EmulatorProcess(
            program=str(PROGRAM), latency=self.latency, seed=self.seed, plant=self.plant
        ).start()
        try:
            self.platform = PlatformThread(self.platform_config).start()
            self.truth = GroundTruth(self.emulator.robot_state, self.mount)
            truth = self.truth
            self.platform.call(lambda sim: sim.on_scan.append(truth))
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        if self.platform is not None:
            self.platform.stop()
            self.platform = None
        if self.emulator is not None:
            self.emulator.stop()
            self.emulator = None

    @property
    def kvp_address(self) -> tuple[str, int]:
        return "127.0.0.1", int(self.emulator.port)

    @property
    def modbus_address(self) -> tuple[str, int]:
        assert self.platform is not None
        sim = self.platform.sim
        return sim.host, sim.port

    @property
    def accel_port(self) -> str | None:
        assert self.platform is not None
        return self.platform.sim.accel_path

    def run(
        self,
        plan: HeavePlan,
        *,
        out_dir: Path | None = None,
        plots: bool = True,
        on_phase: Callable[[str], None] | None = None,
    ) -> HeaveResult:
        """:func:`run_session` against this rig (its addresses and ground truth), on an event
        loop of its own."""
        return asyncio.run(
            run_session(
                plan,
                kvp_address=self.kvp_address,
                modbus_address=self.modbus_address,
                accel_port=self.accel_port,
                truth=self.truth,
                out_dir=out_dir,
                plots=plots,
                on_phase=on_phase,
            )
        )


async def run_session(
    plan: HeavePlan,
    *,
    kvp_address: tuple[str, int],
    modbus_address: tuple[str, int],
    accel_port: str | None,
    truth: GroundTruth | None = None,
    out_dir: Path | None = None,
    plots: bool = True,
    timeout: float = 2.0,
    on_phase: Callable[[str], None] | None = None,
) -> HeaveResult:
    """Connect, run :func:`~.experiment.run_heave`, analyse, write CSV/PNG into ``out_dir``."""
    from pyopenshowvar import Client

    accel = None
    if plan.control.attitude != "plc":
        if accel_port is None:
            raise ValueError("the accelerometer's serial port is needed (or use --attitude plc)")
        accel = await AccelReader(accel_port).open()
    try:
        async with (
            Client(*kvp_address, timeout=timeout) as kvp,
            PlatformClient(*modbus_address, timeout=timeout) as plc,
        ):
            server, phases = await run_heave(kvp, plc, accel, plan, truth=truth, on_phase=on_phase)
            result = analyse(server, phases, truth)
            if accel is not None:
                result.info["accel_lines"] = {
                    "received": accel.received,
                    "rejected": accel.rejected,
                }
            if out_dir is not None:
                write_outputs(result, server, phases, Path(out_dir), plots=plots)
            return result
    finally:
        if accel is not None:
            accel.close()
