"""``kvp demo``: every JOpenShowVar case study against an embedded emulator, one table.

Each case study gets a fresh in-process emulator (:class:`EmulatorThread`) with the program
its KRL side needs (``cart_path`` for line following, ``ext_move_axis`` for teleoperation,
``actuator`` for the haptic loop), the ``kvp`` latency profile (so access times look like a
KRC4 over Ethernet) and the ``--speed`` factor. A fresh emulator per study means no study
sees another one's leftovers (a path flag, a wrench, a stopped program). The case studies run
through the public client exactly as against a real robot; results, CSVs and PNGs go to
``--out`` (one sub-folder per study). Studies whose module is not there yet show as
"not available" instead of failing the demo.
"""

from __future__ import annotations

import asyncio
import importlib
import inspect
import time
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console

from pyopenshowvar_apps.casestudies.common import CaseResult, output_dir, summary_table
from pyopenshowvar_apps.common import plant_choice

__all__ = ["demo", "run_demo"]


#: The plant the case studies run under (``kvp demo --plant``); the emulator's default.
PLANT = {"kind": "dynamic"}


def _with_emulator(
    program: str, speed: float, job: Callable[[Any], Any], store: Any = None
) -> CaseResult:
    """Start an emulator running ``program``, connect a client, ``await job(client)``."""
    from kukavarproxy_emu import EmulatorConfig, EmulatorThread
    from pyopenshowvar import Client

    config = EmulatorConfig(
        host="127.0.0.1",
        port=0,
        program=program,
        speed=speed,
        latency="kvp",
        discovery=False,
        plant=PLANT["kind"],
    )
    with EmulatorThread(config, store=store) as emu:

        async def main() -> CaseResult:
            async with Client("127.0.0.1", emu.port) as client:
                result: CaseResult = await job(client)
                return result

        return asyncio.run(main())


def _line_following(out: Path, speed: float, quick: bool) -> CaseResult:
    from pyopenshowvar_apps.casestudies.linefollow import (
        Table,
        camera_pose,
        parked_store,
        run_line_following,
    )
    from pyopenshowvar_apps.casestudies.lineimage import generate_line_image

    size = (320, 240) if quick else (640, 480)
    img = generate_line_image(
        out / "line.png", width=size[0], height=size[1], n_points=4 if quick else 6, seed=7
    )
    table = Table(*size)

    async def job(client: Any) -> CaseResult:
        return await run_line_following(
            client,
            img.path or out / "line.png",
            out_dir=out,
            time_scale=speed,
            duration_s=4.0 if quick else 10.0,
            ground_truth=img.centreline,
        )

    return _with_emulator("cart_path", speed, job, parked_store(camera_pose(table)))


def _optional(
    module: str, func: str, program: str, title: str
) -> Callable[[Path, float, bool], CaseResult]:
    """A runner for a case study living in another module, imported only when it runs."""

    def runner(out: Path, speed: float, quick: bool) -> CaseResult:
        try:
            fn = getattr(importlib.import_module(module), func)
        except (ImportError, AttributeError):
            return CaseResult(title, {}, {"status": "not available"})
        params = inspect.signature(fn).parameters
        kw: dict[str, Any] = {"out_dir": out, "time_scale": speed}
        if "duration" in params:
            kw["duration"] = 3.0 if quick else 10.0
        kw = {k: v for k, v in kw.items() if k in params}
        return _with_emulator(program, speed, lambda client: fn(client, **kw))

    return runner


def _heave(out: Path, speed: float, quick: bool) -> CaseResult:
    # its own embedded rig (emulator + platform simulator), always in real time
    from pyopenshowvar_apps.heave.demo import demo_case

    return demo_case(out, speed, quick, plant=PLANT["kind"])


#: (sub-folder, title, runner) in the thesis' order.
CASE_STUDIES: list[tuple[str, str, Callable[[Path, float, bool], CaseResult]]] = [
    ("linefollow", "line following", _line_following),
    (
        "teleop",
        "teleoperation",
        _optional(
            "pyopenshowvar_apps.casestudies.teleop",
            "run_teleoperation",
            "ext_move_axis",
            "teleoperation",
        ),
    ),
    (
        "haptic",
        "haptic feedback",
        _optional(
            "pyopenshowvar_apps.casestudies.haptic", "run_haptic", "actuator", "haptic feedback"
        ),
    ),
    ("heave", "heave compensation", _heave),
]


def run_demo(
    out: str | Path = "out/demo",
    *,
    speed: float = 1.0,
    quick: bool = False,
    only: list[str] | None = None,
    console: Console | None = None,
    plant: str = "dynamic",
) -> list[CaseResult]:
    """Run the case studies (``only``: sub-folder names) and print the summary table."""
    console = console or Console()
    PLANT["kind"] = plant
    console.print(f"emulated robot: {plant} plant, kvp latency profile")
    results: list[CaseResult] = []
    for key, title, runner in CASE_STUDIES:
        if only and key not in only:
            continue
        t0 = time.monotonic()
        console.print(f"[bold]{title}[/] ...")
        try:
            result = runner(output_dir(out, key), speed, quick)
        except Exception as exc:  # a failing study must not hide the others' results
            result = CaseResult(title, {}, {"status": f"failed: {exc}"[:80]})
        console.print(f"  done in {time.monotonic() - t0:.1f} s, {len(result.files)} files")
        results.append(result)
    console.print(summary_table(results, title="JOpenShowVar case studies: ours vs thesis"))
    console.print(f"files under {Path(out).resolve()}")
    return results


def demo(
    out: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("out/demo"),
    speed: Annotated[
        float, typer.Option("--speed", help="Emulator speed factor (simulated s per wall s).")
    ] = 1.0,
    quick: Annotated[
        bool, typer.Option("--quick", help="Short runs (smaller image, shorter loops), speed 4.")
    ] = False,
    only: Annotated[
        list[str] | None,
        typer.Option("--only", help="Run only these: linefollow, teleop, haptic, heave."),
    ] = None,
    plant: Annotated[
        str,
        typer.Option(
            "--plant",
            help="dynamic (rigid-body arm, servos, noise) or ideal (measured = set-point).",
            callback=plant_choice,
        ),
    ] = "dynamic",
) -> None:
    """Run every case study against an embedded emulator and print ours vs the thesis."""
    if quick and speed == 1.0:
        speed = 4.0
    run_demo(out, speed=speed, quick=quick, only=only, plant=plant)
