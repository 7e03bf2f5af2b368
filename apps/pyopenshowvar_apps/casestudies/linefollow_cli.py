"""``kvp linefollow``: the thin command around :func:`~apps.casestudies.linefollow.run_line_following`.

Talks to the robot given by the global ``--host``/``--port``; with ``--emulate`` (before or
after the command name) it starts an embedded emulator running ``cart_path`` with the robot
parked at the camera pose. Heavy imports (numpy vision, matplotlib) happen only when the
command runs.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

from pyopenshowvar_apps.common import calibration_option

__all__ = ["linefollow"]


def _positive(value: float) -> float:
    from pyopenshowvar_apps.common import check_seconds

    try:
        return check_seconds(value)
    except typer.BadParameter:
        raise typer.BadParameter(f"{value:g} is not a positive number") from None


def _numbers(count: int, kind: type) -> Any:
    """typer callback: ``'x,y'`` style text of ``count`` numbers (returned unchanged)."""

    def check(text: str | None) -> str | None:
        if text is None:
            return None
        try:
            values = [kind(v) for v in text.split(",")]
        except ValueError:
            values = []
        if len(values) != count:
            what = "integers" if kind is int else "numbers"
            raise typer.BadParameter(f"{text!r} is not {count} comma-separated {what}")
        return text

    return check


def linefollow(
    image: Annotated[
        Path | None, typer.Argument(help="PNG/JPG of the line; omitted: generate one.")
    ] = None,
    start: Annotated[
        str | None,
        typer.Option(callback=_numbers(2, int), help="Start pixel 'x,y' (default: found)."),
    ] = None,
    end: Annotated[
        str | None,
        typer.Option(callback=_numbers(2, int), help="End pixel 'x,y' (default: found)."),
    ] = None,
    resolution: Annotated[
        float, typer.Option(callback=_positive, help="Path sampling step, mm.")
    ] = 2.0,
    scale: Annotated[
        float, typer.Option(callback=_positive, help="Camera scale, mm per pixel.")
    ] = 0.5,
    table: Annotated[
        str,
        typer.Option(
            callback=_numbers(4, float), help="Image centre in $BASE and its rotation: 'X,Y,Z,A'."
        ),
    ] = "520,0,300,-90",
    duration: Annotated[
        float, typer.Option(callback=_positive, help="Target time on the line, s.")
    ] = 10.0,
    cdis: Annotated[
        float, typer.Option(min=0.0, help="$APO.CDIS approximation distance, mm.")
    ] = 1.0,
    seed: Annotated[int, typer.Option(help="Seed of the generated image.")] = 0,
    out: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("out/linefollow"),
    speed: Annotated[
        float, typer.Option(callback=_positive, help="Emulator speed factor with --emulate.")
    ] = 1.0,
    calibration_error: Annotated[str | None, calibration_option()] = None,
) -> None:
    """Follow a line drawn on a table (thesis case study 2): A*, LIN path, $POS_ACT deviation."""
    import asyncio

    from rich.console import Console

    from pyopenshowvar_apps.casestudies.common import output_dir, summary_table
    from pyopenshowvar_apps.casestudies.lineimage import generate_line_image
    from pyopenshowvar_apps.common import Opts, fail_for

    folder = output_dir(out)
    truth = None
    if image is None:
        generated = generate_line_image(folder / "line.png", seed=seed)
        image, truth = folder / "line.png", generated.centreline
    pose = tuple(float(v) for v in table.split(","))
    host, port, scale_t = Opts.host, Opts.port, 1.0
    emu: Any = None
    tcp = None  # the physical TCP of the emulated robot: the executed path is measured from it
    if Opts.emulate:  # kvp [--emulate] linefollow [--emulate]: an emulator running cart_path
        emu, tcp = _emulator(image, scale, pose, speed, calibration_error)
        host, port, scale_t = "127.0.0.1", emu.port, speed

    options = dict(
        start=_pixel(start), end=_pixel(end), resolution_mm=resolution, scale_mm_per_px=scale,
        table_pose=pose, duration_s=duration, cdis_mm=cdis, time_scale=scale_t,
        ground_truth=truth, truth=tcp, out_dir=folder,
    )  # fmt: skip

    try:
        result = asyncio.run(_follow(host, port, image, options))
    except (OSError, TimeoutError, RuntimeError, ValueError) as exc:
        fail_for(exc)
    finally:
        if emu is not None:
            emu.stop()
    Console().print(summary_table([result], title="Line following: ours vs thesis"))
    for f in result.files:
        typer.echo(f)


def _emulator(
    image: Path, scale: float, pose: tuple[float, ...], speed: float, calibration_error: str | None
) -> tuple[Any, Callable[[], Any] | None]:
    """An emulator running ``cart_path`` with the robot parked above the table (its camera
    pose), and the physical TCP of its plant (None with the ideal plant)."""
    from kukavarproxy_emu import EmulatorConfig, EmulatorThread
    from pyopenshowvar_apps.casestudies.linefollow import Table, camera_pose, parked_store
    from pyopenshowvar_apps.casestudies.linefollow_vision import load_gray
    from pyopenshowvar_apps.common import Opts, calibration_seed

    h, w = load_gray(str(image)).shape
    store = parked_store(camera_pose(Table(w, h, scale, pose)))  # type: ignore[arg-type]
    config = EmulatorConfig(
        port=0, program="cart_path", speed=speed, latency="kvp", plant=Opts.plant,
        calibration_error=calibration_seed(calibration_error),
    )  # fmt: skip
    emu = EmulatorThread(config, store=store).start()
    plant = emu.emulator.robot.plant if emu.emulator.robot is not None else None
    if plant is None:
        return emu, None

    def tcp() -> Any:
        return plant.truth.tcp[:3, 3]

    return emu, tcp


async def _follow(host: str, port: int, image: Path, options: dict[str, Any]) -> Any:
    from pyopenshowvar import Client
    from pyopenshowvar_apps.casestudies.linefollow import run_line_following
    from pyopenshowvar_apps.common import Opts

    async with Client(host, port, timeout=Opts.timeout) as client:
        return await run_line_following(client, image, **options)


def _pixel(text: str | None) -> tuple[int, int] | None:
    """An 'x,y' option (already checked by its callback) as a pixel."""
    if text is None:
        return None
    x, y = (int(v) for v in text.split(","))
    return (x, y)
