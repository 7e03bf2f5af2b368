"""Case study 4: haptic force feedback with the KRC kinematics (thesis §4.2.2.2, Figure 4.19).

A simulated 3-DOF haptic device (an omega.7 stand-in: handle position in, force out) is held by
an operator modelled as a spring-damper pulling the handle towards where the hand wants to go.
The handle's offset from its centre sets the *direction* of motion: the robot follows through
MYPOS and the ACTUATOR program (Algorithm 4.12, ``LOOP PTP_REL MYPOS C_PTP``). The force the
robot meets is estimated from its motor torques and rendered on the handle, so the operator
feels the environment push back.

**The estimate** is the app's own (:mod:`.haptic_model`): the library's gravity and point-mass
inertia driven by the measured motion, plus rotor inertia and friction that
:func:`calibrate` identifies on the robot before the run (a short free-space motion), and a
tare offset measured at rest; then Jᵥᵀ F = τ_ext (eq. 4.5). Each cycle reads one consistent
IPO cycle's speeds, torques and axes (:mod:`.haptic_io`). While the arm stands still the
estimate is the mean over the cycles since it stopped (:class:`~.haptic_model.RestAverage`).
The app limits the axis acceleration (``$ACC_AXIS``, default 20 %) as a hand-guided motion
should be gentle.

**What is scored** — against forces our estimator did not produce: a contact the arm makes with
an object in the simulation (``emu.robot.plant.truth.contact``) and ``EMU_WRENCH`` (a virtual
wall or payload the test harness applies). ``truth`` returns the true TCP force; without it on
a real robot the errors are NaN. Settled samples (the app's rest average) and moving samples
(fresh per-cycle estimates) are scored separately (:mod:`.haptic_report`). The handle, the
operator's hand and the forces the app sets up itself are in :mod:`.haptic_world`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from pyopenshowvar.kinematics import KR6R900SIXX, Load, forward, frame_to_matrix
from pyopenshowvar_apps.casestudies.common import CaseResult
from pyopenshowvar_apps.casestudies.devices import Clock
from pyopenshowvar_apps.casestudies.haptic_io import CycleReader, Reading
from pyopenshowvar_apps.casestudies.haptic_model import (
    ForceEstimator,
    JointTerms,
    NominalDynamics,
    RestAverage,
    identify,
    tare,
)
from pyopenshowvar_apps.casestudies.haptic_report import report
from pyopenshowvar_apps.casestudies.haptic_world import (
    Environment,
    HapticDevice,
    Truth,
    Wall,
    World,
    operator_script,
)

__all__ = [
    "HapticDevice",
    "Wall",
    "calibrate",
    "leave_singularity",
    "operator_script",
    "run_haptic",
]

FloatArray = npt.NDArray[np.float64]
log = logging.getLogger(__name__)
MODEL = KR6R900SIXX
#: Fewest cycles of free motion the friction identification is run on.
MIN_IDENT_CYCLES = 20


def _mypos(inc: npt.ArrayLike, b: float = 0.0) -> str:
    """MYPOS text; all six members, so no rotation is left over from an earlier write."""
    x, y, z = np.asarray(inc, float)
    return f"{{X {x:.1f}, Y {y:.1f}, Z {z:.1f}, A 0.0, B {b:.1f}, C 0.0}}"


async def leave_singularity(
    client: Any, reader: CycleReader, clock: Clock, *, a5_deg: float = 30.0, timeout: float = 10.0
) -> None:
    """Tilt the tool (MYPOS rotations about base Y at the TCP) until |A5| ≥ ``a5_deg``.

    ACTUATOR starts at HOME, where A5 = 0 is the wrist singularity: there a sideways Cartesian
    increment can only be followed by swinging A4 and A6 through ±90° or more (measured: A4
    ran to 184°, near its 185° limit, within 3 s of sideways hand motion), which is neither
    gentle nor what the operator asked for. The TCP position does not change."""
    r = await reader.read()
    if abs(r.q[4]) >= a5_deg:
        return
    await client.write("MYPOS", _mypos((0, 0, 0), b=2.0))
    deadline = clock.now() + timeout
    while abs(r.q[4]) < a5_deg and clock.now() < deadline:
        r = await reader.read()
    await client.write("MYPOS", _mypos((0, 0, 0)))
    if abs(r.q[4]) < a5_deg:
        raise RuntimeError(f"the wrist did not leave the singularity (A5 = {r.q[4]:.1f}°)")


async def _wait_still(reader: CycleReader, clock: Clock, timeout: float = 3.0) -> Reading:
    """Read until every axis speed has been zero-ish for a few readings."""
    deadline, calm = clock.now() + timeout, 0
    while True:
        r = await reader.read()
        calm = calm + 1 if float(np.max(np.abs(r.qd))) < 0.02 else 0
        if calm >= 4 or clock.now() > deadline:
            return r


async def calibrate(
    client: Any,
    reader: CycleReader,
    dyn: NominalDynamics,
    clock: Clock,
    *,
    rest_cycles: int = 30,
    amplitude_mm: float = 0.8,
    step_s: float = 0.35,
    identify_joints: bool = True,
) -> tuple[JointTerms, dict[str, float]]:
    """Tare at rest, then identify rotor inertia and friction on a free-space motion.

    The arm must touch nothing. The motion is six short MYPOS pushes (±Z, ±Y, −X then +X, so
    it ends where it began and never goes forward first) of ``amplitude_mm`` per PTP_REL —
    the speeds of the haptic run. ``identify_joints`` False: tare only."""
    await client.write("MYPOS", _mypos((0, 0, 0)))
    await _wait_still(reader, clock)
    q: list[FloatArray] = []
    tau: list[FloatArray] = []
    seen: set[str] = set()
    deadline = clock.now() + rest_cycles * 0.05
    while len(tau) < rest_cycles and clock.now() < deadline:
        r = await reader.read()
        if r.tau_text not in seen:
            seen.add(r.tau_text)
            q.append(r.q)
            tau.append(r.tau)
    offset, noise = tare(dyn, q, tau)
    base = JointTerms(offset=offset, noise=noise)
    info = {"tare_cycles": float(len(tau))}
    if not identify_joints:
        return base, info
    motions, torques = [], []
    a = amplitude_mm
    for inc in ((0, 0, a), (0, 0, -a), (0, a, 0), (0, -a, 0), (-a, 0, 0), (a, 0, 0)):
        await client.write("MYPOS", _mypos(inc))
        end = clock.now() + step_s
        while clock.now() < end:
            r = await reader.read()
            if r.motion is not None:
                motions.append(r.motion)
                torques.append(r.tau)
    await client.write("MYPOS", _mypos((0, 0, 0)))
    info["ident_cycles"] = float(len(motions))
    await _wait_still(reader, clock)
    if len(motions) < MIN_IDENT_CYCLES:
        # too few cycles read whole (a machine too busy to read one cycle's speeds and
        # torques within 12 ms): go on with the tare alone, and say so
        log.warning("haptic: %d usable cycles, friction not identified", len(motions))
        return base, info
    terms, resid = identify(dyn, motions, torques, base)
    info.update({f"ident_resid_A{i + 1}_Nm": float(v) for i, v in enumerate(resid)})
    return terms, info


async def run_haptic(
    client: Any,
    *,
    duration: float = 8.0,
    wall: Wall | None = None,
    payload_kg: float = 0.0,
    environment: Environment | Literal["kvp"] | None = "kvp",
    truth: Truth | None = None,
    hand: Callable[[float], FloatArray] | None = None,
    out_dir: str | Path | None = None,
    time_scale: float = 1.0,
    gain: float = 0.25,
    k_inc: float = 0.02,
    dead_zone_mm: float = 5.0,
    accel_percent: float = 20.0,
    identify_joints: bool = True,
    tilt: bool = True,
    period: float = 0.006,
    plots: bool = True,
) -> CaseResult:
    """Calibrate, then run the haptic loop for ``duration`` robot seconds against ACTUATOR.

    ``wall`` (a virtual spring plane applied as EMU_WRENCH through ``environment``; default
    none) and ``payload_kg`` (a constant held mass: the TCP pushes up with m·g) are the forces
    the app sets up itself; real contact comes from the robot's world. ``environment``:
    ``"kvp"`` writes EMU_WRENCH, a callable receives the 6-vector, None applies nothing.
    ``truth`` returns the true TCP force (N, base axes) for scoring; by default the wrench the
    app applied (None without an environment: a real robot, errors NaN). ``hand``: where the
    operator's hand pulls the handle at each time (mm), default :func:`operator_script`.
    ``identify_joints`` False skips the friction/rotor identification (tare only), for
    comparison. ``tilt``: first leave HOME's wrist singularity (:func:`leave_singularity`).
    ``period`` is the shortest loop period (robot s): about two readings per IPO cycle.
    """
    clock = Clock(time_scale)
    load = Load.from_krl(await client.read_value("$LOAD"))
    tool_value = await client.read_value("$TOOL")
    tool = frame_to_matrix(*(float(tool_value[k]) for k in "XYZABC"))
    dyn = NominalDynamics(MODEL, load)
    limit = MODEL.max_accel * accel_percent / 100.0
    reader = CycleReader(client, clock, model=MODEL, accel_limit=limit)
    old_acc = await client.read("$ACC_AXIS[]")
    world = World(client, environment, truth, wall, payload_kg)
    rows: list[dict[str, float]] = []
    info: dict[str, float] = {}
    try:
        await world.release()
        if tilt:
            await leave_singularity(client, reader, clock)
        for i in range(1, 7):  # gentle from here on: calibration and hand guiding
            await client.write(f"$ACC_AXIS[{i}]", f"{accel_percent:g}")
        terms, info = await calibrate(client, reader, dyn, clock, identify_joints=identify_joints)
        est = ForceEstimator(dyn, terms, tool=tool)
        rows = await _guide(
            client,
            reader,
            est,
            world,
            tool,
            hand or operator_script(duration),
            duration=duration,
            time_scale=time_scale,
            gain=gain,
            k_inc=k_inc,
            dead_zone_mm=dead_zone_mm,
            period=period,
        )
    finally:
        await client.write("MYPOS", _mypos((0, 0, 0)))
        await world.release()
        for i, v in enumerate(str(old_acc).split()[:6], 1):
            await client.write(f"$ACC_AXIS[{i}]", v)
    info["consistent_frac"] = reader.consistent_fraction
    info["steady_frac"] = reader.steady_fraction
    info["implausible"] = float(reader.implausible)
    scored = truth is not None or environment is not None
    return report(rows, info, scored=scored, out_dir=out_dir, plots=plots)


async def _guide(
    client: Any,
    reader: CycleReader,
    est: ForceEstimator,
    world: World,
    tool: FloatArray,
    hand_at: Callable[[float], FloatArray],
    *,
    duration: float,
    time_scale: float,
    gain: float,
    k_inc: float,
    dead_zone_mm: float,
    period: float,
) -> list[dict[str, float]]:
    """The hand-guiding loop: read, estimate the force, render it on the device, jog by the
    handle's displacement; one row per reading."""
    rest = RestAverage(est)
    r0 = await reader.read()
    x0 = np.asarray(forward(MODEL, r0.q, tool=tool), float)[:3]
    await world.apply(world.wrench_at(x0))
    device, clock = HapticDevice(), Clock(time_scale)
    rows: list[dict[str, float]] = []
    rendered, last_inc, moving = np.zeros(3), np.zeros(3), False
    t_prev = 0.0
    while (t := clock.now()) < duration:
        r = await reader.read()
        f_true = world.true_force()
        x = np.asarray(forward(MODEL, r.q, tool=tool), float)[:3]
        f_rest = rest.update(r.q, r.qd, r.tau, r.tau_text, commanding=moving)
        fresh = None
        if r.motion is not None:
            fresh = est.estimate(r.motion, r.tau)
        if f_rest is not None:  # standing: the running mean since it stopped
            rendered = f_rest
        elif fresh is not None:  # a light low-pass (~2 readings) for the hand, not the score
            rendered = rendered + 0.5 * (fresh - rendered)
        p = device.step(hand_at(t), -gain * rendered, max(t - t_prev, 0.0))
        t_prev = t
        inc = _increment(p, k_inc, dead_zone_mm, moving)
        if np.any(inc != last_inc):
            await client.write("MYPOS", _mypos(inc))
            last_inc = inc
        moving = bool(np.any(inc != 0))
        await world.follow(x)
        rows.append(_row(t, x - x0, r, fresh, f_rest if rest.settled else None, f_true, p, moving))
        await clock.sleep(period - (clock.now() - t))
    return rows


#: How much farther than the dead zone the handle must go to start a robot that stands (mm):
#: in contact the handle rests where the rendered force balances the hand, at the edge of the
#: dead zone, and ~1 N of estimate noise would otherwise start and stop the robot for ever.
RESTART_MM = 6.0


def _increment(p: FloatArray, k_inc: float, dead_zone: float, moving: bool) -> FloatArray:
    """The MYPOS increment for handle offset ``p``: the direction of motion beyond the dead
    zone (:data:`RESTART_MM` farther to start a standing robot), at 0.1 mm resolution, so "no
    input" is an exact zero (and the robot really stops)."""
    norm = float(np.linalg.norm(p))
    if norm <= (dead_zone if moving else dead_zone + RESTART_MM):
        return np.zeros(3)
    return np.asarray(np.round(k_inc * p * (1.0 - dead_zone / norm), 1), float)


def _row(
    t: float,
    dx: FloatArray,
    r: Reading,
    fresh: FloatArray | None,
    settled: FloatArray | None,
    f_true: FloatArray,
    handle: FloatArray,
    moving: bool,
) -> dict[str, float]:
    nan3 = np.full(3, math.nan)
    row = {"t": t, "moving": float(moving), "consistent": float(r.consistent)}
    row.update({f"dx_{a}": v for a, v in zip("xyz", dx, strict=True)})
    row.update({f"q_A{i + 1}": v for i, v in enumerate(r.q)})
    row.update({f"tau_A{i + 1}": v for i, v in enumerate(r.tau)})
    for key, value in (
        ("F_est", nan3 if fresh is None else fresh),
        ("F_settled", nan3 if settled is None else settled),
        ("F_true", f_true),
        ("handle", handle),
    ):
        row.update({f"{key}_{a}": float(v) for a, v in zip("xyz", value, strict=True)})
    return row
