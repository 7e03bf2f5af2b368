"""Lazy values of the variable store: variables marked stale and filled when first looked at.

A mixin of :class:`~.store.VariableStore`. The simulated robot publishes its readings this
way (:meth:`LazyValues.defer`): each cycle it marks them stale, and the first :meth:`read`,
:meth:`get` or compiled :class:`~.slot.Slot` access of one of them calls the fill that sets
its group. A robot nobody reads then costs no readings.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping

__all__ = ["LazyValues", "Maker", "Stale"]


#: What a capture returns: called later, it gives the values (base name -> value, a whole
#: array as a list) the group's fill would have set at the moment of the capture.
Maker = Callable[[], Mapping[str, object]]


class Stale:
    """One stale group: its names, the fill that sets them now, and (optional) the capture
    that freezes what the fill depends on, for a :data:`Maker` to compute later."""

    __slots__ = ("capture", "fill", "group")

    def __init__(
        self, group: frozenset[str], fill: Callable[[], None], capture: Callable[[], Maker] | None
    ) -> None:
        self.group, self.fill, self.capture = group, fill, capture


class LazyValues:
    """Stale groups of variables and the fills that set them (see the module)."""

    mutations: int

    def _init_lazy(self) -> None:
        # stale base name -> its group's entry
        self._stale: dict[str, Stale] = {}
        #: Of :attr:`mutations`, the marks of lazy values as stale (:meth:`defer`), not
        #: changes as such.
        self.stale_marks = 0

    def _bump(self, base: str) -> None:
        raise NotImplementedError  # provided by the store

    def defer(
        self,
        names: Iterable[str],
        fill: Callable[[], None],
        capture: Callable[[], Maker] | None = None,
    ) -> Stale:
        """Mark the variables ``names`` stale: the first :meth:`read` or :meth:`get` of any of
        them, and any write to one of them, calls ``fill()`` once, which sets them (e.g. with
        :meth:`set_system`). Returns the group's entry (for :meth:`forget`).

        The simulated robot computes its published readings this way only when someone
        looks: a robot nobody reads costs no formatting. The names form a group filled
        together; several groups may be stale at once (a reader of ``$AXIS_ACT`` does not pay
        for the forward kinematics of ``$POS_ACT``). Deferring a name again replaces the
        earlier, unfilled group it was in.

        ``capture()``, if given, freezes now whatever the fill depends on and returns a
        :data:`Maker` that computes the same values later, whatever happened since (see
        :meth:`capture`); it must not change anything.
        """
        # a frozenset is taken as it is (the robot defers the same names every cycle)
        group = (
            names if isinstance(names, frozenset) else frozenset(n.strip().upper() for n in names)
        )
        entry = Stale(group, fill, capture)
        stale = self._stale
        self.stale_marks += len(group)
        for name in group:
            stale[name] = entry
            self._bump(name)  # its value changes when it is filled
        return entry

    def is_stale(self, base: str) -> bool:
        """Whether ``base`` (upper-case, no index) waits for its fill."""
        return base in self._stale

    def capture(self, base: str) -> Maker | None:
        """The values of the stale group of ``base`` as its fill would set them now, to be
        made later (a compiled SPS pass copies a reading it may never need: it keeps the
        maker instead). None when ``base`` is not stale or its group cannot be captured."""
        entry = self._stale.get(base)
        if entry is None or entry.capture is None:
            return None
        return entry.capture()

    def forget(self, entry: Stale) -> bool:
        """Drop the names still marked by ``entry`` without filling them: their owner knows
        the values will be overwritten before anyone can read them (a dead write). False
        when none was (the group was filled or deferred anew)."""
        stale = self._stale
        dropped = False
        for name in entry.group:
            if stale.get(name) is entry:
                del stale[name]
                dropped = True
        return dropped

    def renew(self, entry: Stale) -> bool:
        """Count the names of ``entry`` as changed again, still waiting for the same fill
        (the owner changed what it will set); False, nothing done, when they do not all
        wait for it any more."""
        stale = self._stale
        group = entry.group
        if any(stale.get(name) is not entry for name in group):
            return False
        self.stale_marks += len(group)
        for name in group:
            self._bump(name)
        return True

    def fill_stale(self, base: str) -> None:
        """Fill the lazy value ``base`` if it is stale (see :meth:`defer`); else nothing.
        Called before every read and every write of ``base``."""
        if self._stale and base in self._stale:
            self._refresh(base)

    def _refresh(self, base: str | None = None) -> None:
        """Fill the group of ``base`` (None: every stale group)."""
        stale = self._stale
        while stale:
            key = base if base is not None else next(iter(stale))
            entry = stale.get(key)
            if entry is None:
                return
            for name in entry.group:
                if stale.get(name) is entry:
                    del stale[name]
            entry.fill()
            if base is not None:
                return
