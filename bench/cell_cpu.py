"""Cell benchmark: CPU per robot at rest and moving for N = 1, 10, 50 robots in one process.

Each cell is ``kukavarproxy-emu --robots N`` (``bench/_emu_server.py``, its own process) with
the defaults a user gets: the dynamic (MuJoCo) plant, the ``follow`` program (``LOOP PTP MYAXIS
C_PTP ENDLOOP``) and the shipped SPS, real time, 12 ms IPO. The figure is the emulator
process' CPU time over wall time, divided by N (% of one core per robot); the targets
are ≤ 1 % at rest and ≤ 5 % moving. Scenarios:

* at rest — nobody connected, the robots stand still;
* moving — this process writes ``MYAXIS`` to every robot every ``TOGGLE`` s, alternating
  between two poses far apart, so each robot is always on its way (its CPU is not counted);
* read every cycle — at rest, and every robot's ``$AXIS_ACT`` and ``$TORQUE_AXIS_ACT[]`` read
  by a client at ~80 Hz (informative: a dashboard polling every robot).

Also the IPO tick lateness (p99 over every robot's ticks, from the emulator itself) and, as the
floor no emulator can go below, the CPU of a bare asyncio process waking every 12 ms.

    .venv/bin/python bench/cell_cpu.py [--quick] [--seconds 5] [--sizes 1,10,50]
"""

from __future__ import annotations

import asyncio
import sys
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import EmuProcess, Row, base_parser, print_rows, write_json

from pyopenshowvar import sync

POSES = (
    "{A1 -90.0, A2 -60.0, A3 80.0, A4 -60.0, A5 -40.0, A6 -90.0}",
    "{A1 90.0, A2 -100.0, A3 110.0, A4 60.0, A5 40.0, A6 90.0}",
)
TOGGLE = 0.6  # s: shorter than a move between the poses, so a robot never arrives
TARGETS = {"rest": 1.0, "moving": 5.0}


def _bare_loop_percent(seconds: float) -> float:
    """CPU % of an asyncio process doing nothing but a 12 ms timer (the floor)."""

    async def main() -> float:
        loop = asyncio.get_running_loop()

        def tick(t: float) -> None:
            loop.call_at(t + 0.012, tick, t + 0.012)

        loop.call_at(loop.time() + 0.012, tick, loop.time() + 0.012)
        c0, w0 = time.process_time(), time.perf_counter()
        await asyncio.sleep(seconds)
        return 100.0 * (time.process_time() - c0) / (time.perf_counter() - w0)

    return asyncio.run(main())


class _Driver(threading.Thread):
    """Writes MYAXIS (moving) or reads the motion variables (reading) of every robot."""

    def __init__(self, host: str, ports: list[int], mode: str) -> None:
        super().__init__(daemon=True)
        self.host, self.ports, self.mode = host, ports, mode
        self.stop = threading.Event()
        self.errors = 0

    def run(self) -> None:
        clients = [sync.Client(self.host, p, timeout=5.0, keepalive=None) for p in self.ports]
        for c in clients:
            c.connect()
        turn = 0
        try:
            while not self.stop.is_set():
                t0 = time.perf_counter()
                for c in clients:
                    try:
                        if self.mode == "moving":
                            c.write("MYAXIS", POSES[turn % 2])
                        else:
                            c.read_many(["$AXIS_ACT", "$TORQUE_AXIS_ACT[]"])
                    except Exception:
                        self.errors += 1
                turn += 1
                pause = TOGGLE if self.mode == "moving" else 0.012
                self.stop.wait(max(0.0, pause - (time.perf_counter() - t0)))
        finally:
            for c in clients:
                c.close()


def _phase(emu: EmuProcess, n: int, mode: str, seconds: float) -> tuple[float, dict[str, Any]]:
    """CPU % per robot and the tick lateness of one scenario on a running cell."""
    driver = None
    if mode != "rest":
        driver = _Driver(emu.host, emu.ports, mode)
        driver.start()
    time.sleep(min(seconds, 1.0 if mode != "rest" else 0.5))  # robots on their way, caches warm
    emu.query("reset")
    cpu0, wall0 = emu.cpu_seconds(), time.perf_counter()
    time.sleep(seconds)
    cpu, wall = emu.cpu_seconds() - cpu0, time.perf_counter() - wall0
    stats = emu.query("stats")
    if driver is not None:
        driver.stop.set()
        driver.join(5.0)
    return 100.0 * cpu / wall / n, stats["jitter"] or {}


def run(quick: bool, seconds: float, sizes: list[int]) -> tuple[list[Row], dict[str, Any]]:
    rows = [
        Row(
            "floor: a bare asyncio process waking every 12 ms",
            _bare_loop_percent(max(seconds, 0.5)),
            "%",
            note="what one process costs before any robot work (the machine's wake-up cost)",
        )
    ]
    extra: dict[str, Any] = {}
    what = {"rest": "at rest", "moving": "moving", "reading": "at rest, read every cycle"}
    # one cell per size; the robots stand still until the last scenario moves them
    modes = ("rest", "moving") if quick else ("rest", "reading", "moving")
    results: dict[tuple[str, int], tuple[float, dict[str, Any]]] = {}
    for n in sizes:
        with EmuProcess(robots=n) as emu:
            for mode in modes:
                results[mode, n] = _phase(emu, n, mode, seconds)
    for mode in ("rest", "moving", "reading"):
        for n in sizes:
            if (mode, n) not in results:
                continue
            pct, jitter = results[mode, n]
            rows.append(
                Row(
                    f"CPU per robot, {n} robot{'s' if n > 1 else ''}, {what[mode]}",
                    pct,
                    "%",
                    target=("ours", "<=", TARGETS[mode]) if mode in TARGETS else None,
                    note=(
                        f"IPO lateness p50 {jitter.get('p50_ms', 0):.2f} ms, p99"
                        f" {jitter.get('p99_ms', 0):.2f} ms, max {jitter.get('max_ms', 0):.1f} ms"
                        f" over {jitter.get('count', 0)} ticks;"
                        f" {jitter.get('overruns', 0)} clock re-bases"
                    ),
                )
            )
            if n == max(sizes) and mode in ("rest", "moving"):
                rows.append(
                    Row(
                        f"IPO tick lateness p99, {n} robots {what[mode]}",
                        float(jitter.get("p99_ms", 0.0)),
                        "ms",
                        target=("ours", "<", 2.0),
                    )
                )
            extra[f"{mode}_{n}"] = jitter
    return rows, extra


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--seconds", type=float, default=5.0, help="wall seconds per scenario")
    ap.add_argument("--sizes", default="1,10,50", help="cell sizes (comma-separated)")
    args = ap.parse_args()
    sizes = [2] if args.quick else [int(x) for x in args.sizes.split(",")]
    seconds = 0.2 if args.quick else args.seconds
    rows, extra = run(args.quick, seconds, sizes)
    print_rows("A cell of robots in one process (% of one core per robot, real time)", rows)
    write_json(args.json, "cell", rows, extra)


if __name__ == "__main__":
    main()
