"""Mutation testing of chosen modules: which one-line bugs would the tests not notice?

    python bench/mutation.py MODULE... [--tests FILE...] [--jobs N] [--json] [--keep]

A MODULE is a file path (``pyopenshowvar/protocol.py``, ``apps/pyopenshowvar_apps/web/jog.py``)
or a dotted name (``pyopenshowvar_apps.heave.control``). For each module the script copies the
packages and tests into a scratch directory, has mutmut (``pip install -e '.[mutation]'``)
generate every mutant of that one file and run, for each mutant, only the tests of the
module's list in ``bench/mutation.toml`` (or ``--tests``) that called the mutated function,
then prints each surviving mutant (file:line and its diff) and the module's score. The working
tree is never written to: mutants live in the scratch copy, which is removed afterwards, also
after Ctrl-C (``--keep`` leaves it for ``mutmut browse``).

A mutant whose tests run past its wall-clock bound (``timeout_*`` in the config) counts as
killed by timeout. Mutants listed in ``bench/mutation_equivalent.toml`` (no test can tell them
from the original; each entry says why) are subtracted and listed; an entry that no longer
matches a survivor is reported as stale. Score = killed / (mutants - equivalent).

The exit status is 0 when every module ran, whatever its score (a score is a figure, not a
verdict), 2 on a usage error and 3 when mutmut could not run a module (e.g. its tests fail
unmutated).
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
CONFIG = Path(__file__).resolve().with_name("mutation.toml")
EQUIVALENT = Path(__file__).resolve().with_name("mutation_equivalent.toml")

#: mutmut's result codes (mutmut.stats.status_by_exit_code), folded into our three outcomes
_KILLED = {1, 3}
_TIMEOUT = {36, -24, 24, 152, 255}
_CRASHED = {-11, -9}  # the mutant crashed the test process: the tests noticed it
_SURVIVED = {0}
_NO_TESTS = {5, 33}  # no test of the list called the mutated function: survives
_SKIPPED = {34}  # `# pragma: no mutate`

#: the helper run inside the scratch copy after mutmut: the diff of each survivor
_DIFF_HELPER = """
import json, sys
from mutmut.mutation.diff_apply import get_diff_for_mutant
names, path = json.loads(sys.argv[1]), sys.argv[2]
print(json.dumps({n: get_diff_for_mutant(n, path=path) for n in names}))
"""


class UsageError(Exception):
    """A module or test file that cannot be resolved: exit status 2."""


class RunError(Exception):
    """mutmut failed on a module (its tests fail unmutated, a crash): exit status 3."""


@dataclass
class Mutant:
    """One surviving or equivalent mutant, where it is and what it changes."""

    name: str
    line: int
    original: str
    mutated: str
    diff: str
    status: str  # "survived", "no tests" or "equivalent"
    why: str = ""


@dataclass
class ModuleReport:
    module: str
    tests: list[str]
    mutants: int = 0
    killed: int = 0
    timeouts: int = 0
    survived: list[Mutant] = field(default_factory=list)
    equivalent: list[Mutant] = field(default_factory=list)
    stale_equivalents: list[dict[str, Any]] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def score(self) -> float:
        effective = self.mutants - len(self.equivalent)
        return 100.0 * self.killed / effective if effective else 100.0


def load_config(path: Path) -> dict[str, Any]:
    with path.open("rb") as f:
        return tomllib.load(f)


def resolve_module(arg: str, root: Path, packages: dict[str, str]) -> str:
    """A repository-relative file path for a path or dotted module name."""
    candidates = [arg]
    if not arg.endswith(".py"):
        parts = arg.split(".")
        base = packages.get(parts[0], parts[0])
        candidates += [
            "/".join([base, *parts[1:]]) + ".py",
            "/".join([base, *parts[1:], "__init__"]) + ".py",
        ]
    for candidate in candidates:
        path = (root / candidate).resolve()
        if path.is_file():
            try:
                return path.relative_to(root.resolve()).as_posix()
            except ValueError:
                break
    raise UsageError(f"no module file for {arg!r} under {root}")


def scratch_path(module: str, packages: dict[str, str]) -> str:
    """The module's path in the scratch copy, where every package sits at the top level."""
    for name, repo_dir in sorted(packages.items(), key=lambda item: -len(item[1])):
        if module == repo_dir or module.startswith(repo_dir.rstrip("/") + "/"):
            return name + module[len(repo_dir.rstrip("/")) :]
    raise UsageError(f"{module} is in none of the configured packages {sorted(packages)}")


def build_scratch(root: Path, scratch: Path, settings: dict[str, Any]) -> None:
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".pytest_cache", ".hypothesis")
    for name, repo_dir in settings["packages"].items():
        shutil.copytree(root / repo_dir, scratch / name, ignore=ignore)
    for extra in settings.get("also_copy", []):
        source = root / extra
        if source.is_dir():
            shutil.copytree(source, scratch / extra, ignore=ignore, dirs_exist_ok=True)
        elif source.is_file():
            shutil.copy2(source, scratch / extra)


def write_mutmut_config(
    scratch: Path, settings: dict[str, Any], target: str, tests: list[str]
) -> None:
    """The [tool.mutmut] table of the scratch copy's pyproject.toml (TOML: JSON strings are
    valid TOML basic strings, so patterns keep their backslashes)."""
    table = {
        "source_paths": sorted(settings["packages"]),
        "only_mutate": [target],
        "pytest_add_cli_args_test_selection": tests,
        "pytest_add_cli_args": list(settings.get("pytest_args", [])),
        "do_not_mutate_patterns": list(settings.get("do_not_mutate_patterns", [])),
        # mutmut runs the tests in its own copy (mutants/): the files tests read go there too
        "also_copy": list(settings.get("also_copy", [])),
        "timeout_constant": float(settings.get("timeout_constant", 5.0)),
        "timeout_multiplier": float(settings.get("timeout_multiplier", 4.0)),
        "use_setproctitle": False,
        "use_git_change_detection": False,
    }
    pyproject = scratch / "pyproject.toml"
    text = pyproject.read_text(encoding="utf-8") if pyproject.is_file() else ""
    text = re.sub(r"(?ms)^\[tool\.mutmut\].*?(?=^\[|\Z)", "", text)
    body = "".join(f"{key} = {json.dumps(value)}\n" for key, value in table.items())
    pyproject.write_text(f"{text.rstrip()}\n\n[tool.mutmut]\n{body}", encoding="utf-8")


def run_mutmut(scratch: Path, jobs: int, log: Path, nice: int) -> int:
    """mutmut in its own process group, so Ctrl-C or a crash ends all of its workers."""
    env = dict(os.environ)
    # made now, not by mutmut: a PYTHONPATH entry that does not exist yet when the interpreter
    # starts is cached as "no such directory" and never searched again
    (scratch / "mutants").mkdir(exist_ok=True)
    # subprocess tests (the emulator's CLI, `kvp`) import the mutated copy too
    env["PYTHONPATH"] = os.pathsep.join(
        [str(scratch / "mutants"), *filter(None, [env.get("PYTHONPATH")])]
    )
    env.pop("MUTANT_UNDER_TEST", None)
    cmd = [sys.executable, "-m", "mutmut", "run", "--max-children", str(jobs)]
    if nice:
        cmd = ["nice", "-n", str(nice), *cmd]
    with log.open("wb") as out:
        proc = subprocess.Popen(
            cmd, cwd=scratch, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
        )
        try:
            return proc.wait()
        finally:
            # the mutmut group: workers, and any emulator a killed test left behind
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait()


def function_ranges(source: str) -> dict[str, tuple[int, int]]:
    """Line ranges of functions and methods, keyed like mutmut (``x_f``, ``xǁClassǁm``)."""
    ranges: dict[str, tuple[int, int]] = {}

    def visit(node: ast.AST, cls: str | None) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                key = f"xǁ{cls}ǁ{child.name}" if cls else f"x_{child.name}"
                ranges.setdefault(key, (child.lineno, child.end_lineno or child.lineno))
            elif isinstance(child, ast.ClassDef) and cls is None:
                visit(child, child.name)

    visit(ast.parse(source), None)
    return ranges


def locate(diff: str, mutant_name: str, source_lines: list[str], ranges: dict[str, Any]) -> Mutant:
    """The file line, original and mutated text of a mutant from its function-level diff."""
    removed = [
        ln[1:] for ln in diff.splitlines() if ln.startswith("-") and not ln.startswith("---")
    ]
    added = [ln[1:] for ln in diff.splitlines() if ln.startswith("+") and not ln.startswith("+++")]
    original = " ".join(part.strip() for part in removed)
    mutated = " ".join(part.strip() for part in added)
    key = mutant_name.rpartition(".")[2].partition("__mutmut_")[0]
    start, end = ranges.get(key, (1, len(source_lines)))
    line = start
    if removed:
        first = removed[0].strip()
        for number in range(start, end + 1):
            if source_lines[number - 1].strip() == first:
                line = number
                break
    return Mutant(mutant_name, line, original, mutated, diff, "survived")


def load_equivalents(path: Path) -> list[dict[str, Any]]:
    if not path.is_file():
        return []
    return list(load_config(path).get("equivalent", []))


def _norm(text: str) -> str:
    return " ".join(text.split())


def apply_equivalents(report: ModuleReport, entries: list[dict[str, Any]]) -> None:
    """Moves the annotated survivors to ``equivalent``; entries matching none are stale."""
    mine = [e for e in entries if e.get("module") == report.module]
    for entry in mine:
        matches = [
            m
            for m in report.survived
            if _norm(m.original) == _norm(str(entry["original"]))
            and _norm(m.mutated) == _norm(str(entry["mutant"]))
        ]
        if len(matches) > 1 and "line" in entry:
            matches = [m for m in matches if m.line == entry["line"]] or matches[:1]
        if not matches:
            report.stale_equivalents.append(entry)
            continue
        for m in matches:
            report.survived.remove(m)
            m.status, m.why = "equivalent", str(entry.get("why", ""))
            report.equivalent.append(m)


def run_module(
    module: str,
    tests: list[str],
    *,
    root: Path,
    settings: dict[str, Any],
    equivalents: list[dict[str, Any]],
    jobs: int,
    nice: int,
    keep: bool,
) -> ModuleReport:
    report = ModuleReport(module, tests)
    target = scratch_path(module, settings["packages"])
    scratch = Path(tempfile.mkdtemp(prefix="mutation-"))
    started = time.monotonic()
    try:
        build_scratch(root, scratch, settings)
        write_mutmut_config(scratch, settings, target, tests)
        log = scratch / "mutmut.log"
        code = run_mutmut(scratch, jobs, log, nice)
        meta = scratch / "mutants" / (target + ".meta")
        if code != 0 or not meta.is_file():
            tail = log.read_text(errors="replace")[-3000:]
            raise RunError(f"mutmut failed on {module} (exit {code}); its log ends:\n{tail}")
        codes: dict[str, int | None] = json.loads(meta.read_text())["exit_code_by_key"]
        survivors: list[tuple[str, str]] = []
        for name, rc in sorted(codes.items()):
            if rc in _SKIPPED:
                continue
            report.mutants += 1
            if rc in _KILLED or rc in _CRASHED:
                report.killed += 1
            elif rc in _TIMEOUT:
                report.killed += 1
                report.timeouts += 1
            else:  # survived, no tests, not checked, suspicious: the tests did not notice
                survivors.append((name, "no tests" if rc in _NO_TESTS else "survived"))
        diffs: dict[str, str] = {}
        if survivors:
            out = subprocess.run(
                [sys.executable, "-c", _DIFF_HELPER, json.dumps([n for n, _ in survivors]), target],
                cwd=scratch,
                capture_output=True,
                text=True,
                check=True,
                timeout=600,
            )
            diffs = json.loads(out.stdout.strip().splitlines()[-1])
        source = (root / module).read_text(encoding="utf-8")
        ranges = function_ranges(source)
        lines = source.splitlines()
        for name, status in survivors:
            mutant = locate(diffs.get(name, ""), name, lines, ranges)
            mutant.status = status
            report.survived.append(mutant)
        apply_equivalents(report, equivalents)
    finally:
        report.seconds = time.monotonic() - started
        if keep:
            print(f"scratch copy kept: {scratch}", file=sys.stderr)
        else:
            shutil.rmtree(scratch, ignore_errors=True)
    return report


def print_report(reports: list[ModuleReport]) -> None:
    for r in reports:
        print(f"\n== {r.module}  ({len(r.tests)} test files, {r.seconds:.0f} s)")
        for m in r.survived:
            print(f"-- {r.module}:{m.line}  {m.status}  ({m.name})")
            body = [ln for ln in m.diff.splitlines() if not ln.startswith(("---", "+++"))]
            print("\n".join("   " + ln for ln in body) or f"   {m.original} -> {m.mutated}")
        for m in r.equivalent:
            print(f"   equivalent {r.module}:{m.line}: {m.original} -> {m.mutated}  ({m.why})")
        for e in r.stale_equivalents:
            print(f"   STALE equivalent entry (matches no survivor): {e}")
    print(
        f"\n{'module':48} {'mutants':>7} {'killed':>6} {'timeout':>7} "
        f"{'survived':>8} {'equiv':>5} {'score':>6} {'time':>6}"
    )
    for r in reports:
        print(
            f"{r.module:48} {r.mutants:7d} {r.killed:6d} {r.timeouts:7d} "
            f"{len(r.survived):8d} {len(r.equivalent):5d} {r.score:5.1f}% {r.seconds:5.0f}s"
        )


def as_json(reports: list[ModuleReport]) -> str:
    rows = []
    for r in reports:
        row = asdict(r)
        row["score"] = round(r.score, 1)
        rows.append(row)
    return json.dumps({"modules": rows}, indent=2)


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


def main(argv: list[str] | None = None) -> int:
    # Ctrl-C, a kill or a closed terminal all end mutmut's process group and remove the scratch
    # copy (the finally clauses); a background shell starts jobs with SIGINT ignored, so it is
    # reset here too
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, _interrupt)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("modules", nargs="+", metavar="MODULE")
    parser.add_argument("--tests", nargs="+", help="test files instead of the config's list")
    parser.add_argument("--jobs", type=int, default=1, help="mutants tested in parallel")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument("--keep", action="store_true", help="keep the scratch copy")
    parser.add_argument("--nice", type=int, default=10, help="niceness of the mutmut run")
    parser.add_argument("--root", type=Path, default=ROOT, help=argparse.SUPPRESS)
    parser.add_argument("--config", type=Path, default=CONFIG, help=argparse.SUPPRESS)
    parser.add_argument("--equivalent", type=Path, default=EQUIVALENT, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    root = args.root.resolve()
    config = load_config(args.config)
    settings = config["settings"]
    mapping: dict[str, list[str]] = config.get("modules", {})
    equivalents = load_equivalents(args.equivalent)
    try:
        plan = []
        for arg in args.modules:
            module = resolve_module(arg, root, settings["packages"])
            tests = list(args.tests or mapping.get(module, []))
            if not tests:
                raise UsageError(
                    f"no tests for {module}: add it to {args.config.name} or pass --tests"
                )
            missing = [t for t in tests if not (root / t.split("::")[0]).exists()]
            if missing:
                raise UsageError(f"test files of {module} not found: {missing}")
            plan.append((module, tests))
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    reports = []
    try:
        for module, tests in plan:
            if not args.json:
                print(f"mutating {module} against {len(tests)} test files ...", flush=True)
            reports.append(
                run_module(
                    module,
                    tests,
                    root=root,
                    settings=settings,
                    equivalents=equivalents,
                    jobs=args.jobs,
                    nice=args.nice,
                    keep=args.keep,
                )
            )
    except RunError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        print(
            "interrupted: the working tree was never mutated; scratch copy removed", file=sys.stderr
        )
        return 130
    if args.json:
        print(as_json(reports))
    else:
        print_report(reports)
    return 0


if __name__ == "__main__":
    sys.exit(main())
