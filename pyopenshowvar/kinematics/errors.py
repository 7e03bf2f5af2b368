"""Errors of the kinematics package (part of the pyopenshowvar exception tree)."""

from __future__ import annotations

from ..errors import KvpError

__all__ = ["UnreachableError"]


class UnreachableError(KvpError, ValueError):
    """A pose has no inverse-kinematics solution, or none inside the software limits / S / T.

    The message says which: out of reach (and by how much), or which solutions exist and why
    each was refused, so a caller steering a robot knows what to relax.
    """
