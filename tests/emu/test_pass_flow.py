"""Dead statements of an SPS pass followed by the next pass (``krl.pass_flow``), by hand."""

from __future__ import annotations

from kukavarproxy_emu.krl.pass_flow import Path, Unit, dead_units, overlaps


def assign(target: Path, *sources: Path) -> Unit:
    return Unit(tuple(sources), (target,), (target,))


def counter(path: Path) -> Unit:
    """IF P < L THEN P = P + 1 ELSE P = 1 ENDIF: reads P, writes it on both ways."""
    return Unit((path,), (path, path), (path,))


W, G = ("W",), ("G",)
C, A, R = ("W", "C"), ("W", "A"), ("W", "R")


def test_the_snapshot_shape_defers_everything_but_its_counter() -> None:
    units = [counter(C), assign(A, ("$AXIS_ACT",)), assign(R, ("$TORQUE", 2)), assign(G, W)]
    assert dead_units(units) == [False, True, True, True]


def test_a_copy_the_next_pass_reads_first_is_live() -> None:
    # the next pass reads W.A (into X) before it copies W.A again: W.A is live (X is not:
    # the next pass overwrites it unread)
    units = [assign(("X",), A), assign(A, ("$AXIS_ACT",))]
    assert dead_units(units) == [True, False]


def test_a_write_on_one_way_only_does_not_kill() -> None:
    # IF F THEN W.R = V ENDIF: when F is false the next pass leaves this pass's W.R visible
    maybe = Unit((("F",), ("V",)), (R,), ())
    assert dead_units([maybe]) == [False]
    assert dead_units([assign(R, ("V",))]) == [True]


def test_a_whole_structure_kills_its_members_and_is_read_by_them() -> None:
    assert dead_units([assign(C, ("N",)), assign(W, ("V",))]) == [True, True]
    # W is read (its member C) by a statement that is live (it reads itself): live
    assert dead_units([assign(W, ("V",)), assign(("Y",), ("Y",), C)]) == [False, False]
    assert overlaps(("W",), ("W", "C")) and overlaps(("W", "C"), ("W",))
    assert not overlaps(("W", "C"), ("W", "A")) and not overlaps(("T", 1), ("T", 2))


def test_a_value_read_only_by_dead_statements_is_dead_too() -> None:
    # X = T[1] is overwritten by the next pass unread, so T[1] feeds nothing anyone sees
    units = [assign(("T", 0), ("S",)), assign(("T", 1), ("S",)), assign(("X",), ("T", 0))]
    assert dead_units(units) == [True, True, True]
    # Y = Y + T[1] reads its own value: live, and so is the T[1] it reads
    units = [assign(("T", 0), ("S",)), assign(("Y",), ("Y",), ("T", 0))]
    assert dead_units(units) == [False, False]
