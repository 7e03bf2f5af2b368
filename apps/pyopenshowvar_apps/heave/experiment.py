"""The heave experiment: waves with the compensation off, then on; ground truth; attenuation.

:func:`run_heave` drives a running set-up — a KVP client to a robot running ``heave.src``, a
Modbus master to the platform PLC, the accelerometer stream — through the phases

    park the platform → waves ramp in (``ramp`` s) → compensation OFF (``off`` s)
    → switch ON → settle (``settle`` s) → compensation ON (``on`` s)

and measures the end-effector's world motion in both windows. With the embedded simulators
(:class:`EmbeddedRig`) the world pose of the flange is **ground truth** from the simulators' own
state, T_platform(true pose) · T_mount · FK(robot axes), sampled at every PLC scan (10 ms); it
is never computed from what the controller reads. Against real hardware there is no ground truth;
the figures then come from the control server's own x_c (eq. 4.14) and say so
(``ground_truth: false``).

Attenuation per axis, in percent: 100·(1 − RMS_on / RMS_off) and the same for the peak, where the
motion is the flange's world position minus the set-point x_s. With waves of one frequency the
windows are whole periods (the demo: half periods, which is enough for a sine's RMS and peak), so
the RMS of each window is the wave's and not a fraction of it.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .control import MODEL, ControlConfig, ControlServer
from .geometry import FloatArray, PlatformPose, platform_matrix
from .operator import OperatorInput
from .waves import WaveGenerator

__all__ = ["PROGRAM", "GroundTruth", "HeavePlan", "HeaveResult", "analyse", "run_heave"]

#: The KRL program the robot runs (its .dat beside it).
PROGRAM = Path(__file__).with_name("krl") / "heave.src"
AXES = "xyz"


@dataclass
class HeavePlan:
    """What one experiment does (durations in seconds)."""

    waves: WaveGenerator
    off: float = 20.0
    on: float = 20.0
    settle: float = 1.0
    control: ControlConfig = field(default_factory=ControlConfig)
    operator: OperatorInput | None = None
    #: Bring the platform back to neutral and switch the drives off at the end.
    park: bool = True

    @classmethod
    def thesis(
        cls, seed: int = 19, *, periods: int = 2, frequency: float = 0.1, **kw: Any
    ) -> HeavePlan:
        """The hardest thesis sea (see :meth:`WaveGenerator.thesis_max`), whole periods."""
        ramp = kw.pop("ramp", min(2.0, 0.25 / frequency))
        waves = WaveGenerator.thesis_max(seed, frequency=frequency, ramp=ramp)
        span = periods / frequency
        return cls(waves, off=span, on=span, **kw)


class GroundTruth:
    """World pose of the flange from the simulators' state, one sample per PLC scan.

    ``robot_state`` returns the simulated robot's axes (deg), its flange pose in the robot's
    base frame (4×4, mm) and its own clock (s) as the simulator knows them, at the moment of the
    call; it runs on the platform simulator's thread (every PLC scan).
    """

    def __init__(
        self,
        robot_state: Callable[[], tuple[FloatArray, FloatArray, float]],
        mount: FloatArray | None = None,
        max_rows: int = 400_000,
    ) -> None:
        self.robot_state = robot_state
        self.mount = np.eye(4) if mount is None else np.asarray(mount, float)
        self.rows: deque[tuple[float, ...]] = deque(maxlen=max_rows)
        #: The flange pose (base frame) the robot stood on at the start: the "no robot motion"
        #: reference of what the platform alone does to the flange.
        self.flange0: FloatArray | None = None

    def __call__(self, sim: Any) -> None:
        # raw numbers only (this runs on every PLC scan); the transforms run batched, later
        pose: PlatformPose = sim.pose
        q, flange, robot_time = self.robot_state()
        self.rows.append(
            (
                time.monotonic(),
                pose.z,
                pose.phi,
                pose.theta,
                *q,
                *np.asarray(flange)[:3].ravel(),
                robot_time,
            )
        )

    COLUMNS = (
        "t", "world_x", "world_y", "world_z", "still_x", "still_y", "still_z",
        "true_heave", "true_roll", "true_pitch", "q1", "q2", "q3", "q4", "q5", "q6", "robot_time",
    )  # fmt: skip

    def array(self) -> FloatArray:
        """One row per scan, :attr:`COLUMNS`: the flange's world position, where it would be had
        the robot stood still on ``flange0``, the platform's true pose and the robot's axes."""
        raw = np.array(list(self.rows), dtype=np.float64).reshape(-1, 23)
        plates = np.array([platform_matrix(PlatformPose(*r[1:4])) @ self.mount for r in raw])
        plates = plates.reshape(-1, 4, 4)
        flange_xyz1 = np.column_stack([raw[:, 10:22].reshape(-1, 3, 4)[:, :, 3], np.ones(len(raw))])
        world = np.einsum("nij,nj->ni", plates, flange_xyz1)[:, :3]
        f0 = self.flange0 if self.flange0 is not None else (
            np.vstack([raw[0, 10:22].reshape(3, 4), [0, 0, 0, 1]]) if len(raw) else np.eye(4)
        )  # fmt: skip
        still = (plates @ np.asarray(f0)[:, 3])[:, :3]
        return np.column_stack([raw[:, :1], world, still, raw[:, 1:4], raw[:, 4:10], raw[:, 22:]])


@dataclass
class HeaveResult:
    metrics: dict[str, float]
    info: dict[str, Any]
    files: list[Path] = field(default_factory=list)
    series: dict[str, FloatArray] = field(default_factory=dict, repr=False)

    def as_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            k: (round(v, 4) if math.isfinite(v) else None) for k, v in self.metrics.items()
        }
        out.update(self.info)
        out["files"] = [str(p) for p in self.files]
        return out


async def _park(platform: Any, timeout: float) -> None:
    """Neutral set-point, then wait until the platform stands there (bounded)."""
    await platform.set_pose(PlatformPose())
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        state = await platform.read_state()
        near = abs(state.heave) < 0.5 and abs(state.roll) < 0.05 and abs(state.pitch) < 0.05
        if near and not state.flag("moving"):
            return
        await asyncio.sleep(0.05)
        await platform.set_pose(PlatformPose())  # feeds the watchdog too


async def run_heave(
    kvp: Any,
    platform: Any,
    accel: Any,
    plan: HeavePlan,
    *,
    truth: GroundTruth | None = None,
    on_phase: Callable[[str], None] | None = None,
) -> tuple[ControlServer, dict[str, float]]:
    """Run the phases on a connected set-up; returns the server (its logs) and the phase times."""
    await platform.configure(watchdog=1.0)
    await platform.enable(True)
    await _park(platform, 15.0)
    server = ControlServer(
        kvp, platform, accel, operator=plan.operator, config=plan.control, waves=plan.waves
    )
    await server.start()
    if truth is not None:
        truth.flange0 = truth.robot_state()[1]
    t0 = server.wave_t0
    phases = {"t0": t0, "off_start": t0 + plan.waves.ramp}
    try:
        if on_phase:
            on_phase("waves on, compensation OFF")
        await _run_until(server, phases["off_start"] + plan.off)
        phases["switch"] = time.monotonic()
        server.set_compensation(True)
        if on_phase:
            on_phase("compensation ON")
        phases["on_start"] = phases["switch"] + plan.settle
        await _run_until(server, phases["on_start"] + plan.on)
        phases["end"] = time.monotonic()
    finally:
        await server.stop()
        if plan.park:
            with contextlib.suppress(Exception):
                await _park(platform, 10.0)
                await platform.enable(False)
    return server, phases


async def _run_until(server: ControlServer, deadline: float) -> None:
    while (left := deadline - time.monotonic()) > 0:
        if server.quit.is_set():
            if server.error is not None:
                raise server.error
            raise KeyboardInterrupt("the operator quit")
        await asyncio.sleep(min(left, 0.05))


def _interp_columns(t: FloatArray, rows: list[dict[str, float]], keys: list[str]) -> FloatArray:
    src_t = np.array([r["t"] for r in rows])
    return np.stack([np.interp(t, src_t, np.array([r[k] for r in rows])) for k in keys], axis=1)


def _axis_effort(robot_time: FloatArray, q: FloatArray) -> dict[str, float]:
    """How hard the robot's axes worked while compensating: the 99th percentile of each axis'
    speed and (0.1 s averaged) acceleration in % of its limit (§3.1), the largest over the axes,
    and which.

    Differences run on the robot's own clock, one state per interpolation cycle (the recorder
    samples faster and sees each state several times)."""
    t, first = np.unique(robot_time, return_index=True)
    if len(t) < 20:
        return {}
    q = q[first]
    speed = np.gradient(q, t, axis=0)
    # a PTP follower moves in short trapezoids, each at full acceleration: average over ~0.1 s
    # to see what the waves ask of the axis, not the micro-segments' own ramps
    kernel = np.ones(9) / 9.0
    smooth = np.stack([np.convolve(speed[:, k], kernel, mode="same") for k in range(6)], axis=1)
    accel = np.gradient(smooth, t, axis=0)[4:-4]
    out: dict[str, float] = {}
    for name, values, limit in (
        ("speed", speed, MODEL.max_speed),
        ("accel", accel, MODEL.max_accel),
    ):
        pct = 100.0 * np.percentile(np.abs(values), 99, axis=0) / np.asarray(limit, float)
        k = int(np.argmax(pct))
        out[f"axis_{name}_p99_pct"] = float(pct[k])
        out[f"axis_{name}_p99_axis"] = float(k + 1)
    return out


def analyse(
    server: ControlServer, phases: dict[str, float], truth: GroundTruth | None
) -> HeaveResult:
    """Attenuation (RMS and peak per axis), loop rate, delays; the series for CSV and plots."""
    rows = list(server.rows)
    if len(rows) < 10:
        raise RuntimeError(f"only {len(rows)} control steps ran; nothing to analyse")
    ctrl_t = np.array([r["t"] for r in rows])
    if truth is not None and len(truth.rows) > 10:
        data = truth.array()
        t = data[:, 0]
        world = data[:, 1:4]
        source = "simulators (ground truth)"
    else:
        t = ctrl_t
        world = np.array([[r[f"xc_{a}"] for a in AXES] for r in rows])
        data = None
        source = "control server estimate x_c (no ground truth)"
    x_s = _interp_columns(t, rows, [f"xs_{a}" for a in AXES])
    comp = np.interp(t, ctrl_t, np.array([r["comp"] for r in rows])) > 0.5
    err = world - x_s
    off = (t >= phases["off_start"]) & (t < phases["switch"]) & ~comp
    on = (t >= phases["on_start"]) & (t < phases["end"]) & comp
    if off.sum() < 5 or on.sum() < 5:
        raise RuntimeError("the off or on window holds no samples (run too short?)")
    m: dict[str, float] = {}
    for i, a in enumerate(AXES):
        rms_off, rms_on = (float(np.sqrt(np.mean(err[w, i] ** 2))) for w in (off, on))
        pk_off, pk_on = (float(np.max(np.abs(err[w, i]))) for w in (off, on))
        m[f"attenuation_rms_{a}"] = 100.0 * (1.0 - rms_on / rms_off) if rms_off > 0 else math.nan
        m[f"attenuation_peak_{a}"] = 100.0 * (1.0 - pk_on / pk_off) if pk_off > 0 else math.nan
        m[f"rms_off_mm_{a}"], m[f"rms_on_mm_{a}"] = rms_off, rms_on
        m[f"peak_off_mm_{a}"], m[f"peak_on_mm_{a}"] = pk_off, pk_on
    if data is not None:
        # the same windows against what the platform alone did to a robot standing still
        still = data[:, 4:7] - x_s
        for i, a in enumerate(AXES):
            d = float(np.sqrt(np.mean(still[on, i] ** 2)))
            m[f"disturbance_rms_on_mm_{a}"] = d
        m.update(_axis_effort(data[on, 16], data[on, 10:16]))
    dts = np.diff(ctrl_t[(ctrl_t >= phases["off_start"]) & (ctrl_t < phases["end"])])
    m["loop_hz"] = float(1.0 / np.mean(dts)) if dts.size else math.nan
    m["loop_p50_ms"] = float(np.percentile(dts, 50) * 1e3) if dts.size else math.nan
    m["loop_p99_ms"] = float(np.percentile(dts, 99) * 1e3) if dts.size else math.nan
    m["lead_ms"] = 1e3 * float(rows[-1]["lead"])
    stats = server.kvp.stats.snapshot().as_ms() if hasattr(server.kvp, "stats") else {}
    info: dict[str, Any] = {
        "ground_truth": data is not None,
        "measured_by": source,
        "windows_s": {
            "off": float(phases["switch"] - phases["off_start"]),
            "on": float(phases["end"] - phases["on_start"]),
        },
        "waves": server.waves.describe() if server.waves is not None else {},
        "kvp_access_ms": {k: round(float(v), 3) for k, v in dict(stats).items()} if stats else {},
        "lag_updates": server.lag.updates,
        "attitude": server.config.attitude,
    }
    series = {
        "t": t - phases["t0"],
        "world": world,
        "x_s": x_s,
        "err": err,
        "comp": comp.astype(float),
    }
    if data is not None:
        series["truth"] = data
    return HeaveResult(m, info, series=series)
