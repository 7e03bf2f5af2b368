"""What ``kvp universal`` runs: the backend, the input device, the server, the page, the report.

Kept apart from the command-line parsing (:mod:`.cli`) so tests and benchmarks can run the same
set-up in-process. :func:`run` prints the first line (arm, backend, solver, mode, input), a
status line every second, and a closing summary (loop rate, solver times, latency figures).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import typer

from pyopenshowvar.arms import Arm
from pyopenshowvar.universal import NoClosedFormError

from .backend import ArmBackend, BackendError
from .inputs import InputDevice, InputUnavailable, ScriptedInput, circle, hold, square
from .server import ControlServer

__all__ = ["RunError", "make_device", "run", "summary"]


class RunError(RuntimeError):
    """A one-line failure with the exit code ``kvp`` ends with."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


def make_device(kind: str, *, script: str = "circle", leap: str = "figure8") -> InputDevice:
    """The input device ``kind`` (web devices are made by the page's server)."""
    if kind == "script":
        scripts: dict[str, Callable[[float], Any]] = {
            "circle": circle(), "square": square(), "hold": hold((0.5, 0.0, 0.0), until=2.0)
        }  # fmt: skip
        return ScriptedInput(scripts[script])
    if kind == "keyboard":
        from .inputs import KeyboardInput

        return KeyboardInput()
    if kind == "gamepad":
        from .gamepad import GamepadInput

        return GamepadInput()
    if kind == "leap":
        from ..casestudies import devices as dev
        from .inputs import LeapInput

        hands = {"figure8": dev.figure_eight(), "circle": dev.circle(), "step": dev.step()}
        if leap == "keyboard":
            return LeapInput(dev.KeyboardDevice())
        if leap in hands:
            return LeapInput(dev.ScriptedDevice(hands[leap], duration=math.inf))
        try:
            return LeapInput(dev.ScriptedDevice(dev.replay_csv(leap), duration=math.inf))
        except (OSError, ValueError, KeyError) as exc:
            raise RunError(2, f"--leap {leap}: not figure8, circle, step, keyboard or a CSV "
                              f"with columns t,x,y,z ({exc})") from None  # fmt: skip
    raise RunError(2, f"unknown input {kind!r}")


async def make_backend(
    arm: Arm, *, target: tuple[str, int] | None, sim: str, osc: tuple[str, int] | None,
    speed: float,
) -> tuple[ArmBackend, Any]:  # fmt: skip
    """The arm behind the server, and what else must run with it (the stand-in simulator)."""
    if target is not None:
        from .kvparm import KvpArm

        return KvpArm(arm, *target, speed_scale=speed), None
    if sim == "osc":
        from .protolink import ProtoArm

        assert osc is not None
        backend = ProtoArm(arm, *osc)
        await backend.listen()
        return backend, None
    from .sim import SimulatedArm

    try:
        return SimulatedArm(arm, engine=sim), None  # type: ignore[arg-type]
    except ValueError as exc:
        raise RunError(2, str(exc)) from None


def summary(server: ControlServer) -> list[str]:
    """Closing figures from the recorded ticks."""
    ticks = list(server.ticks)
    live = [t for t in ticks if t.alive]
    if len(ticks) < 2:
        return ["no control cycles ran"]
    dts = np.array([t.dt for t in ticks[1:]])
    solve = np.array([t.solve_ms for t in live if math.isfinite(t.solve_ms)])
    lines = [f"{len(ticks)} cycles, loop rate {1.0 / np.median(dts):.1f} Hz "
             f"(period p50 {1e3 * np.median(dts):.1f} ms, p99 {1e3 * np.percentile(dts, 99):.1f} ms)"]  # fmt: skip
    if len(solve):
        lines.append(f"solver {server.solver_name}: p50 {np.median(solve):.2f} ms, "
                     f"p99 {np.percentile(solve, 99):.2f} ms")  # fmt: skip
    return lines


async def run(
    *, arm: Arm, solver: str, input_: str, mode: str, target: tuple[str, int] | None,
    sim: str, osc: tuple[str, int] | None, standin: bool, script: str, leap: str,
    duration: float | None, rate: float, kp: float | None, kv: float | None, budget: float,
    arms: list[str], view: bool, bind: str, http_port: int, token: str | None, speed: float,
) -> None:  # fmt: skip
    backend, _ = await make_backend(arm, target=target, sim=sim, osc=osc, speed=speed)
    web_input = None
    device: InputDevice
    if input_ == "web":
        from .web import WebInput

        web_input = WebInput()
        device = web_input
    else:
        device = make_device(input_, script=script, leap=leap)
    server = ControlServer(backend, device, solver=solver, mode=mode, rate_hz=rate,
                           budget=budget, k_p=kp, k_v=kv, arms=arms)  # fmt: skip
    tasks: list[asyncio.Task[Any]] = []
    if sim == "osc" and target is None:
        from .protolink import ProtoArm, StandInSimulator

        assert isinstance(backend, ProtoArm)
        typer.echo(f"waiting for a simulator on {backend.host}:{backend.port} (ToOSC / ToAAUC)")
        if standin:
            stand = StandInSimulator(backend.host, backend.port)
            tasks.append(asyncio.create_task(stand.run(), name="stand-in"))
    try:
        await server.start()
    except InputUnavailable as exc:
        await backend.close()
        raise RunError(2, str(exc)) from None
    except NoClosedFormError as exc:
        await backend.close()
        raise RunError(2, str(exc)) from None
    except BackendError as exc:
        await backend.close()
        raise RunError(3, str(exc)) from None
    typer.echo(f"universal: {server.backend.name}, solver {server.solver_name}, {mode} mode, "
               f"input {device.name}")  # fmt: skip
    page = None
    try:
        async with contextlib.AsyncExitStack() as stack:
            if view:
                from .web import ViewServer

                try:
                    page = ViewServer(server, web_input, bind=bind, port=http_port, token=token)
                except OSError as exc:
                    raise RunError(2, f"cannot serve on {bind}:{http_port}: {exc}") from None
                await stack.enter_async_context(page)
                typer.echo(f"open {page.url}")
            typer.echo("Ctrl-C stops" + (" (or Q)" if input_ == "keyboard" else ""))
            status = asyncio.create_task(_status(server))
            try:
                await server.run(duration)
            except BackendError as exc:
                raise RunError(3, str(exc)) from None
            finally:
                status.cancel()
    finally:
        with contextlib.suppress(BackendError):
            await server.close()
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    for line in summary(server):
        typer.echo(line)


async def _status(server: ControlServer) -> None:
    while True:
        await asyncio.sleep(1.0)
        s = server.status()
        tip = " ".join(f"{v:.0f}" for v in s.get("tip", []))
        state = "moving" if s.get("alive") else "stopped (input released or silent)"
        typer.echo(f"{time.strftime('%H:%M:%S')} {s['arm']} {s['solver']} {s['mode']} "
                   f"{s['rate_hz']} Hz tip [{tip}] mm {state}"
                   + (f" solve {s['solve_ms']} ms" if s.get("solve_ms") is not None else ""))  # fmt: skip
