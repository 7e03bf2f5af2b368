"""``kvp universal``: one input device, any arm, interchangeable solvers; ``kvp universal-sim``.

::

    kvp universal --arm knuckle_boom_crane --solver pso --input gamepad --mode velocity
    kvp universal --arm adept_cobra600 --input web             # the pad's page at the URL printed
    kvp universal --arm kuka_youbot_arm --input script --duration 10
    kvp --emulate universal --arm kr6_r900_sixx --input web     # the emulator, over KVP (KVP_JOG)
    kvp universal --arm kr6_r900_sixx --kvp 192.168.1.10:7000 --input gamepad
    kvp universal --arm knuckle_boom_crane --sim osc --osc-listen 127.0.0.1:9100 --input script
    kvp universal-sim --connect 127.0.0.1:9100                  # the stand-in simulator

The first line names the arm, the backend, the solver, the mode and the input; then a status
line a second; at the end the loop's rate and the solver's times. Errors are one line, exit 2
(usage) or 1 (the arm or the device failed).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import secrets
from typing import Annotated, Any

import typer

from pyopenshowvar_apps.common import EXIT_USAGE, Opts, fail, start_embedded_emulator

__all__ = ["universal", "universal_sim"]

INPUTS = ("gamepad", "keyboard", "leap", "web", "script")
SCRIPTS = ("circle", "square", "hold")


def _hostport(text: str, what: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        fail(EXIT_USAGE, f"{what} must be HOST:PORT, got {text!r}")
    return host.strip("[]"), int(port)


def universal(
    ctx: typer.Context,
    arm: Annotated[str, typer.Option("--arm", help="Catalogue name or a .toml/.urdf file.")] = "knuckle_boom_crane",
    solver: Annotated[str, typer.Option("--solver", help="closed-form, dls, ga or pso.")] = "dls",
    input_: Annotated[str, typer.Option("--input", help="gamepad, keyboard, leap, web or script.")] = "script",
    mode: Annotated[str, typer.Option("--mode", help="position (eq. 2.7) or velocity (eq. 2.8).")] = "velocity",
    kvp: Annotated[str | None, typer.Option("--kvp", help="Drive a KUKA robot at HOST:PORT (KVP_JOG).")] = None,
    sim: Annotated[str, typer.Option("--sim", help="auto, kinematic, mujoco or osc (external, protobuf).")] = "auto",
    osc_listen: Annotated[str, typer.Option("--osc-listen", help="HOST:PORT the external simulator connects to.")] = "127.0.0.1:0",
    standin: Annotated[bool, typer.Option("--standin/--no-standin", help="With --sim osc: run the stand-in simulator in-process.")] = True,
    script: Annotated[str, typer.Option("--script", help="circle, square or hold (--input script).")] = "circle",
    leap: Annotated[str, typer.Option("--leap", help="figure8, circle, step, keyboard or a CSV (--input leap).")] = "figure8",
    duration: Annotated[float, typer.Option("--duration", help="Seconds (0: until Ctrl-C / quit).")] = 0.0,
    rate: Annotated[float, typer.Option("--rate", help="Control loop rate, Hz.")] = 50.0,
    kp: Annotated[float | None, typer.Option("--kp", help="Position scale k_p, mm at full deflection.")] = None,
    kv: Annotated[float | None, typer.Option("--kv", help="Velocity scale k_v, mm/s at full deflection.")] = None,
    budget_ms: Annotated[float, typer.Option("--budget-ms", help="Solver time budget (the thesis: 20 ms).")] = 20.0,
    arms: Annotated[str, typer.Option("--arms", help="Comma-separated arms 'next arm' cycles through.")] = "knuckle_boom_crane,adept_cobra600,kuka_youbot_arm",
    view: Annotated[bool | None, typer.Option("--view/--no-view", help="Serve the 3D view (default: with --input web).")] = None,
    bind: Annotated[str, typer.Option("--bind", help="Address of the page; beyond loopback a token is required.")] = "127.0.0.1",
    http_port: Annotated[int, typer.Option("--http-port", help="HTTP port of the page (0: a free one).")] = 8090,
    speed: Annotated[float, typer.Option("--speed", help="Over KVP: fraction of the jog speed limits, (0, 1].")] = 0.5,
) -> None:  # fmt: skip
    """The universal control architecture (thesis ch. 2.2): an input device drives any arm
    through an interchangeable solver, in position or velocity mode."""
    from pyopenshowvar.arms import ArmFileError, UnknownArmError, load_arm
    from pyopenshowvar.universal import SOLVERS

    if input_ not in INPUTS:
        fail(EXIT_USAGE, f"--input must be one of {', '.join(INPUTS)}, not {input_!r}")
    if mode not in ("position", "velocity"):
        fail(EXIT_USAGE, f"--mode must be position or velocity, not {mode!r}")
    if solver not in SOLVERS:
        fail(EXIT_USAGE, f"--solver must be one of {', '.join(SOLVERS)}, not {solver!r}")
    if sim not in ("auto", "kinematic", "mujoco", "osc"):
        fail(EXIT_USAGE, f"--sim must be auto, kinematic, mujoco or osc, not {sim!r}")
    if script not in SCRIPTS:
        fail(EXIT_USAGE, f"--script must be one of {', '.join(SCRIPTS)}, not {script!r}")
    if not (duration >= 0 and math.isfinite(duration)) or not 1 <= rate <= 500:
        fail(EXIT_USAGE, "--duration must be >= 0 and --rate 1..500 Hz")
    if not 0.0 < speed <= 1.0:
        fail(EXIT_USAGE, f"--speed must be in (0, 1], got {speed:g}")
    try:
        the_arm = load_arm(arm)
        cycle = [a.strip() for a in arms.split(",") if a.strip()]
        for name in cycle:
            load_arm(name)
    except (ArmFileError, UnknownArmError) as exc:
        fail(EXIT_USAGE, str(exc))
    target: tuple[str, int] | None = None
    if kvp is not None:
        target = _hostport(kvp, "--kvp")
    over_kvp = kvp is not None or Opts.emulate
    if over_kvp and the_arm.kuka is None:
        fail(EXIT_USAGE, f"{the_arm.key or arm}: only KUKA six-axis arms are driven over KVP")
    if kvp is None and Opts.emulate:
        from pyopenshowvar_apps.web.runner import KRL_DIR

        # the embedded emulator is the arm driven (kvp --robot, if given, wins: KVPArm then
        # refuses a robot whose $MODEL_NAME[] is not the arm's)
        Opts.robot = Opts.robot or arm
        start_embedded_emulator(ctx, program=str(KRL_DIR / "kvp_jog.src"),
                                config_files=[KRL_DIR / "kvp_jog_config.dat"])  # fmt: skip
        target = (Opts.host, Opts.port)
    token = secrets.token_urlsafe(12) if bind not in ("127.0.0.1", "localhost", "::1") else None
    settings: dict[str, Any] = dict(
        arm=the_arm, solver=solver, input_=input_, mode=mode, target=target, sim=sim,
        osc=_hostport(osc_listen, "--osc-listen") if sim == "osc" else None, standin=standin,
        script=script, leap=leap, duration=duration or None, rate=rate, kp=kp, kv=kv,
        budget=budget_ms / 1e3, arms=cycle if not over_kvp else [the_arm.key],
        view=input_ == "web" if view is None else view, bind=bind, http_port=http_port,
        token=token, speed=speed,
    )  # fmt: skip
    from .runner import RunError, run

    try:
        with contextlib.suppress(KeyboardInterrupt):
            asyncio.run(run(**settings))
    except RunError as exc:
        fail(exc.code, str(exc))


def universal_sim(
    connect: Annotated[str, typer.Option("--connect", help="HOST:PORT of kvp universal --sim osc.")] = "127.0.0.1:9100",
    idle: Annotated[float, typer.Option("--idle", help="Seconds without a message before giving up.")] = 10.0,
) -> None:  # fmt: skip
    """The stand-in external simulator: answers the thesis' ToOSC messages with ToAAUC."""
    from .protolink import ProtocolError, StandInSimulator

    host, port = _hostport(connect, "--connect")

    async def main() -> int:
        sim = StandInSimulator(host, port, idle_timeout=idle)
        try:
            await sim.run()
        except (OSError, TimeoutError, ProtocolError) as exc:
            fail(1, f"stand-in simulator: {exc or type(exc).__name__}")
        return sim.messages

    with contextlib.suppress(KeyboardInterrupt):
        typer.echo(f"stand-in simulator: {asyncio.run(main())} messages answered")
