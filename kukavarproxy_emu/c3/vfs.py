"""The emulated controller's file system for C3 Bridge file messages: in memory, confined, bounded.

Paths are KRC paths: ``KRC:\\R1\\Program\\CELL.SRC`` (``/`` accepted for ``\\``, any case), or,
where the spec allows a module path, ``/R1/CELL`` (:meth:`VirtualFS.resolve_module`). Nothing
here touches the host's disk: a path is a key in a dict. Anything that could name a host file
or climb out of ``KRC:\\`` — another drive (``C:\\``), a UNC share (``\\\\host\\x``), a host path
(``/etc/passwd``), ``..`` or ``.`` components, characters Windows forbids — is refused with
``ErrorArgument``, before any lookup.

Names compare case-insensitively and keep the case they were created with (as on Windows).
Every size is bounded (:class:`Limits`): one file, the number of files and directories, all
bytes together, and the path length (Windows' MAX_PATH), so a client cannot grow the
emulator's memory without bound.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from importlib import resources

from pyopenshowvar.c3.constants import ErrorCode, ItemAttribute, ItemType

__all__ = ["Limits", "VFile", "VfsError", "VirtualFS", "filetime"]

ROOT = "KRC:"
#: Directories a KRC4 has, created empty (plus the shipped programs in R1\Program).
SEED_DIRS = ("R1", "R1\\Program", "R1\\System", "R1\\TP", "R1\\Mada", "STEU", "STEU\\Mada")
_FORBIDDEN = set('<>:"|?*') | {chr(c) for c in range(32)}
#: Seconds between 1601-01-01 (FILETIME's epoch) and 1970-01-01.
_EPOCH_DELTA = 11_644_473_600


def filetime(unix: float) -> int:
    """Windows FILETIME ticks (100 ns since 1601) of a Unix time."""
    return int((unix + _EPOCH_DELTA) * 10_000_000)


@dataclass(frozen=True)
class Limits:
    """What one emulated controller stores at most."""

    file_size: int = 1024 * 1024
    files: int = 512
    directories: int = 256
    total_bytes: int = 16 * 1024 * 1024
    #: Characters of a whole path (Windows MAX_PATH is 260).
    path_length: int = 260


class VfsError(Exception):
    """A refused file operation; ``code`` is the C3 error code to answer with."""

    def __init__(self, code: ErrorCode, message: str) -> None:
        super().__init__(message)
        self.code = code


@dataclass
class VFile:
    """One file: its path as created, its bytes, attributes and times (Unix seconds)."""

    path: str
    data: bytes
    attributes: int = ItemAttribute.ARCHIVE
    created: float = field(default_factory=time.time)
    modified: float = field(default_factory=time.time)
    accessed: float = field(default_factory=time.time)

    @property
    def item_type(self) -> int:
        ext = self.path.rsplit(".", 1)[-1].upper() if "." in self.path else ""
        return int(ItemType.MODULE if ext in ("SRC", "DAT", "SUB") else ItemType.TEXT_FILE)


def _refuse(path: str, why: str) -> VfsError:
    return VfsError(ErrorCode.ARGUMENT, f"path {path[:80]!r} refused: {why}")


def _parent(key: str) -> str:
    return key.rsplit("\\", 1)[0] if "\\" in key else ROOT


class VirtualFS:
    """An in-memory ``KRC:\\`` tree (see the module docstring for the rules)."""

    def __init__(self, limits: Limits | None = None, *, seed: bool = True) -> None:
        self.limits = limits or Limits()
        self.files: dict[str, VFile] = {}
        #: key (upper case) → directory path as created; the root is ``KRC:``.
        self.dirs: dict[str, str] = {ROOT: ROOT}
        self.total = 0
        if seed:
            for d in SEED_DIRS:
                self.mkdir(f"{ROOT}\\{d}")
            self._seed_programs()

    # ------------------------------------------------------------------ paths

    def normalize(self, path: str) -> str:
        """``krc:/r1/program/x.src`` → ``KRC:\\r1\\program\\x.src``; refuses what leaves KRC:."""
        if len(path) > self.limits.path_length:
            raise _refuse(path, f"longer than {self.limits.path_length} characters")
        text = path.replace("/", "\\")
        if text.startswith("\\\\"):
            raise _refuse(path, "network (UNC) paths are not on the controller")
        if not text[:4].upper() == ROOT:
            drive = text[:2] if len(text) > 1 and text[1] == ":" else ""
            if drive:
                raise _refuse(path, f"drive {drive} is the host's; only KRC:\\ is reachable")
            raise _refuse(path, "not a KRC path (write KRC:\\R1\\Program\\NAME.SRC)")
        rest = text[4:].strip("\\")
        parts = [p for p in rest.split("\\")] if rest else []
        for part in parts:
            if part in ("", ".", ".."):
                raise _refuse(path, f"component {part!r} is not allowed")
            if set(part) & _FORBIDDEN or part.endswith((" ", ".")):
                raise _refuse(path, f"component {part!r} has a character Windows forbids")
        return "\\".join([ROOT, *parts])

    @staticmethod
    def key(normal: str) -> str:
        return normal.upper()

    def resolve_module(self, name: str) -> str:
        """The key of a module's ``.src``: ``/R1/CELL``, ``/R1/CELL.SRC``, ``KRC:\\...\\CELL``."""
        text = name.strip()
        if text.upper().startswith(("/R1/", "\\R1\\")):
            stem = text[4:].replace("/", "\\")
            found = self._find_module(stem)
            if found is None:
                raise VfsError(ErrorCode.GENERAL, f"no module {text} under KRC:\\R1")
            return found
        key = self.key(self.normalize(text))
        if key in self.files and key.endswith((".SRC", ".SUB")):
            return key
        if key + ".SRC" in self.files:
            return key + ".SRC"
        raise VfsError(ErrorCode.GENERAL, f"no module {text}")

    def _find_module(self, stem: str) -> str | None:
        self.normalize(f"{ROOT}\\R1\\{stem}")  # same component rules
        want = stem.upper()
        if not want.endswith((".SRC", ".SUB")):
            want += ".SRC"
        first = f"{ROOT}\\R1\\PROGRAM\\{want}"
        if first in self.files:
            return first
        hits = sorted(k for k in self.files if k.startswith(f"{ROOT}\\R1\\") and k.endswith(want))
        return next((k for k in hits if k.endswith("\\" + want)), None)

    def full_name(self, path: str) -> str:
        """#27: a module path to the file's KRC path (the spec's ``/R1/TEST.SRC`` example)."""
        text = path.strip()
        if text.upper().startswith(("/R1/", "\\R1\\")):
            found = self._find_module(text[4:].replace("/", "\\"))
            if found is not None:
                return self.files[found].path
            stem = text[4:].replace("/", "\\").upper()
            return f"{ROOT}\\R1\\PROGRAM\\{stem}"
        normal = self.normalize(text)
        hit = self.files.get(self.key(normal))
        return hit.path if hit else normal

    def krc_name(self, path: str) -> str:
        """#28: ``KRC:\\R1\\PROGRAM\\TEST.SRC`` → ``/R1/TEST.SRC`` (modules under R1 only)."""
        key = self.key(self.normalize(path))
        for prefix in (f"{ROOT}\\R1\\PROGRAM\\", f"{ROOT}\\R1\\"):
            if key.startswith(prefix):
                return "/R1/" + key[len(prefix) :].replace("\\", "/")
        raise VfsError(ErrorCode.GENERAL, f"{path} has no module path (not under KRC:\\R1)")

    # ------------------------------------------------------------------ operations

    def read(self, path: str) -> VFile:
        key = self.key(self.normalize(path))
        hit = self.files.get(key)
        if hit is None:
            what = "is a directory" if key in self.dirs else "does not exist"
            raise VfsError(ErrorCode.GENERAL, f"{path} {what}")
        hit.accessed = time.time()
        return hit

    def write(self, path: str, data: bytes, *, overwrite: bool, force: bool = False) -> VFile:
        normal = self.normalize(path)
        key = self.key(normal)
        if len(data) > self.limits.file_size:
            raise VfsError(
                ErrorCode.MEMORY, f"{len(data)} bytes exceed the {self.limits.file_size} per file"
            )
        if key in self.dirs:
            raise VfsError(ErrorCode.GENERAL, f"{path} is a directory")
        if _parent(key) not in self.dirs:
            raise VfsError(
                ErrorCode.GENERAL, f"directory {normal.rsplit(chr(92), 1)[0]} does not exist"
            )
        old = self.files.get(key)
        if old is not None:
            if not overwrite:
                raise VfsError(ErrorCode.GENERAL, f"{old.path} exists (overwrite not requested)")
            if old.attributes & ItemAttribute.READ_ONLY and not force:
                raise VfsError(ErrorCode.ACCESS, f"{old.path} is read-only")
        elif len(self.files) >= self.limits.files:
            raise VfsError(
                ErrorCode.MEMORY, f"the controller holds {self.limits.files} files at most"
            )
        grown = self.total - (len(old.data) if old else 0) + len(data)
        if grown > self.limits.total_bytes:
            raise VfsError(ErrorCode.MEMORY, f"over the {self.limits.total_bytes} bytes of storage")
        now = time.time()
        new = VFile(normal if old is None else old.path, bytes(data), created=now, modified=now)
        if old is not None:
            new.created, new.attributes = old.created, old.attributes
        self.files[key] = new
        self.total = grown
        return new

    def delete(self, path: str, *, force: bool = False) -> None:
        key = self.key(self.normalize(path))
        hit = self.files.get(key)
        if hit is None:
            if key in self.dirs and key != ROOT:
                if any(_parent(k) == key for k in [*self.files, *self.dirs]):
                    raise VfsError(ErrorCode.GENERAL, f"directory {path} is not empty")
                del self.dirs[key]
                return
            raise VfsError(ErrorCode.GENERAL, f"{path} does not exist")
        if hit.attributes & ItemAttribute.READ_ONLY and not force:
            raise VfsError(ErrorCode.ACCESS, f"{hit.path} is read-only")
        del self.files[key]
        self.total -= len(hit.data)

    def mkdir(self, path: str) -> None:
        normal = self.normalize(path)
        key = self.key(normal)
        if key in self.dirs:
            return
        if key in self.files:
            raise VfsError(ErrorCode.GENERAL, f"{path} is a file")
        if _parent(key) not in self.dirs:
            raise VfsError(ErrorCode.GENERAL, f"the parent of {path} does not exist")
        if len(self.dirs) > self.limits.directories:
            raise VfsError(ErrorCode.MEMORY, f"{self.limits.directories} directories at most")
        self.dirs[key] = normal

    def copy(self, source: str, destination: str, *, overwrite: bool, move: bool) -> None:
        src = self.read(source)
        dst = self.write(destination, src.data, overwrite=overwrite)
        dst.attributes = src.attributes
        if move:
            self.delete(source, force=True)

    def set_attributes(self, path: str, attributes: int, mask: int) -> None:
        hit = self.read(path)
        keep = ItemAttribute.DIRECTORY
        hit.attributes = ((hit.attributes & ~mask) | (attributes & mask)) & ~keep

    def listing(self, path: str, *, recursive: bool) -> list[tuple[str, VFile | None]]:
        """(path, file or None for a directory) of the items under ``path``, sorted."""
        key = self.key(self.normalize(path))
        if key not in self.dirs:
            raise VfsError(ErrorCode.GENERAL, f"directory {path} does not exist")
        prefix = key + "\\"

        def wanted(k: str) -> bool:
            return k.startswith(prefix) and (recursive or "\\" not in k[len(prefix) :])

        items: list[tuple[str, VFile | None]] = [
            (d + "\\", None) for k, d in self.dirs.items() if wanted(k)
        ]
        items += [(f.path, f) for k, f in self.files.items() if wanted(k)]
        return sorted(items, key=lambda item: item[0].upper())

    def is_dir(self, path: str) -> bool:
        return self.key(self.normalize(path)) in self.dirs

    # ------------------------------------------------------------------ seed

    def _seed_programs(self) -> None:
        """The shipped KRL programs in ``KRC:\\R1\\Program`` (``/R1/FOLLOW`` selects one)."""
        folder = resources.files("kukavarproxy_emu") / "programs"
        for entry in sorted(folder.iterdir(), key=lambda e: e.name):
            if entry.name.lower().endswith((".src", ".dat", ".sub")):
                data = entry.read_bytes()
                self.write(f"{ROOT}\\R1\\Program\\{entry.name}", data, overwrite=True)
