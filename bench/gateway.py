"""``kvp gateway`` at scale: CPU of the gateway process and OPC UA update latency, N robots.

    .venv/bin/python bench/gateway.py                  # 10 and 50 robots at 10 Hz, 20 s each
    .venv/bin/python bench/gateway.py --robots 50 --seconds 60
    .venv/bin/python bench/gateway.py --quick          # 2 robots, 2 s (smoke test)

Three kinds of process: the emulated robots (bench/_cell_emus.py, 10 per process, animated
so every poll reads new axis values), the gateway (the real ``kvp gateway cell.toml`` command) and
this script, an asyncua client that subscribes to A1's ActualPosition of every robot
(publishing interval ``--publish-ms``, queue 10 so no sample is merged away). CPU is the
gateway process's own user+system time over the measuring window, as % of one core. Latency
is the client's receive time minus the value's SourceTimestamp, which the gateway sets to the
arrival of the KVP reply the value came from: "a subscribed client sees a new value within
200 ms of its KVP read". Targets: gateway ≤ 50 % of one core with 50 robots at
10 Hz; every update within 200 ms.
"""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _cell_emus import SNAPSHOT_MEMBERS
from _common import ROOT, Row, base_parser, machine_info, percentile, print_rows, write_json

CELL_EMUS = Path(__file__).resolve().with_name("_cell_emus.py")


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _cell_file(folder: Path, ports: list[int], hz: float, snapshot: bool) -> Path:
    lines = ['[cell]\nname = "bench"\nendpoint = "opc.tcp://127.0.0.1:0"\n']
    members = ", ".join(f'"{k}" = "{v}"' for k, v in SNAPSHOT_MEMBERS.items())
    for i, port in enumerate(ports, 1):
        lines.append(
            f'[[robot]]\nname = "r{i}"\nhost = "127.0.0.1"\nport = {port}\npoll_hz = {hz}\n'
        )
        if snapshot:
            lines.append(f'[[robot.snapshot]]\nvariable = "GW_SNAP"\nmembers = {{ {members} }}\n')
    path = folder / "cell.toml"
    path.write_text("\n".join(lines))
    return path


class _Handler:
    def __init__(self) -> None:
        self.latencies: list[float] = []
        self.counts: dict[Any, int] = {}
        self.bad = 0
        self.recording = False

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        now = datetime.now(UTC)
        dv = data.monitored_item.Value
        if not self.recording:
            return
        if dv.StatusCode is not None and not dv.StatusCode.is_good():
            self.bad += 1
            return
        if dv.SourceTimestamp is not None:
            self.latencies.append((now - dv.SourceTimestamp).total_seconds() * 1e3)
        self.counts[node] = self.counts.get(node, 0) + 1


async def _measure(
    url: str, robots: int, gw_pid: int, seconds: float, publish_ms: float
) -> dict[str, Any]:
    from asyncua import Client, ua

    handler = _Handler()
    async with Client(url, timeout=30) as client:
        ns = await client.get_namespace_index("urn:pyopenshowvar:kvp-gateway")
        nodes = [
            client.get_node(
                ua.NodeId(f"bench.MotionDevices.r{i}.Axes.A1.ParameterSet.ActualPosition", ns)
            )
            for i in range(1, robots + 1)
        ]
        sub = await client.create_subscription(publish_ms, handler)
        await sub.subscribe_data_change(nodes, queuesize=10, sampling_interval=0)
        await asyncio.sleep(3.0)  # every robot connected and polling
        handler.recording = True
        c0, t0 = _cpu_seconds(gw_pid), time.monotonic()
        await asyncio.sleep(seconds)
        c1, t1 = _cpu_seconds(gw_pid), time.monotonic()
        handler.recording = False
        await sub.delete()
    lat = sorted(handler.latencies)
    polls = sum(handler.counts.values())
    return {
        "cpu_pct": 100 * (c1 - c0) / (t1 - t0),
        "cpu_ms_per_poll": 1e3 * (c1 - c0) / polls if polls else float("nan"),
        "p50": percentile(lat, 50),
        "p99": percentile(lat, 99),
        "max": lat[-1] if lat else float("nan"),
        "updates_per_robot_s": sum(handler.counts.values()) / robots / (t1 - t0),
        "robots_seen": len(handler.counts),
        "bad": handler.bad,
        "samples": len(lat),
    }


def _start_emulators(
    robots: int, per_process: int, snapshot: bool
) -> tuple[list[subprocess.Popen[str]], list[int]]:
    """The robots in processes of ``per_process`` each (the OS shares CPU per process, and the
    benchmark must measure the gateway, not wait for starved emulators)."""
    procs: list[subprocess.Popen[str]] = []
    ports: list[int] = []
    remaining = robots
    while remaining > 0:
        n = min(per_process, remaining)
        remaining -= n
        proc = subprocess.Popen(
            [sys.executable, str(CELL_EMUS), str(n), *(["--snapshot"] if snapshot else [])],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT,
        )  # fmt: skip
        procs.append(proc)
    for proc in procs:
        assert proc.stdout is not None
        line = proc.stdout.readline().split()
        if not line or line[0] != "ports":
            for p in procs:
                p.kill()
            raise RuntimeError(f"emulators did not start: {line}")
        ports += [int(p) for p in line[1:]]
    return procs, ports


def run(
    robots: int, seconds: float, hz: float, publish_ms: float, per_process: int, snapshot: bool
) -> tuple[dict[str, Any], float]:
    emus, ports = _start_emulators(robots, per_process, snapshot)
    with tempfile.TemporaryDirectory() as tmp:
        cell = _cell_file(Path(tmp), ports, hz, snapshot)
        started = time.monotonic()
        gw = subprocess.Popen(
            [
                sys.executable,
                "-c",
                "from pyopenshowvar_apps.cli import main; main()",
                "gateway",
                str(cell),
                "--log-level",
                "warning",
            ],
            stdout=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        try:
            assert gw.stdout is not None
            first = gw.stdout.readline().strip()
            startup = time.monotonic() - started
            # CPU, unlike wall time, barely depends on the machine's load
            startup_cpu = _cpu_seconds(gw.pid)
            if not first.startswith("serving "):
                raise RuntimeError(f"gateway did not start: {first!r}")
            result = asyncio.run(_measure(first.split()[1], robots, gw.pid, seconds, publish_ms))
            result["startup_cpu"] = startup_cpu
        finally:
            gw.terminate()
            gw.wait(20)
            for emu in emus:
                assert emu.stdin is not None
                emu.stdin.close()
                emu.wait(20)
    return result, startup


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--robots", type=int, action="append", help="cell sizes (default 10 and 50)")
    ap.add_argument("--seconds", type=float, default=20.0, help="measuring window per size")
    ap.add_argument("--hz", type=float, default=10.0, help="poll rate of every robot")
    ap.add_argument(
        "--publish-ms", type=float, default=100.0, help="subscription publishing interval"
    )
    ap.add_argument(
        "--snapshot",
        action="store_true",
        help="a snapshot group: $AXIS_ACT and five scalars in one STRUC read",
    )
    ap.add_argument(
        "--robots-per-process", type=int, default=10, help="emulated robots per process"
    )
    args = ap.parse_args()
    sizes = args.robots or ([2] if args.quick else [10, 50])
    seconds = 2.0 if args.quick else args.seconds
    rows: list[Row] = []
    extra: dict[str, Any] = {"machine": machine_info(), "publish_ms": args.publish_ms}
    mode = ", snapshot group" if args.snapshot else ""
    for n in sizes:
        r, startup = run(
            n, seconds, args.hz, args.publish_ms, args.robots_per_process, args.snapshot
        )
        extra[f"n{n}"] = r
        note = f"{r['samples']} updates from {r['robots_seen']}/{n} robots, {r['bad']} Bad"
        rows += [
            Row(
                f"gateway CPU, {n} robots at {args.hz:g} Hz{mode}",
                r["cpu_pct"],
                "%",
                target=("ours", "<=", 50.0),
                note=f"% of one core; load {extra['machine']['load']}",
            ),
            Row(
                f"gateway CPU per poll, {n} robots",
                r["cpu_ms_per_poll"] * 1e3,
                "µs",
                note="CPU seconds / updates seen (A1 changes every poll)",
            ),
            Row(
                f"gateway CPU projected to {n} x {args.hz:g} polls/s",
                r["cpu_ms_per_poll"] * n * args.hz / 10,
                "%",
                target=("ours", "<=", 50.0),
                note="for when the loaded machine delivered fewer polls than asked",
            ),
            Row(f"update latency p50, {n} robots", r["p50"], "ms"),
            Row(f"update latency p99, {n} robots", r["p99"], "ms", target=("ours", "<=", 200.0)),
            Row(
                f"update latency max, {n} robots",
                r["max"],
                "ms",
                target=("ours", "<=", 200.0),
                note=note,
            ),
            Row(
                f"updates per robot, {n} robots",
                r["updates_per_robot_s"],
                "/s",
                target=("ours", ">=", 0.95 * args.hz),
            ),
            Row(f"start-up to 'serving', {n} robots", startup, "s", note="wall time"),
            Row(
                f"start-up CPU to 'serving', {n} robots",
                r["startup_cpu"],
                "s",
                note="the gateway process's CPU time (interpreter and imports included)",
            ),
        ]
    print_rows("kvp gateway (OPC UA Robotics)", rows)
    write_json(args.json, "Gateway", rows, extra)


if __name__ == "__main__":
    main()
