"""The emulator under attack as a process of its own: started, stopped, its memory measured.

:class:`EmulatorProcess` runs ``kukavarproxy-emu`` in a subprocess, so its resident memory is
the emulator's own; :class:`PeakRss` reads a process's memory high-water mark since a reset,
so a test sees the peak *during* an abuse, not what is left after the abusers went away.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path
from types import TracebackType
from typing import Self

__all__ = ["EmulatorProcess", "PeakRss"]


class EmulatorProcess:
    """``kukavarproxy-emu --port 0 ARGS...`` in a subprocess; ``with`` stops it (SIGTERM)."""

    def __init__(self, *args: str, env: dict[str, str] | None = None) -> None:
        self.args = list(args)
        self.env = env
        self.proc: subprocess.Popen[str] | None = None
        self.host = "127.0.0.1"
        self.port = 0

    def start(self) -> Self:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "kukavarproxy_emu", "--port", "0", *self.args],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            env={**os.environ, **(self.env or {}), "PYTHONUNBUFFERED": "1"},
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline().strip()
        if not line.startswith("listening on "):
            self.proc.kill()
            raise RuntimeError(f"kukavarproxy-emu did not start: {line!r}")
        host, _, port = line.removeprefix("listening on ").rpartition(":")
        self.host, self.port = host, int(port)
        return self

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def rss_mb(self) -> float:
        """Resident set size in MB (Linux ``/proc``)."""
        for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024 / 1e6
        raise RuntimeError("no VmRSS")

    def stop(self) -> int | None:
        """SIGTERM and wait; the exit status (None if it had to be killed)."""
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
            return None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


class PeakRss:
    """The peak resident memory (MB) of process ``pid`` since the last :meth:`reset`."""

    def __init__(self, pid: int) -> None:
        self.pid = pid

    def _status(self, key: str) -> float:
        for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
            if line.startswith(key):
                return int(line.split()[1]) * 1024 / 1e6
        raise RuntimeError(f"no {key} for process {self.pid}")

    def rss_mb(self) -> float:
        return self._status("VmRSS:")

    def reset(self) -> float:
        """Start a new peak at the current RSS (``clear_refs`` 5); returns that RSS."""
        Path(f"/proc/{self.pid}/clear_refs").write_text("5")
        return self.rss_mb()

    def peak_mb(self) -> float:
        return self._status("VmHWM:")
