"""``kvp heave`` and ``kvp platform``: the heave-compensation experiment and the platform simulator.

``kvp heave`` talks to a real robot (``--host``/``--port``, running ``heave.src``), a real
platform PLC (``--modbus``) and the accelerometer board (``--accel``); ``kvp --emulate heave``
starts the embedded emulator and platform simulator instead and measures against ground truth.
``kvp platform`` runs the platform simulator in the foreground, like the PLC it stands for.
"""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

if TYPE_CHECKING:
    from .experiment import HeavePlan

__all__ = ["heave", "platform", "register"]


def _address(text: str, default_port: int) -> tuple[str, int]:
    host, _, port = text.rpartition(":") if ":" in text else (text, "", "")
    try:
        return host or "127.0.0.1", int(port) if port else default_port
    except ValueError:
        raise typer.BadParameter(f"expected HOST[:PORT], got {text!r}") from None


def _fail(exc: BaseException) -> None:
    from pyopenshowvar import KvpError
    from pyopenshowvar_apps.common import (
        EXIT_CONNECTION,
        EXIT_PROTOCOL,
        EXIT_TIMEOUT,
        fail,
        fail_for,
    )

    from .master import PlatformError

    if isinstance(exc, KvpError):
        fail_for(exc)
    if isinstance(exc, TimeoutError):
        fail(EXIT_TIMEOUT, str(exc))
    if isinstance(exc, ConnectionError | OSError):
        fail(EXIT_CONNECTION, str(exc))
    if isinstance(exc, PlatformError | RuntimeError):
        fail(EXIT_PROTOCOL, str(exc))
    raise exc


def heave(
    ctx: typer.Context,
    modbus: Annotated[
        str, typer.Option(help="Platform PLC, HOST[:PORT] (Modbus TCP).")
    ] = "127.0.0.1:5020",
    accel: Annotated[
        str, typer.Option(help="Accelerometer board's serial device.")
    ] = "/dev/ttyACM0",
    attitude: Annotated[
        str,
        typer.Option(
            help="Roll/pitch from 'fused' (PLC corrected by the accelerometer), 'accel' "
            "(the thesis) or 'plc'."
        ),
    ] = "fused",
    waves: Annotated[
        str, typer.Option(help="'thesis' (largest amplitudes), 'random' (eq. 4.13 draws).")
    ] = "thesis",
    frequency: Annotated[float, typer.Option(help="Wave frequency for --waves thesis (Hz).")] = 0.1,
    seed: Annotated[int, typer.Option(help="Seed of the waves (and the simulators).")] = 19,
    periods: Annotated[int, typer.Option(help="Wave periods per phase (off, then on).")] = 2,
    duration: Annotated[
        float | None, typer.Option(help="Seconds per phase (overrides --periods).")
    ] = None,
    operator: Annotated[str, typer.Option(help="auto, gamepad, keyboard or scripted.")] = "auto",
    lead: Annotated[
        float | None, typer.Option(help="Fixed command delay (s); default: measured.")
    ] = None,
    out: Annotated[Path, typer.Option(help="Output folder (CSV, PNG).")] = Path("out/heave"),
    plots: Annotated[bool, typer.Option(help="Write the PNG plots.")] = True,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the figures as one JSON object.")
    ] = False,
    sweep: Annotated[
        bool, typer.Option(help="Find the breakdown frequency (embedded only).")
    ] = False,
) -> None:
    """Heave compensation on the wave platform (thesis §4.2.3): waves, compensation off then on."""
    from pyopenshowvar_apps.common import EXIT_USAGE, Opts, fail

    from .operator import ScriptedOperator

    # --emulate: our own embedded set-up (the emulator running heave.src in its own process and
    # the platform simulator), not the generic embedded emulator
    embedded = Opts.emulate
    if sweep:
        if not embedded:
            fail(
                EXIT_USAGE, "--sweep shakes the platform up to 2 Hz: only with kvp --emulate heave"
            )
        _sweep(seed, out, as_json)
        return
    plan = _plan(attitude, waves, frequency, seed, periods, duration, lead, operator)

    def say(text: str) -> None:
        if not as_json:
            typer.echo(f"heave: {text}", err=True)

    chosen = plan.operator
    if chosen is not None and not isinstance(chosen, ScriptedOperator):
        say(f"operator: {chosen.name} (toggle compensation: space / button A, quit: q / B)")
    try:
        result = _run(plan, embedded, modbus, accel, seed, out, plots, say)
    except KeyboardInterrupt:
        raise
    except BaseException as exc:
        _fail(exc)
        return
    if as_json:
        typer.echo(json.dumps(result.as_json(), indent=1))
    else:
        _print(result)


def _plan(
    attitude: str,
    waves: str,
    frequency: float,
    seed: int,
    periods: int,
    duration: float | None,
    lead: float | None,
    operator: str,
) -> HeavePlan:
    """The experiment the options ask for (a usage error for options that do not fit)."""
    from pyopenshowvar_apps.common import EXIT_USAGE, fail

    from .control import ControlConfig
    from .estimation import ATTITUDES
    from .experiment import HeavePlan
    from .operator import select_operator, square
    from .waves import WaveGenerator

    if attitude not in ATTITUDES or waves not in ("thesis", "random") or frequency <= 0:
        fail(EXIT_USAGE, "--attitude fused|accel|plc, --waves thesis|random and --frequency > 0")
    control = ControlConfig(attitude=attitude, lead=lead)
    if waves == "thesis":
        plan = HeavePlan.thesis(seed, periods=periods, frequency=frequency, control=control)
    else:
        sea = WaveGenerator.random(seed, ramp=2.0)
        plan = HeavePlan(sea, off=30.0, on=30.0, control=control)
    if duration is not None:
        plan.off = plan.on = duration
    try:
        plan.operator = select_operator(
            operator, square(plan.waves.ramp + plan.off + plan.settle + 1.0)
        )
    except (LookupError, ValueError) as exc:
        fail(EXIT_USAGE, str(exc))
    return plan


def _run(
    plan: Any, embedded: bool, modbus: str, accel: str, seed: int, out: Path, plots: bool, say: Any
) -> Any:
    from pyopenshowvar_apps.common import Opts

    from .runner import EmbeddedRig, run_session

    if embedded:
        with EmbeddedRig(seed=seed, plant=Opts.plant) as rig:
            say(
                f"embedded emulator on {rig.kvp_address[1]}, platform PLC on {rig.modbus_address[1]}"
            )
            return rig.run(plan, out_dir=out, plots=plots, on_phase=say)
    return asyncio.run(
        run_session(
            plan,
            kvp_address=(Opts.host, Opts.port),
            modbus_address=_address(modbus, 5020),
            accel_port=accel,
            out_dir=out,
            plots=plots,
            timeout=Opts.timeout,
            on_phase=say,
        )
    )


def _print(result: Any) -> None:
    from rich.console import Console
    from rich.table import Table

    m = result.metrics
    table = Table(title=f"World motion of the end-effector ({result.info['measured_by']})")
    for col in (
        "axis",
        "RMS off (mm)",
        "RMS on (mm)",
        "RMS attenuation",
        "peak off",
        "peak on",
        "peak attenuation",
    ):
        table.add_column(col, justify="right")
    for a in "xyz":
        table.add_row(
            a.upper(), f"{m[f'rms_off_mm_{a}']:.2f}", f"{m[f'rms_on_mm_{a}']:.2f}",
            f"{m[f'attenuation_rms_{a}']:.1f} %", f"{m[f'peak_off_mm_{a}']:.2f}",
            f"{m[f'peak_on_mm_{a}']:.2f}", f"{m[f'attenuation_peak_{a}']:.1f} %",
        )  # fmt: skip
    console = Console()
    console.print(table)
    console.print(
        f"control loop {m['loop_hz']:.0f} Hz (period p50 {m['loop_p50_ms']:.1f} ms, "
        f"p99 {m['loop_p99_ms']:.1f} ms), command delay {m['lead_ms']:.0f} ms"
    )
    for path in result.files:
        console.print(str(path))


def _sweep(seed: int, out: Path, as_json: bool) -> None:
    from pyopenshowvar_apps.common import Opts

    from .sweep import describe, run_sweep

    progress = None if as_json else (lambda text: typer.echo(f"sweep: {text}", err=True))
    result = run_sweep(seed=seed, out_dir=out, progress=progress, plant=Opts.plant)
    if as_json:
        typer.echo(json.dumps(describe(result), indent=1))
        return
    bd = result.breakdown_hz
    typer.echo(
        f"breakdown (heave attenuation < 50 %): {bd:.2f} Hz"
        if math.isfinite(bd)
        else "no breakdown up to the highest frequency swept"
    )
    for path in result.files:
        typer.echo(str(path))


def platform(
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="Modbus TCP port (502 needs root).")] = 5020,
    wave: Annotated[
        bool, typer.Option(help="Drives on and the PLC's own waves from the start.")
    ] = False,
    seed: Annotated[int, typer.Option(help="Seed of the waves and the sensor noise.")] = 19,
    motor_speed: Annotated[float, typer.Option(help="Joint speed limit (deg/s).")] = 90.0,
    motor_accel: Annotated[float, typer.Option(help="Joint acceleration limit (deg/s²).")] = 360.0,
    accel_noise: Annotated[float, typer.Option(help="Accelerometer noise (g, 1 σ).")] = 0.005,
    watchdog: Annotated[
        float,
        typer.Option(
            help="Master watchdog (s): the drives stop this long after the last master write,"
            " in every mode. 0 = off; only this option switches it off (the WATCHDOG register"
            " may shorten it only)."
        ),
    ] = 1.0,
) -> None:
    """Run the wave-platform simulator (PLC on Modbus TCP + accelerometer serial stream)."""
    from pyopenshowvar_apps.common import EXIT_CONNECTION, EXIT_USAGE, fail

    from .plc import MotorLimits
    from .simulator import PlatformConfig, PlatformSimulator

    try:
        config = PlatformConfig(
            host=host, port=port, seed=seed, wave=wave, accel_noise=accel_noise,
            motors=MotorLimits(motor_speed, motor_accel), watchdog=watchdog,
        )  # fmt: skip
    except ValueError as exc:
        fail(EXIT_USAGE, str(exc))

    async def main() -> None:
        async with PlatformSimulator(config) as sim:
            typer.echo(f"platform PLC on modbus://{sim.host}:{sim.port}", err=False)
            typer.echo(f"accelerometer on {sim.accel_path}", err=False)
            if wave and watchdog > 0:
                typer.echo(
                    f"waves on: they stop {watchdog:g} s after the last master write (a master"
                    " writes HEARTBEAT, or start with --watchdog 0 to run without one)"
                )
            await asyncio.Event().wait()

    try:
        asyncio.run(main())
    except OSError as exc:
        fail(EXIT_CONNECTION, f"cannot listen on {host}:{port}: {exc.strerror or exc}")


def register(app: typer.Typer) -> None:
    """Add ``heave`` and ``platform`` to the ``kvp`` app."""
    app.command("heave")(heave)
    app.command("platform")(platform)
