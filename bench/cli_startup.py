"""CLI start-up benchmark: wall time of ``kvp read '$OV_PRO'`` from process start to answer.

A shell script calls ``kvp`` once per value, so the start-up (imports) is the cost it pays. The
figure is the median of N runs against an emulator already running in its own process (the
request itself is well under a millisecond); ``import pyopenshowvar_apps.cli`` alone is timed
too, and py-openshowvar's one-shot read (a fresh interpreter, import, connect, read) is the
peer: the cheapest way a Python user reads one variable from a shell.

    .venv/bin/python bench/cli_startup.py [--quick] [--repeat 15]
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import EmuProcess, Row, median, repeat_main

KVP = str(Path(sys.executable).with_name("kvp"))
PEER = (
    "import sys, py_openshowvar as p; c = p.openshowvar('127.0.0.1', int(sys.argv[1]));"
    " print(c.read('$OV_PRO', debug=False)); c.close()"
)


def _wall(argv: list[str]) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, text=True, check=False)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{argv[0]} failed: {proc.stderr.strip()[-500:]}")
    return dt


def run(quick: bool, repeat: int) -> tuple[list[Row], dict[str, Any]]:
    rows: list[Row] = []
    with EmuProcess("--latency", "none", "--no-robot") as emu:
        port = str(emu.port)
        _wall([KVP, "-p", port, "read", "$OV_PRO"])  # warm the page cache and .pyc files
        ours = [_wall([KVP, "-p", port, "read", "$OV_PRO"]) * 1e3 for _ in range(repeat)]
        imports = [
            _wall([sys.executable, "-c", "import pyopenshowvar_apps.cli"]) * 1e3
            for _ in range(repeat)
        ]
        peer: list[float] = []
        try:
            import py_openshowvar  # noqa: F401

            peer = [_wall([sys.executable, "-c", PEER, port]) * 1e3 for _ in range(repeat)]
        except ImportError:  # optional peer
            pass
    rows.append(
        Row(
            "kvp read start-up, process start to answer (median)",
            median(ours),
            "ms",
            peer=median(peer) if peer else None,
            peer_name="py-openshowvar one-shot",
            note=f"min {min(ours):.0f} ms, max {max(ours):.0f} ms over {repeat} runs",
            runs=ours,
        )
    )
    rows.append(
        Row("import pyopenshowvar_apps.cli (fresh interpreter, median)", median(imports), "ms")
    )
    return rows, {"repeat": repeat}


def main() -> None:
    repeat_main(__doc__, "CLI start-up", "CLI", run, repeat=15)


if __name__ == "__main__":
    main()
