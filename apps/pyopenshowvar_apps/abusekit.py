"""What the attack tools of the apps share: a ``kvp`` command in its own process, its peak memory,
and the attackers' tally (:mod:`.web.abuse`, :mod:`.heave.abuse`, ``tests/abuse``, ``bench``).

* :class:`AppProcess` — ``kvp ARGS...`` in a subprocess, started once its first line says where
  it serves; its stderr goes to a file, so the tracebacks it printed can be counted;
* :class:`PeakMemory` — a thread sampling a process' resident memory every few ms, so a suite
  sees the peak *during* an attack, not what is left once the attackers have gone;
* :class:`AttackTally` — what the attackers did and saw, their own failures included.

Nothing here asserts.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Self

__all__ = ["AppProcess", "AttackTally", "PeakMemory", "rss_mb"]


@dataclass
class AttackTally:
    """What the attackers did and saw."""

    connections: int = 0
    #: Connections the server closed (or refused) on its own.
    closed_by_server: int = 0
    #: Messages or requests sent, and answers read.
    sent: int = 0
    answers: int = 0
    bytes_sent: int = 0
    #: The attackers' own failures (a connect that failed, an answer that never came): the
    #: suite asserts there are none, so an attack that silently did nothing cannot pass.
    errors: int = 0
    notes: list[str] = field(default_factory=list)

    def error(self, what: str) -> None:
        self.errors += 1
        if len(self.notes) < 10:
            self.notes.append(what)


def rss_mb(pid: int) -> float:
    """Resident set size of ``pid`` in MB (Linux ``/proc``)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024 / 1e6
    raise RuntimeError("no VmRSS")


class PeakMemory:
    """``with PeakMemory(pid) as mem: ...``; then ``mem.peak`` (MB) of what was sampled."""

    def __init__(self, pid: int, period: float = 0.01) -> None:
        self.pid, self.period = pid, period
        self.start = self.peak = rss_mb(pid)
        self.samples = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="peak-rss", daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            try:
                self.peak = max(self.peak, rss_mb(self.pid))
            except (OSError, RuntimeError):
                return  # the process is gone: the suite sees that on its own
            self.samples += 1

    def __enter__(self) -> Self:
        self._thread.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._stop.set()
        self._thread.join(5.0)


class AppProcess:
    """``kvp ARGS...`` in a subprocess; :attr:`first` is its first line (where it serves)."""

    def __init__(self, *args: str, expect: str) -> None:
        self.args, self.expect = list(args), expect
        self.err = tempfile.TemporaryFile(mode="w+")
        self.proc: subprocess.Popen[str] | None = None
        self.first = ""

    def __enter__(self) -> Self:
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

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stderr(self) -> str:
        self.err.seek(0)
        return self.err.read()

    def tracebacks(self) -> int:
        return self.stderr().count("Traceback")

    def stop(self) -> int | None:
        """SIGINT (Ctrl-C) and wait: the exit status, or None if it had to be killed."""
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            return self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
            return None
        finally:
            if self.proc.stdout is not None:
                self.proc.stdout.close()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()
        self.err.close()
