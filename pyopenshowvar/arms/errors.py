"""Errors of the arms package (part of the pyopenshowvar exception tree)."""

from __future__ import annotations

from ..errors import KvpError

__all__ = ["ArmFileError", "UnknownArmError"]


class ArmFileError(KvpError, ValueError):
    """An arm description (TOML or URDF) that cannot be used, with the file and key named.

    One error per file, naming the first problem: ``arm.toml: joint 3: unknown key 'lenght'
    (did you mean 'length'?)``, so a typo is found at once instead of silently ignored.
    """


class UnknownArmError(KvpError, LookupError):
    """A name that is neither a catalogue entry nor an existing file."""
