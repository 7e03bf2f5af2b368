"""The mutation-testing script itself (bench/mutation.py), on a tiny project made here.

The tiny module has one mutant the tests cannot see (``x > 0`` → ``x > 1``: no test asks about
x == 1), one annotated as equivalent, one that loops forever (``n = n - 1`` → ``n = n + 1``:
killed by the per-mutant timeout) and an equivalence entry that matches nothing (stale). The
report must say exactly that, and the working tree must be left as it was.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytest.importorskip("mutmut")

SCRIPT = Path(__file__).resolve().parents[1] / "bench" / "mutation.py"

MODULE = '''\
"""A tiny module with a known surviving mutant."""


def is_positive(x: int) -> bool:
    return x > 0


def countdown(n: int) -> int:
    while n > 0:
        n = n - 1
    return n
'''

TESTS = """\
from pathlib import Path

from tinypkg.tiny import countdown, is_positive


def test_a_file_the_tests_read_is_there() -> None:
    assert (Path(__file__).parents[1] / "docs" / "note.txt").read_text() == "read by a test"


def test_sign() -> None:
    assert is_positive(5)
    assert not is_positive(-5)


def test_countdown() -> None:
    assert countdown(3) == 0
"""

CONFIG = """\
[settings]
packages = { tinypkg = "src/tinypkg" }
also_copy = ["tests", "docs", "pyproject.toml"]
timeout_constant = 1.0
timeout_multiplier = 2.0
pytest_args = ["-p", "no:cacheprovider"]

[modules]
"src/tinypkg/tiny.py" = ["tests/test_tiny.py"]
"""

EQUIVALENT = """\
[[equivalent]]
module = "src/tinypkg/tiny.py"
line = 5
original = "return x > 0"
mutant = "return x >= 0"
why = "pretend: the smoke test's annotation"

[[equivalent]]
module = "src/tinypkg/tiny.py"
original = "return n"
mutant = "return n + 42"
why = "matches no mutant: reported as stale"
"""


def _tree_digest(root: Path) -> str:
    h = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*") if p.is_file() and "__pycache__" not in p.parts):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(path.read_bytes())
    return h.hexdigest()


@pytest.fixture
def tiny(tmp_path: Path) -> Path:
    root = tmp_path / "proj"
    (root / "src" / "tinypkg").mkdir(parents=True)
    (root / "tests").mkdir()
    (root / "docs").mkdir()
    (root / "docs" / "note.txt").write_text("read by a test")
    (root / "src" / "tinypkg" / "__init__.py").write_text("")
    (root / "src" / "tinypkg" / "tiny.py").write_text(MODULE)
    (root / "tests" / "test_tiny.py").write_text(TESTS)
    (root / "pyproject.toml").write_text("[tool.pytest.ini_options]\naddopts = '-q'\n")
    (root / "mutation.toml").write_text(CONFIG)
    (root / "equivalent.toml").write_text(EQUIVALENT)
    return root


def _run(tiny: Path, tmp_path: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    scratch_parent = tmp_path / "scratch"
    scratch_parent.mkdir(exist_ok=True)
    env = {**os.environ, "TMPDIR": str(scratch_parent)}
    env.pop("PYTHONPATH", None)
    return subprocess.run(
        [sys.executable, str(SCRIPT), "--root", str(tiny), "--config", str(tiny / "mutation.toml"),
         "--equivalent", str(tiny / "equivalent.toml"), "--nice", "0", *extra],
        capture_output=True, text=True, env=env, timeout=240,
    )  # fmt: skip


def test_report_lists_the_survivor_the_equivalent_and_the_timeout(
    tiny: Path, tmp_path: Path
) -> None:
    before = _tree_digest(tiny)
    done = _run(tiny, tmp_path, "tinypkg.tiny", "--json")
    assert done.returncode == 0, done.stderr[-3000:]
    (report,) = json.loads(done.stdout)["modules"]
    assert report["module"] == "src/tinypkg/tiny.py"
    assert report["tests"] == ["tests/test_tiny.py"]
    survived = {(m["line"], m["original"], m["mutated"]) for m in report["survived"]}
    assert (5, "return x > 0", "return x > 1") in survived
    assert all(m["status"] == "survived" for m in report["survived"])
    assert "-    return x > 0" in report["survived"][0]["diff"]
    equivalent = [(m["line"], m["mutated"], m["why"]) for m in report["equivalent"]]
    assert equivalent == [(5, "return x >= 0", "pretend: the smoke test's annotation")]
    assert [e["mutant"] for e in report["stale_equivalents"]] == ["return n + 42"]
    assert report["timeouts"] >= 1  # n = n + 1 never ends: killed by the per-mutant bound
    killed, total = report["killed"], report["mutants"]
    assert killed == total - len(report["survived"]) - len(report["equivalent"])
    assert report["score"] == pytest.approx(round(100 * killed / (total - 1), 1))
    # the working tree is untouched and the scratch copy is gone
    assert _tree_digest(tiny) == before
    assert list((tmp_path / "scratch").iterdir()) == []


def test_text_report_and_usage_errors(tiny: Path, tmp_path: Path) -> None:
    missing = _run(tiny, tmp_path, "tinypkg.nothing")
    assert missing.returncode == 2 and "no module file" in missing.stderr
    (tiny / "src" / "tinypkg" / "other.py").write_text("def f() -> int:\n    return 1\n")
    unmapped = _run(tiny, tmp_path, "src/tinypkg/other.py")
    assert unmapped.returncode == 2 and "no tests for src/tinypkg/other.py" in unmapped.stderr


def test_module_whose_tests_fail_unmutated_is_an_error(tiny: Path, tmp_path: Path) -> None:
    (tiny / "tests" / "test_tiny.py").write_text(
        TESTS
        + textwrap.dedent("""
            def test_broken() -> None:
                assert is_positive(0)
        """)
    )
    done = _run(tiny, tmp_path, "src/tinypkg/tiny.py")
    assert done.returncode == 3 and "mutmut failed on src/tinypkg/tiny.py" in done.stderr
    assert list((tmp_path / "scratch").iterdir()) == []


def test_text_report_shows_each_survivor_with_its_diff_and_the_table(
    capsys: pytest.CaptureFixture[str],
) -> None:
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_mutation", SCRIPT)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["bench_mutation"] = mod  # dataclasses resolve their module by name
    try:
        spec.loader.exec_module(mod)
        diff = "--- a\n+++ a\n@@ -1,2 +1,2 @@\n def f(x):\n-    return x > 0\n+    return x > 1"
        report = mod.ModuleReport("pkg/m.py", ["tests/t.py"], mutants=10, killed=8, timeouts=1)
        report.survived.append(mod.Mutant("pkg.m.x_f__mutmut_2", 5, "return x > 0",
                                          "return x > 1", diff, "survived"))  # fmt: skip
        report.equivalent.append(mod.Mutant("pkg.m.x_f__mutmut_1", 5, "return x > 0",
                                            "return x >= 0", "", "equivalent", "x is never 0"))  # fmt: skip
        mod.print_report([report])
    finally:
        del sys.modules["bench_mutation"]
    out = capsys.readouterr().out
    assert "-- pkg/m.py:5  survived  (pkg.m.x_f__mutmut_2)" in out
    assert "   -    return x > 0\n   +    return x > 1" in out
    assert "equivalent pkg/m.py:5: return x > 0 -> return x >= 0  (x is never 0)" in out
    # 8 killed of 10 - 1 equivalent
    assert re.search(r"pkg/m.py\s+10\s+8\s+1\s+1\s+1\s+88.9%", out)


def _processes_in(directory: Path) -> list[int]:
    found = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cwd = os.readlink(proc / "cwd")
        except OSError:
            continue
        if cwd.startswith(str(directory)):
            found.append(int(proc.name))
    return found


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc to see the worker processes")
def test_interrupt_ends_every_worker_and_removes_the_scratch_copy(
    tiny: Path, tmp_path: Path
) -> None:
    # a test that keeps the run busy long enough to be interrupted in the middle
    (tiny / "tests" / "test_tiny.py").write_text(
        TESTS.replace(
            "def test_countdown() -> None:",
            "def test_countdown() -> None:\n    assert countdown(3_000_000) == 0",
        )
    )
    before = _tree_digest(tiny)
    scratch_parent = tmp_path / "scratch"
    scratch_parent.mkdir()
    env = {**os.environ, "TMPDIR": str(scratch_parent)}
    env.pop("PYTHONPATH", None)
    run = subprocess.Popen(
        [sys.executable, str(SCRIPT), "--root", str(tiny), "--config", str(tiny / "mutation.toml"),
         "--equivalent", str(tiny / "equivalent.toml"), "--nice", "0", "tinypkg.tiny"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        scratch = None
        while time.monotonic() < deadline and run.poll() is None:
            made = list(scratch_parent.glob("mutation-*/mutants/tinypkg/tiny.py.meta"))
            if made:
                scratch = made[0].parents[2]
                break
            time.sleep(0.05)
        assert scratch is not None, "mutmut never got to testing mutants"
        run.send_signal(signal.SIGINT)
        _, err = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 130, err
    assert "interrupted: the working tree was never mutated" in err
    assert list(scratch_parent.iterdir()) == []
    assert _processes_in(scratch) == []
    assert _tree_digest(tiny) == before
