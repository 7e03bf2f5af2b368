"""``kvp teleop`` and ``kvp haptic``: thin commands over :mod:`.teleop` and :mod:`.haptic`.

``--emulate`` (before or after the command name, as for every ``kvp`` command) starts an
in-process emulator running the program the case study needs (EXT_MOVE_AXIS or ACTUATOR) with
the ``kvp`` latency profile; without it the commands talk to ``--host/--port`` (a real KRC must
run the matching KRL program). ``--sim`` is the old, deprecated spelling of ``--emulate``.
"""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Annotated, Any

import typer

from pyopenshowvar_apps.common import EXIT_USAGE, calibration_option, check_seconds, fail

__all__ = ["haptic", "teleop"]


#: The deprecated ``--sim`` flag, hidden from --help; ``--emulate`` is the flag everywhere.
SimFlag = Annotated[bool, typer.Option("--sim", hidden=True, help="Deprecated: use --emulate.")]


#: ``--calibration-error`` (with --emulate).
CalibrationOpt = Annotated[str | None, calibration_option()]


def _run(
    program: str,
    sim: bool,
    job: Any,
    obstacles: tuple[Any, ...] = (),
    calibration: str | None = None,
) -> Any:
    from rich.console import Console

    from pyopenshowvar import Client, KvpError
    from pyopenshowvar_apps.casestudies.common import summary_table
    from pyopenshowvar_apps.common import Opts, calibration_seed, fail_for

    thread = None
    host, port = Opts.host, Opts.port
    if sim:
        typer.echo("kvp: --sim is deprecated, use --emulate", err=True)
    if sim or Opts.emulate:
        from kukavarproxy_emu import EmulatorConfig, EmulatorThread

        config = EmulatorConfig(
            port=0, program=program, latency="kvp", plant=Opts.plant,
            obstacles=obstacles if Opts.plant == "dynamic" else (),
            calibration_error=calibration_seed(calibration),
        )  # fmt: skip
        thread = EmulatorThread(config)
        thread.start()
        host, port = "127.0.0.1", thread.port

    async def main() -> Any:
        async with Client(host, port, timeout=Opts.timeout) as kvp:
            return await job(kvp, thread)

    try:
        result = asyncio.run(main())
    except KvpError as exc:
        fail_for(exc)
    finally:
        if thread is not None:
            thread.stop()
    Console().print(summary_table([result], title=result.name))
    for path in result.files:
        typer.echo(str(path))
    return result


def _one_of(*choices: str) -> Any:
    def check(value: str) -> str:
        if value not in choices:
            raise typer.BadParameter(f"{value!r} is not one of {', '.join(choices)}")
        return value

    return check


def teleop(
    mode: Annotated[
        str,
        typer.Option(
            callback=_one_of("position", "velocity"),
            help="position (eq. 2.7) or velocity (eq. 4.2).",
        ),
    ] = "position",
    device: Annotated[
        str, typer.Option(help="figure8, circle, step, keyboard or a CSV path.")
    ] = "figure8",
    duration: Annotated[float, typer.Option(callback=check_seconds, help="Seconds.")] = 10.0,
    program: Annotated[
        str,
        typer.Option(callback=_one_of("ext_move_axis", "follow"), help="ext_move_axis or follow."),
    ] = "ext_move_axis",
    out: Annotated[Path, typer.Option(help="Output folder.")] = Path("out"),
    sim: SimFlag = False,
    calibration_error: CalibrationOpt = None,
) -> None:
    """Case study 3: teleoperate with a hand device (custom IK + PID → MYAXIS)."""
    from pyopenshowvar_apps.casestudies import devices as dev
    from pyopenshowvar_apps.casestudies.teleop import run_teleoperation

    scripts = {"figure8": dev.figure_eight(), "circle": dev.circle(), "step": dev.step()}
    hand: dev.HandDevice
    if device == "keyboard":
        hand = dev.KeyboardDevice()
        typer.echo("arrows/WASD move, R/F up/down, space recentres, q quits", err=True)
    elif device in scripts:
        hand = dev.ScriptedDevice(scripts[device], duration=duration)
    else:
        try:
            hand = dev.ScriptedDevice(dev.replay_csv(device), duration=duration)
        except (OSError, ValueError, KeyError) as exc:
            fail(
                EXIT_USAGE,
                f"--device {device}: not figure8, circle, step, keyboard or a readable CSV "
                f"with columns t,x,y,z ({exc})",
            )
    _run(
        program,
        sim,
        lambda kvp, emu: run_teleoperation(
            kvp,
            hand,
            mode=mode,  # type: ignore[arg-type]
            duration=duration,
            out_dir=out,
            program=program,  # type: ignore[arg-type]
        ),
        calibration=calibration_error,
    )


def haptic(
    duration: Annotated[float, typer.Option(callback=check_seconds, help="Seconds.")] = 8.0,
    payload: Annotated[float, typer.Option(min=0.0, help="Held payload, kg.")] = 0.0,
    out: Annotated[Path, typer.Option(help="Output folder.")] = Path("out"),
    sim: SimFlag = False,
    calibration_error: CalibrationOpt = None,
) -> None:
    """Case study 4: haptic force feedback through MYPOS / ACTUATOR and $TORQUE_AXIS_ACT
    (with --emulate the robot pushes into a foam block 30 mm ahead)."""
    from pyopenshowvar_apps.casestudies.haptic import run_haptic

    def job(kvp: Any, emu: Any) -> Any:
        # with --emulate the payload is applied as EMU_WRENCH and the true force is the
        # plant's (contact + EMU_WRENCH); a real robot has neither: the errors are not scored
        plant = emu.emulator.robot.plant if emu is not None else None
        truth = None if plant is None else lambda: plant.truth.contact[:3] + plant.truth.wrench[:3]
        environment = "kvp" if emu is not None else None
        return run_haptic(
            kvp,
            duration=duration,
            payload_kg=payload,
            out_dir=out,
            truth=truth,
            environment=environment,  # type: ignore[arg-type]
        )

    from kukavarproxy_emu import Obstacle
    from pyopenshowvar.kinematics import KR6R900SIXX, forward

    # with --emulate, something to touch: a foam block 30 mm in front of HOME's TCP
    x, y, z = forward(KR6R900SIXX, KR6R900SIXX.home)[:3]
    block = Obstacle((x + 130.0, y, z), (100.0, 300.0, 300.0), stiffness=2.0)
    _run("actuator", sim, job, obstacles=(block,), calibration=calibration_error)
