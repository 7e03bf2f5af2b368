"""Lazy package attributes: a package names where each public name lives and imports the
module only when the name is first used (``import pyopenshowvar`` stays fast and a client-only
install never imports what it lacks).

A package keeps its two-line ``__getattr__``/``__dir__`` (so type checkers see them) and hands
the work to :func:`load` and :func:`names`.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

__all__ = ["load", "names"]


def load(package: str, sources: Mapping[str, str], namespace: dict[str, Any], name: str) -> Any:
    """The attribute ``name`` of ``package``, imported from its module in ``sources`` (a
    module name relative to the package) and kept in ``namespace`` for the next use."""
    source = sources.get(name)
    if source is None:
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{package}.{source}"), name)
    namespace[name] = value
    return value


def names(sources: Mapping[str, str], namespace: Mapping[str, Any]) -> list[str]:
    """What ``dir(package)`` lists: the names loaded already and those still to load."""
    return sorted({*namespace, *sources})
