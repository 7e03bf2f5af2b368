"""`kvp web`: page load time, live update rate and jog stop latency, measured over KVP.

    .venv/bin/python bench/web_jog.py                 # 10 stops per trigger (~1 minute)
    .venv/bin/python bench/web_jog.py --quick         # 1 stop each, no browser (smoke test)
    .venv/bin/python bench/web_jog.py --plant dynamic # with the emulator's servo plant

An emulator (with the KRC's measured KVP latency, `--latency kvp`) runs the shipped KVP_JOG
program and `kvp web` serves the pad, each in its own process, over real TCP. A page (a WebSocket client, or headless Chromium when it is installed)
jogs A1 at 100 % jog override; then one of the triggers below fires at t0, while a separate
KVP client reads $AXIS_ACT back to back. The stop latency is the time from t0 to the first
reading from which A1 no longer changes (resolution: one read, about 1 ms on the emulator).

* release — the page sends "release" (the button came up);
* dropped connection — the page's TCP connection is aborted (no closing handshake);
* silent page — the keep-alives stop (a frozen tab, a dead phone): the server's 100 ms
  keep-alive timeout is part of the figure;
* silent PC — the PC stops topping up the credit (kvp web killed, KVP link down): the KRL
  program's own watchdog (5 increments) stops the robot;
* browser: release of the mouse button, and the tab being hidden, in Chromium.
"""

from __future__ import annotations

import asyncio
import json
import math
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import ROOT, EmuProcess, Row, base_parser, machine_info, median, print_rows, write_json
from pyopenshowvar_apps.web.jogplan import JogRequest, plan_jog
from pyopenshowvar_apps.web.runner import KRL_DIR

from kukavarproxy_emu import Emulator, EmulatorConfig
from pyopenshowvar import Client
from pyopenshowvar.kinematics import KR6R900SIXX

JOG = {"t": "jog", "frame": "axis", "key": "A1", "ov": 100}
#: Seconds a button is held before the trigger, and the window watched after it (--quick
#: shortens both: the smoke test only checks that the script runs).
HOLD, WATCH = 0.5, 0.5
#: "Stopped" = within this many degrees of the rest position for good (0.01 deg of A1 is about
#: 0.1 mm at the flange): the dynamic plant's encoders are noisy (2e-5 deg) and its servos
#: settle exponentially, so "never changes again" would time the noise, not the stop.
STILL = 0.01
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]  # fmt: skip


async def stop_latency(kvp: Client, trigger: Callable[[], Awaitable[None]]) -> float:
    """ms from the trigger to the first $AXIS_ACT reading from which A1 stays within
    :data:`STILL` of where it comes to rest (NaN if A1 was not moving before the trigger)."""
    before = float((await kvp.read_joint_angles())[0])
    await asyncio.sleep(0.03)
    if abs(float((await kvp.read_joint_angles())[0]) - before) < 10 * STILL:
        await trigger()
        return math.nan  # the jog did not run (refused or not yet seen): not a stop to time
    t0 = time.monotonic()
    await trigger()
    samples: list[tuple[float, float]] = []
    while time.monotonic() - t0 < WATCH:
        a1 = float((await kvp.read_joint_angles())[0])
        samples.append((time.monotonic(), a1))
    final = samples[-1][1]
    moving = [i for i, (_, a) in enumerate(samples) if abs(a - final) > STILL]
    first_still = samples[moving[-1] + 1][0] if moving else samples[0][0]
    return (first_still - t0) * 1e3


async def ws_page(web: WebProcess) -> Any:
    from websockets.asyncio.client import connect

    ws = await connect(f"ws://127.0.0.1:{web.port}/ws", max_queue=None)
    await ws.recv()  # hello
    return ws


class Holder:
    """A page holding a jog button: the press and a keep-alive every 25 ms."""

    def __init__(self, ws: Any, press: int, direction: int) -> None:
        self.ws, self.msg = ws, json.dumps({**JOG, "press": press, "dir": direction})
        self.task = asyncio.create_task(self._run())

    async def _run(self) -> None:
        while True:
            await self.ws.send(self.msg)
            await asyncio.sleep(0.025)

    async def stop(self) -> None:
        self.task.cancel()
        await asyncio.gather(self.task, return_exceptions=True)


async def ws_triggers(web: WebProcess, kvp: Client, n: int) -> dict[str, list[float]]:
    out: dict[str, list[float]] = {"release": [], "dropped connection": [], "silent page": []}
    press = 0
    for i in range(n):
        for name in out:
            ws = await ws_page(web)
            press += 1
            holder = Holder(ws, press, 1 if (i + press) % 2 else -1)
            await asyncio.sleep(HOLD)

            async def trigger(holder: Holder = holder, name: str = name) -> None:
                await holder.stop()
                if name == "release":
                    await holder.ws.send(json.dumps({"t": "release"}))
                elif name == "dropped connection":
                    holder.ws.transport.abort()

            out[name].append(await stop_latency(kvp, trigger))
            if name != "dropped connection":
                await ws.close()
            await asyncio.sleep(0.1)
    return out


async def silent_pc(kvp: Client, port: int, n: int) -> list[float]:
    """The PC stops moving JOG_UNTIL on: only the robot's own watchdog stops it."""
    runs = []
    async with Client("127.0.0.1", port, timeout=10.0) as pc:  # a loaded machine stalls
        for i in range(n):
            plan = plan_jog(JogRequest("axis", "A1", 1 if i % 2 else -1, None, 100.0), KR6R900SIXX)
            count = int(await pc.read("JOG_COUNT"))
            await pc.write_many(plan.start_writes(count + 5))
            for _ in range(int(HOLD / 0.04)):
                count = int(await pc.read("JOG_COUNT"))
                await pc.write("JOG_UNTIL", str(count + 5))
                await asyncio.sleep(0.04)

            async def trigger() -> None:  # the last top-up, then silence
                await pc.write("JOG_UNTIL", str(int(await pc.read("JOG_COUNT")) + 5))

            runs.append(await stop_latency(kvp, trigger))
            await pc.write_many(plan.stop_writes())
            await asyncio.sleep(0.1)
    return runs


async def browser_figures(web: WebProcess, kvp: Client, n: int) -> dict[str, Any] | None:
    executable = shutil.which("chromium")
    try:
        from playwright.async_api import async_playwright
    except ImportError:
        return None
    if executable is None:
        return None
    out: dict[str, Any] = {"load": [], "dom": [], "release (browser)": [], "tab hidden": []}
    async with async_playwright() as pw:
        ctx = await pw.chromium.launch_persistent_context(
            tempfile.mkdtemp(prefix="kvp-web-bench-"),
            executable_path=executable,
            args=CHROMIUM_ARGS,
            headless=True,
            viewport={"width": 1200, "height": 860},
        )
        for i in range(n):
            page = await ctx.new_page()
            await page.goto(web.page_url("127.0.0.1"))
            while await page.evaluate("window.kvpStats.firstState") is None:  # noqa: ASYNC110 - polling a browser or KVP is what a client does
                await asyncio.sleep(0.02)
            out["load"].append(await page.evaluate("window.kvpStats.firstState"))
            out["dom"].append(
                await page.evaluate(
                    "performance.getEntriesByType('navigation')[0].domContentLoadedEventEnd"
                )
            )
            for name in ("release (browser)", "tab hidden"):
                while await page.evaluate("document.querySelector('.jog').disabled"):  # noqa: ASYNC110 - polling a browser or KVP is what a client does
                    await asyncio.sleep(0.02)
                sign = "1" if i % 2 else "-1"
                await page.locator(f'.jog[data-key="A1"][data-dir="{sign}"]').hover()
                await page.mouse.down()
                await asyncio.sleep(HOLD)

                async def trigger(name: str = name, page: Any = page) -> None:
                    if name == "tab hidden":
                        await page.evaluate(
                            "Object.defineProperty(document, 'visibilityState',"
                            " {value: 'hidden', configurable: true});"
                            "document.dispatchEvent(new Event('visibilitychange'))"
                        )
                    else:
                        await page.mouse.up()

                out[name].append(await stop_latency(kvp, trigger))
                await page.mouse.up()
                await page.evaluate("delete document.visibilityState")
            await asyncio.sleep(3.0 if i == 0 else 0.1)
            if i == 0:
                out["rate"] = await page.evaluate("window.kvpStats.rate")
            await page.close()
        await ctx.close()
    return out


async def sim_stops(n: int, plant: str | None) -> list[float]:
    """The robot's side alone, in the emulator's simulated time (no load can change it): ms
    from the moment the zero increment is in the controller's variables to the first cycle
    from which the published $AXIS_ACT stays within STILL of its rest position."""
    extra: dict[str, Any] = {"plant": plant} if plant is not None else {}
    config = EmulatorConfig(
        port=0,
        program=str(KRL_DIR / "kvp_jog.src"),
        config_files=(KRL_DIR / "kvp_jog_config.dat",),
        **extra,
    )
    runs: list[float] = []
    async with Emulator(config) as emu, Client("127.0.0.1", emu.port) as pc:
        robot = emu.robot
        assert robot is not None
        samples: list[tuple[float, float]] = []
        zero_at: list[float] = []
        tick = robot.clock.callback

        def sampled_tick() -> None:  # every cycle's published $AXIS_ACT, none missed
            if not zero_at and emu.store.get("JOG_AX")["A1"] == 0.0:  # type: ignore[index]
                zero_at.append(robot.time)  # the write landed since the previous cycle
            tick()
            value = emu.store.get("$AXIS_ACT")
            samples.append((robot.time, float(value["A1"])))  # type: ignore[index]

        robot.clock.callback = sampled_tick
        await asyncio.sleep(0.1)
        for i in range(n):
            plan = plan_jog(JogRequest("axis", "A1", 1 if i % 2 else -1, None, 100.0), KR6R900SIXX)
            # A limit far ahead: a stalled loop must not end the jog before the stop is timed.
            count = int(await pc.read("JOG_COUNT"))
            await pc.write_many(plan.start_writes(count + 10_000))
            await asyncio.sleep(HOLD + 0.007 * i)  # vary the phase of the stop
            samples.clear()
            await asyncio.sleep(0.05)
            zero_at.clear()
            await pc.write(plan.target, plan.stop_writes()[0][1])
            await asyncio.sleep(0.4 / robot.clock.speed)  # 0.4 s of simulated time, or more
            await pc.write_many(plan.stop_writes())
            t_zero = zero_at[0]
            before = [a for t, a in samples if t <= t_zero + 1e-9]
            if (
                len(before) < 2
                or abs(before[-1] - before[-2]) < 0.9 * plan.speed * robot.kernel.ipo
            ):
                runs.append(math.nan)  # not cruising when the stop landed: not this measurement
                continue
            final = samples[-1][1]
            moving = [t for t, a in samples if abs(a - final) > STILL]
            # the first cycle that reads still is one IPO after the last one that moved
            runs.append(((moving[-1] + robot.kernel.ipo) - t_zero) * 1e3 if moving else 0.0)
    return runs


class WebProcess:
    """``kvp --port PORT web --http-port 0`` in a subprocess (the PC, on its own core)."""

    def __init__(self, kvp_port: int) -> None:
        self.proc = subprocess.Popen(
            [str(Path(sys.executable).with_name("kvp")), "--port", str(kvp_port), "web",
             "--http-port", "0"],
            stdout=subprocess.PIPE, text=True, cwd=ROOT,
        )  # fmt: skip
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline().strip()
        if not line.startswith("serving on http://"):
            self.proc.kill()
            raise RuntimeError(f"kvp web did not start: {line!r}")
        self.url = line.removeprefix("serving on ")
        self.port = int(self.url.rstrip("/").rpartition(":")[2])

    def page_url(self, host: str = "127.0.0.1") -> str:
        return self.url

    def close(self) -> None:
        self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


async def jog_ready(kvp: Client, web: WebProcess) -> None:
    """Until KVP_JOG runs and the pad has seen it (a press is refused before that)."""
    while await kvp.read("$PRO_STATE1") != "#P_ACTIVE":  # noqa: ASYNC110 - polling KVP
        await asyncio.sleep(0.05)
    ws = await ws_page(web)
    while True:
        state = json.loads(await ws.recv())
        # a state while the link is still connecting has no program part yet
        connected = state.get("t") == "state" and state["link"]["connected"]
        if connected and state["program"]["jog_ready"] is None:
            break
    await ws.close()


async def run(n: int, quick: bool, plant: str | None) -> tuple[list[Row], dict[str, Any]]:
    args = ["--program", str(KRL_DIR / "kvp_jog.src"), "--config", str(KRL_DIR / "kvp_jog_config.dat"),
            "--latency", "kvp"]  # fmt: skip
    if plant is not None:
        args += ["--plant", plant]
    rows: list[Row] = []
    with EmuProcess(*args) as emu:
        web = WebProcess(emu.port)
        try:
            async with Client("127.0.0.1", emu.port, timeout=10.0) as kvp:
                await jog_ready(kvp, web)
                ws = await ws_triggers(web, kvp, n)
                pc = await silent_pc(kvp, emu.port, n)
                browser = None if quick else await browser_figures(web, kvp, n)
        finally:
            web.close()
    sim = await sim_stops(n if not quick else 2, plant)

    def stop_row(name: str, runs: list[float], target: float | None, note: str = "") -> Row:
        runs = [r for r in runs if not math.isnan(r)]
        if not runs:  # every try was void (the jog never ran): say so, do not fail
            return Row(f"jog stop latency after {name}", math.nan, "ms", note="no valid run")
        return Row(
            f"jog stop latency after {name} (median; max {max(runs):.0f} ms)",
            median(runs),
            "ms",
            target=("ours", "<=", target) if target is not None else None,
            note=note,
            runs=runs,
        )

    rows.append(
        stop_row(
            "the zero increment, in simulated time",
            sim,
            100.0,
            "the robot's side alone (KVP_JOG + motion + plant), unaffected by the machine's load",
        )
    )
    rows.append(stop_row("release", ws["release"], 100.0))
    rows.append(stop_row("a dropped connection", ws["dropped connection"], 100.0))
    rows.append(
        stop_row("a silent page", ws["silent page"], None, "includes the 100 ms keep-alive timeout")
    )
    rows.append(
        stop_row(
            "a silent PC", pc, None, "KVP_JOG plans at most 5 increments past the last JOG_UNTIL"
        )
    )
    extra: dict[str, Any] = {"plant": plant or "default", "repeat": n}
    if browser is not None:
        rows.append(
            Row(
                "page load: navigation to first live state (median)",
                median(browser["load"]),
                "ms",
                runs=browser["load"],
            )
        )
        rows.append(
            Row(
                "page load: DOMContentLoaded (median)",
                median(browser["dom"]),
                "ms",
                runs=browser["dom"],
            )
        )
        rows.append(
            Row(
                "live update rate in the browser",
                browser["rate"],
                "Hz",
                target=("ours", ">=", 10.0),
            )
        )
        rows.append(stop_row("mouse release in Chromium", browser["release (browser)"], 100.0))
        rows.append(stop_row("the tab being hidden in Chromium", browser["tab hidden"], 100.0))
    else:
        extra["browser"] = "skipped (no Chromium/playwright, or --quick)"
    return rows, extra


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--plant", default=None, help="emulator plant (when the emulator has one)")
    args = ap.parse_args()
    global HOLD, WATCH
    n = 1 if args.quick else (args.repeat or 10)
    if args.quick:
        HOLD, WATCH = 0.2, 0.25
    rows, extra = asyncio.run(run(n, args.quick, args.plant))
    info = machine_info()
    print(f"{info['cpu']}, {info['cores']} cores, load {info['load']}; plant {extra['plant']}")
    print_rows("kvp web", rows)
    write_json(args.json, "Web jog pad", rows, extra)


if __name__ == "__main__":
    main()
