"""What the attack tools of the apps share (:mod:`.web.abuse`, :mod:`.heave.abuse`,
``tests/abuse``, ``bench/app_abuse.py``), on top of the emulator's (:mod:`kukavarproxy_emu.abuse`):

* :class:`AppProcess` — ``kvp ARGS...`` in a subprocess, started once its first line says where
  it serves; its stderr goes to a file, so the tracebacks it printed can be counted;
* :class:`PeakMemory` — a process' peak resident memory *during* an attack (the kernel's
  high-water mark), not what is left once the attackers have gone;
* :class:`ChildProbe` / :func:`run_child_probe` — a bystander in a process of its own, so the
  attackers' event loop (and GIL) does not slow it down;
* :class:`AttackTally` — what the attackers did and saw, their own failures included.

Nothing here asserts.
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Self

from kukavarproxy_emu.abuse import AbuseTally, EmulatorProcess, PeakRss

__all__ = ["AppProcess", "AttackTally", "ChildProbe", "PeakMemory", "run_child_probe"]


@dataclass
class AttackTally(AbuseTally):
    """:class:`~kukavarproxy_emu.abuse.AbuseTally` (connections, requests, replies, wrong,
    errors) and what an attack on an app counts besides."""

    #: Connections the server closed (or refused) on its own.
    closed_by_server: int = 0
    bytes_sent: int = 0
    notes: list[str] = field(default_factory=list)

    def error(self, what: str) -> None:
        """One failure of the attacker itself (a connect that failed, an answer that never
        came): the suites assert there are none, so an attack that did nothing cannot pass."""
        self.errors += 1
        if len(self.notes) < 10:
            self.notes.append(what)


class PeakMemory:
    """``with PeakMemory(pid) as mem: ...``; then ``mem.peak``: the highest resident memory
    (MB) of process ``pid`` while the block ran, and ``mem.start``, what it had at the start.
    The kernel keeps the high-water mark (``VmHWM``, reset on entry through ``clear_refs``),
    so no peak between two samples is missed (Linux)."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self._rss = PeakRss(pid)  # the emulator suite's reader of the same two figures
        self.start = self.peak = 0.0

    def __enter__(self) -> Self:
        self.start = self._rss.reset()  # a new high-water mark, from the RSS now
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.peak = self._rss.peak_mb()


class AppProcess(EmulatorProcess):
    """``kvp ARGS...`` in a subprocess (``with`` stops it, SIGTERM); :attr:`first` is its first
    line, which must start with ``expect``."""

    def __init__(self, *args: str, expect: str) -> None:
        super().__init__(*args)
        self.expect = expect
        self.err = tempfile.TemporaryFile(mode="w+")
        self.first = ""

    def start(self) -> Self:
        kvp = str(Path(sys.executable).with_name("kvp"))
        self.proc = subprocess.Popen(
            [kvp, *self.args],
            stdout=subprocess.PIPE,
            stderr=self.err,
            text=True,
            env={**os.environ, "PYTHONUNBUFFERED": "1"},
        )
        assert self.proc.stdout is not None
        self.first = self.proc.stdout.readline().strip()
        if not self.first.startswith(self.expect):
            self.stop()
            raise RuntimeError(f"kvp {' '.join(self.args)} did not start: {self.first!r}")
        return self

    def stderr(self) -> str:
        self.err.seek(0)
        return self.err.read()

    def tracebacks(self) -> int:
        return self.stderr().count("Traceback")

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        super().__exit__(exc_type, exc, tb)
        if self.proc is not None and self.proc.stdout is not None:
            self.proc.stdout.close()
        self.err.close()


class ChildProbe:
    """``python -m MODULE ARGS...`` (whose main is :func:`run_child_probe`): ``await start()``
    returns once it is connected, ``await result()`` gives what it measured (JSON). Monotonic
    clocks agree across the processes of one machine, so its samples can be split by when an
    attack ran."""

    def __init__(self, module: str, *args: str, seconds: float) -> None:
        self.module, self.args, self.seconds = module, args, seconds
        self.proc: asyncio.subprocess.Process | None = None

    async def start(self) -> None:
        self.proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", self.module, *self.args, stdout=asyncio.subprocess.PIPE
        )
        assert self.proc.stdout is not None
        if await self.proc.stdout.readline() != b"ready\n":
            raise RuntimeError(f"{self.module} did not start")

    async def result(self) -> Any:
        assert self.proc is not None
        out, _ = await asyncio.wait_for(self.proc.communicate(), self.seconds + 30)
        if self.proc.returncode != 0:
            raise RuntimeError(f"{self.module} failed (exit {self.proc.returncode})")
        return json.loads(out)


def run_child_probe(probe: Callable[[Callable[[], None]], Coroutine[Any, Any, Any]]) -> None:
    """The child's side of :class:`ChildProbe`: ``probe(ready)`` calls ``ready()`` once
    connected; what it returns is printed as JSON."""
    out = asyncio.run(probe(lambda: print("ready", flush=True)))
    print(json.dumps(out))
