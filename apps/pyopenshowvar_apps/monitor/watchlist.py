"""The monitor's watch list: variable names saved as JSON and restored at the next start.

The file is ``$KVP_MONITOR_FILE`` or ``--watch-file``, else ``monitor.json`` in
``$XDG_CONFIG_HOME/kvp`` (``~/.config/kvp``)::

    {"version": 1, "watch": ["MYAXIS", "$OV_PRO"]}

A missing or unreadable file gives the default list; saving creates the folder.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

DEFAULT_WATCH = ("MYAXIS", "$OV_PRO")


def default_watch_file() -> Path:
    env = os.environ.get("KVP_MONITOR_FILE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "kvp" / "monitor.json"


class WatchList:
    """An ordered list of unique names (case kept, compared case-insensitively) with a file."""

    def __init__(self, path: Path | None, names: list[str] | None = None) -> None:
        self.path = path
        self.names: list[str] = []
        for n in names or []:
            self.add(n)

    @classmethod
    def load(cls, path: Path | None) -> WatchList:
        """The saved list, or the defaults when there is no (valid) file."""
        if path is not None and path.exists():
            try:
                data = json.loads(path.read_text(encoding="utf-8"))
                names = [str(n) for n in data.get("watch", [])]
                return cls(path, names)
            except (OSError, ValueError, AttributeError):
                pass
        return cls(path, list(DEFAULT_WATCH))

    def save(self) -> None:
        if self.path is None:
            return
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text(json.dumps({"version": 1, "watch": self.names}, indent=2), encoding="utf-8")
        tmp.replace(self.path)

    def add(self, name: str) -> bool:
        name = name.strip()
        if not name or name.upper() in (n.upper() for n in self.names):
            return False
        self.names.append(name)
        return True

    def remove(self, name: str) -> bool:
        for n in self.names:
            if n.upper() == name.upper():
                self.names.remove(n)
                return True
        return False
