"""Shared helpers of the benchmark scripts: the emulator subprocess, medians, results, machine.

Every benchmark script builds a list of :class:`Row` (one figure: ours, the peer's, the ratio,
the target and whether it is met), prints it and, with ``--json PATH``, writes it for
``bench/run_all.py``, which regenerates ``docs/BENCHMARKS.md``. Benchmarks never assert: a slow
machine gives slow numbers, never a failure.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
EMU_SERVER = Path(__file__).resolve().with_name("_emu_server.py")


def median(values: Sequence[float]) -> float:
    return float(statistics.median(values))


def percentile(sorted_values: Sequence[float], q: float) -> float:
    """Nearest-rank percentile of already sorted values (q in 0..100)."""
    if not sorted_values:
        return float("nan")
    return float(sorted_values[min(len(sorted_values) - 1, int(len(sorted_values) * q / 100))])


@dataclass
class Row:
    """One figure of a benchmark table.

    ``target`` is (what, op, value): what ∈ {"ratio", "ours"}, op ∈ {"<=", "<", ">=", ">"}.
    The ratio is always ours / peer; the target says which side is good.
    """

    figure: str
    ours: float
    unit: str
    peer: float | None = None
    peer_name: str = ""
    target: tuple[str, str, float] | None = None
    note: str = ""
    runs: list[float] = field(default_factory=list)

    @property
    def ratio(self) -> float | None:
        if self.peer is None or self.peer == 0:
            return None
        return self.ours / self.peer

    @property
    def met(self) -> bool | None:
        if self.target is None:
            return None
        what, op, value = self.target
        x = self.ratio if what == "ratio" else self.ours
        if x is None:
            return None
        return {
            "<=": x <= value,
            "<": x < value,
            ">=": x >= value,
            ">": x > value,
        }[op]

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["ratio"] = self.ratio
        d["met"] = self.met
        return d


def fmt(x: float | None, unit: str = "") -> str:
    if x is None:
        return "–"
    if unit in ("µs", "ms"):
        return f"{x:,.1f} {unit}" if x < 100 else f"{x:,.0f} {unit}"
    if unit == "%":
        return f"{x:.1f} %"
    if unit == "MB":
        return f"{x:.1f} MB"
    if abs(x) >= 100:
        return f"{x:,.0f} {unit}".strip()
    return f"{x:.3g} {unit}".strip()


def fmt_target(row: Row) -> str:
    if row.target is None:
        return "–"
    what, op, value = row.target
    op = {"<=": "≤", ">=": "≥"}.get(op, op)
    if what == "ratio":
        return f"ratio {op} {value:g}"
    return f"{op} {fmt(value, row.unit)}"


def fmt_met(row: Row) -> str:
    met = row.met
    return "–" if met is None else ("met" if met else "**missed**")


def print_rows(title: str, rows: Sequence[Row]) -> None:
    print(f"\n{title}")
    for r in rows:
        ratio = r.ratio
        line = f"  {r.figure:58s} ours {fmt(r.ours, r.unit):>16s}"
        if r.peer is not None:
            line += f"  {r.peer_name or 'peer'} {fmt(r.peer, r.unit):>14s}"
        if ratio is not None:
            line += f"  ratio {ratio:.3g}"
        if r.target is not None:
            line += f"  [{fmt_target(r)}: {fmt_met(r)}]"
        print(line, flush=True)
        if r.note:
            print(f"      {r.note}")


def base_parser(doc: str | None) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        description=(doc or "").strip().splitlines()[0] if doc else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument(
        "--quick", action="store_true", help="tiny sizes (smoke test), numbers meaningless"
    )
    ap.add_argument("--repeat", type=int, default=None, help="runs per figure (median is quoted)")
    ap.add_argument("--json", type=Path, default=None, help="also write the rows to this file")
    return ap


def write_json(path: Path | None, area: str, rows: Sequence[Row], extra: dict[str, Any]) -> None:
    if path is None:
        return
    path.write_text(
        json.dumps({"area": area, "rows": [r.as_dict() for r in rows], "extra": extra}, indent=1)
    )


def repeat_main(
    doc: str | None,
    title: str,
    area: str,
    run: Callable[[bool, int], tuple[list[Row], dict[str, Any]]],
    *,
    repeat: int,
) -> None:
    """The whole ``main`` of a benchmark that is one ``run(quick, repeat) -> (rows, extra)``:
    the shared options (``--repeat`` defaults to ``repeat``, 1 with ``--quick``), the table
    (``title`` may name ``{repeat}``) and the JSON for ``run_all.py``."""
    args = base_parser(doc).parse_args()
    n = args.repeat or (1 if args.quick else repeat)
    rows, extra = run(args.quick, n)
    print_rows(title.format(repeat=n), rows)
    write_json(args.json, area, rows, extra)


# --------------------------------------------------------------------------- machine


def machine_info() -> dict[str, str]:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        import numpy

        np_version = numpy.__version__
    except ImportError:  # pragma: no cover
        np_version = "-"
    load = ""
    try:
        load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:  # pragma: no cover
        pass
    return {
        "date": time.strftime("%Y-%m-%d %H:%M %Z"),
        "cpu": cpu,
        "cores": str(os.cpu_count()),
        "python": f"{platform.python_implementation()} {platform.python_version()}",
        "numpy": np_version,
        "os": f"{platform.system()} {platform.release()}",
        "load": load,
    }


# --------------------------------------------------------------------------- emulator process


def rss_mb(pid: int) -> float:
    """Resident set size of a process in MB (psutil when installed, else /proc)."""
    try:
        import psutil

        return float(psutil.Process(pid).memory_info().rss) / 1e6
    except ImportError:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024 / 1e6
    return float("nan")


class EmuProcess:
    """``bench/_emu_server.py`` in a subprocess (its own GIL and core).

    ``with EmuProcess("--latency", "kvp", "--seed", "1") as emu: emu.port``; ``emu.query("stats")``
    returns the server's counters and IPO jitter; ``emu.query("reset")`` clears the jitter record.
    The options are those of ``kukavarproxy-emu`` (the harness builds the same EmulatorConfig).
    """

    def __init__(self, *args: str, robots: int = 1) -> None:
        self.args = ["--port", "0", "--idle-timeout", "0", "--max-clients", "0", *args]
        if robots != 1:
            self.args += ["--robots", str(robots)]
        self.robots = robots
        self.proc: subprocess.Popen[str] | None = None
        self.host = "127.0.0.1"
        self.port = 0
        #: Every robot's port (a cell: ``--robots N``).
        self.ports: list[int] = []

    def __enter__(self) -> EmuProcess:
        self.proc = subprocess.Popen(
            [sys.executable, str(EMU_SERVER), *self.args],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        assert self.proc.stdout is not None
        for _ in range(self.robots):
            line = self.proc.stdout.readline().strip()
            if not line.startswith("listening on "):
                self.proc.kill()
                raise RuntimeError(f"emulator did not start: {line!r}")
            host, _, port = line.removeprefix("listening on ").rpartition(":")
            self.ports.append(int(port))
        self.host, self.port = host, self.ports[0]
        return self

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    def query(self, command: str) -> dict[str, Any]:
        assert (
            self.proc is not None and self.proc.stdin is not None and self.proc.stdout is not None
        )
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()
        result: dict[str, Any] = json.loads(self.proc.stdout.readline())
        return result

    def cpu_seconds(self) -> float:
        """User + system CPU time the emulator process has used so far."""
        fields = Path(f"/proc/{self.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def __exit__(self, *exc: object) -> None:
        if self.proc is None:
            return
        try:
            if self.proc.stdin is not None:
                self.proc.stdin.close()  # EOF: the harness stops
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
