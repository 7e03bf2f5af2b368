"""Attacks on `kvp web` and `kvp platform`, each measured from outside, over loopback.

    .venv/bin/python bench/app_abuse.py            # the full attacks (~40 s)
    .venv/bin/python bench/app_abuse.py --quick    # shorter attacks (smoke test)

An emulator runs KVP_JOG, `kvp web` serves the pad and `kvp platform` simulates the wave
platform, each in its own process. Then:

* rogue page — an authorised page writes the jog program's own variables through the watch
  list (JOG_ACC 100, JOG_AX {A1 2}, JOG_UNTIL 1000000, JOG_MODE 1) and closes; a KVP client
  watches A1 for 3 s: how far and how fast it turned after the page had gone;
* slowloris — 80 sockets (from 127.0.0.2) send a request head one byte every 2 s for 12 s
  while a page (from 127.0.0.1) loads `GET /` every 0.5 s: the loads that failed, the slowest;
* crafted messages — NaN, 1e999, 2000-deep arrays, a binary frame, not JSON: how the server
  closed, and the tracebacks it printed (also for a page that closes right after connecting);
* silent master — a Modbus master switches the drives and the PLC's waves on and disconnects;
  a reader (reads do not feed the watchdog) watches how long the platform keeps moving;
* WATCHDOG = 0 and an undefined coil written by any client: accepted, or the Modbus exception.
"""

from __future__ import annotations

import asyncio
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import EmuProcess, Row, base_parser, machine_info, print_rows, write_json
from pyopenshowvar_apps.heave.abuse import PlatformProcess, silent_master, write_refusal
from pyopenshowvar_apps.web.abuse import (
    CRAFTED,
    AttackTally,
    WebProcess,
    axis_motion,
    closing_pages,
    crafted,
    page_load,
    rogue_page,
    slowloris,
)
from pyopenshowvar_apps.web.jogplan import AXIS_SPEED
from pyopenshowvar_apps.web.runner import KRL_DIR

from pyopenshowvar import Client

KVP = str(Path(sys.executable).with_name("kvp"))


async def ready(kvp: Client) -> None:
    async with asyncio.timeout(20):
        while await kvp.read("$PRO_STATE1") != "#P_ACTIVE":  # noqa: ASYNC110 - polling KVP
            await asyncio.sleep(0.05)
    await asyncio.sleep(1.5)  # the pad's link has read the program state


async def web_attacks(quick: bool) -> list[Row]:
    rows: list[Row] = []
    args = ["--program", str(KRL_DIR / "kvp_jog.src"), "--config", str(KRL_DIR / "kvp_jog_config.dat")]  # fmt: skip
    with EmuProcess(*args) as emu, WebProcess(emu.port) as web:
        async with Client("127.0.0.1", emu.port, timeout=5.0) as kvp:
            await ready(kvp)
            answers = await rogue_page(web.ws_url)
            watch = 1.0 if quick else 3.0
            motion = await axis_motion("127.0.0.1", emu.port, watch)
            refused = sum(1 for a in answers if a.get("error") or a.get("t") != "result")
            rows.append(Row("rogue page: A1 travel after the page closed", float(motion.travel[0]),
                                "deg", target=("ours", "<=", 0.01),
                                note=f"{refused}/{len(answers)} writes refused; watched {watch:g} s"))  # fmt: skip
            rows.append(Row("rogue page: A1 peak speed / the A1 jog speed",
                                float(motion.peak_speed[0]) / AXIS_SPEED[0], "x",
                                target=("ours", "<=", 1.0)))  # fmt: skip
            rows.append(Row("rogue page: A1 still moving at the end of the watch",
                                float(motion.last_motion > watch - 0.2), "",
                                target=("ours", "<=", 0.0)))  # fmt: skip
            await kvp.write_many([("JOG_AX", "{A1 0}"), ("JOG_UNTIL", "0"), ("JOG_MODE", "0")])
        rows += await slow_rows(web, quick)
        rows += await crafted_rows(web)
    return rows


async def slow_rows(web: WebProcess, quick: bool) -> list[Row]:
    tally = AttackTally()
    attack = asyncio.create_task(
        slowloris("127.0.0.1", web.port, tally, sockets=80, source="127.0.0.2")
    )
    await asyncio.sleep(1.0)  # every attacking socket is connected
    loads: list[tuple[int, float]] = []
    end = time.monotonic() + (3.0 if quick else 12.0)
    while time.monotonic() < end:
        loads.append(await page_load("127.0.0.1", web.port))
        await asyncio.sleep(0.5)
    attack.cancel()
    await asyncio.gather(attack, return_exceptions=True)
    failed = [s for s, _ in loads if s != 200]
    return [
        Row("slowloris: page loads that failed (80 sockets)", float(len(failed)), "",
            target=("ours", "<=", 0.0),
            note=f"of {len(loads)}; statuses {sorted(set(failed))}; attacker: "
            f"{tally.connections} connections, {tally.closed_by_server} closed by the server"),
        Row("slowloris: slowest page load", max(t for _, t in loads) * 1e3, "ms",
            target=("ours", "<=", 1000.0)),
    ]  # fmt: skip


async def crafted_rows(web: WebProcess) -> list[Row]:
    rows = []
    for name, message in CRAFTED.items():
        before = web.tracebacks()
        code, reason = await crafted(web.ws_url, message)
        await asyncio.sleep(0.2)  # a traceback is printed after the close
        rows.append(Row(f"crafted message, {name}: tracebacks printed", float(web.tracebacks() - before),
                        "", target=("ours", "<=", 0.0), note=f"close {code} {reason[:60]!r}"))  # fmt: skip
    before = web.tracebacks()
    await closing_pages(web.ws_url, 20)
    await asyncio.sleep(0.3)
    rows.append(Row("20 jogging pages closing at once: tracebacks printed", float(web.tracebacks() - before),
                    "", target=("ours", "<=", 0.0)))  # fmt: skip
    return rows


async def platform_attacks(quick: bool) -> list[Row]:
    rows: list[Row] = []
    with PlatformProcess() as plc:
        watch = 2.5 if quick else 4.0
        moving = await silent_master(plc.host, plc.port, watch)
        rows.append(Row("silent master, waves on: platform moving after the disconnect",
                        moving, "s", target=("ours", "<=", 1.5),
                        note=f"watched {watch:g} s; the watchdog is 1 s"))  # fmt: skip
        for what, kind, address, value in (
            ("WATCHDOG = 0 written by any client", "register", 7, 0),
            ("undefined coil 5 written", "coil", 5, 1),
        ):
            code = await write_refusal(plc.host, plc.port, kind, address, value)
            rows.append(Row(f"{what}: Modbus exception (0 = accepted)", float(code), "",
                            target=("ours", ">=", 2.0)))  # fmt: skip
    return rows


def main() -> None:
    ap = base_parser(__doc__)
    args = ap.parse_args()
    rows_web = asyncio.run(web_attacks(args.quick))
    rows_plc = asyncio.run(platform_attacks(args.quick))
    info = machine_info()
    print(f"{info['cpu']}, {info['cores']} cores, load {info['load']}")
    print_rows("kvp web under attack", rows_web)
    print_rows("kvp platform under attack", rows_plc)
    extra: dict[str, Any] = {"quick": args.quick}
    write_json(args.json, "Attacks on kvp web and kvp platform", rows_web + rows_plc, extra)


if __name__ == "__main__":
    main()
