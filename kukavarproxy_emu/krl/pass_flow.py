"""Which statements of an SPS pass nobody can see when the next pass follows (dead writes).

A submit program's ``LOOP`` body runs once per cycle. When the next pass follows before anyone
looks at the variables (the lazy pass of :mod:`.lazy_pass` makes every look a trigger), a
statement of the first pass is **dead** if every path it writes is written again, on every
way through, before any statement that runs reads it: its value is never seen. An SPS
snapshot's copies are dead this way (the next pass copies again before ``CELL = CELL_W``
reads them), its pass counter is not (the next pass reads it to count on).

The analysis works on :class:`Unit` s, one per top-level statement of the body, with the
paths each reads and writes as keys: ``(BASE,)`` is a whole variable, ``(BASE, i, "A1")``
element ``i`` (flat, 0-based) and member ``A1``. Two paths overlap when one is a prefix of
the other; a write *kills* a path it covers (a prefix of it) only where it happens on every
way through its unit (both branches of an ``IF``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ..slot import Slot

__all__ = ["Path", "Unit", "dead_units", "overlaps", "slot_path"]

Path = tuple[str | int, ...]


def slot_path(slot: Slot) -> Path:
    """The key of the part of a variable ``slot`` addresses."""
    index: tuple[int, ...] = (slot.index,) if slot.var.is_array else ()
    return (slot.var.name, *index, *slot.members)


def overlaps(a: Path, b: Path) -> bool:
    """One path is part of the other (or they are the same)."""
    n = min(len(a), len(b))
    return a[:n] == b[:n]


def _covers(kill: Path, path: Path) -> bool:
    return path[: len(kill)] == kill  # a shorter path is never equal to a longer kill


@dataclass(frozen=True, slots=True)
class Unit:
    """One statement of the pass: what it reads, writes, and writes on every way through."""

    reads: tuple[Path, ...]
    writes: tuple[Path, ...]
    kills: tuple[Path, ...]


def dead_units(units: Sequence[Unit]) -> list[bool]:
    """For each unit of a pass: is it dead when the same pass runs again right after it?

    The pass is followed by a second copy of itself, after which everything is seen (the
    second copy's units are all live). Working backwards through the first copy, a unit is
    dead when each of its writes is killed by a later unit that runs (live) before a live
    unit reads it. A dead unit neither reads nor kills: it does not run.
    """
    n = len(units)
    dead = [False] * n
    for i in range(n - 1, -1, -1):
        later = [u for j, u in enumerate(units) if j > i and not dead[j]] + list(units)
        dead[i] = bool(units[i].writes) and all(_dead(w, later) for w in units[i].writes)
    return dead


def _dead(path: Path, later: Sequence[Unit]) -> bool:
    for unit in later:
        if any(overlaps(path, r) for r in unit.reads):
            return False  # seen (a unit reads before it writes)
        if any(_covers(k, path) for k in unit.kills):
            return True
    return False  # still there when the second pass has ended: seen
