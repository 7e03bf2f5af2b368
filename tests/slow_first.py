"""The suite's longest tests first, so that three workers on two cores finish together.

pytest-xdist deals tests out in collection order. Left in file order, a 30-second test that
happens to be dealt out last keeps one worker busy while the others have long finished; dealt
out first, the short tests fill the gaps behind it (longest-processing-time-first scheduling).
Together with a small scheduling chunk (``--maxschedchunk`` in pyproject's ``addopts``), the
workers end within a few short tests of each other.

The durations come from ``tests/durations.json``: each test that took at least
``MIN_SECONDS`` in a whole-suite run, in seconds. A test not in it counts as short; a stale
file only costs balance, never correctness. Refresh it from a run's JUnit report::

    .venv/bin/python -m pytest --junitxml=/tmp/suite.xml
    .venv/bin/python tests/slow_first.py /tmp/suite.xml
"""

from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import pytest

DURATIONS = Path(__file__).with_name("durations.json")
MIN_SECONDS = 2.0


def load(path: Path = DURATIONS) -> dict[str, float]:
    """Test node id → seconds; empty if the file is missing or unreadable."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return {str(k): float(v) for k, v in data.items()} if isinstance(data, dict) else {}


def order(items: list[pytest.Item], durations: dict[str, float]) -> None:
    """Sort ``items`` in place: known long tests first, longest first; the rest keep their order."""
    items.sort(key=lambda item: -durations.get(item.nodeid, 0.0))


def from_junit(report: Path, root: Path) -> dict[str, float]:
    """Node id → seconds of every test case in a JUnit report that took ``MIN_SECONDS`` or more."""
    out: dict[str, float] = {}
    for case in ET.parse(report).iter("testcase"):
        seconds = float(case.get("time", 0.0))
        if seconds < MIN_SECONDS:
            continue
        # junit's classname is the module path with dots ("tests.emu.test_plant")
        module = (case.get("classname") or "").replace(".", "/") + ".py"
        if (root / module).exists():
            out[f"{module}::{case.get('name')}"] = round(seconds, 1)
    return dict(sorted(out.items(), key=lambda kv: -kv[1]))


def main(argv: Sequence[str]) -> int:
    if len(argv) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    root = Path(__file__).resolve().parents[1]
    found = from_junit(Path(argv[0]), root)
    DURATIONS.write_text(json.dumps(found, indent=1) + "\n", encoding="utf-8")
    print(f"{len(found)} tests of {MIN_SECONDS} s or more written to {DURATIONS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
