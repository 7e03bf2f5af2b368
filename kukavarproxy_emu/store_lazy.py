"""Lazy values of the variable store: variables marked stale and filled when first looked at.

A mixin of :class:`~.store.VariableStore`. The simulated robot publishes its readings this
way (:meth:`LazyValues.defer`): each cycle it marks them stale, and the first :meth:`read`,
:meth:`get` or compiled :class:`~.slot.Slot` access of one of them calls the fill that sets
its group. A robot nobody reads then costs no readings.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

__all__ = ["LazyValues"]


class LazyValues:
    """Stale groups of variables and the fills that set them (see the module)."""

    mutations: int

    def _init_lazy(self) -> None:
        # stale base name -> (its group, the fill that sets the whole group)
        self._stale: dict[str, tuple[frozenset[str], Callable[[], None]]] = {}
        #: Of :attr:`mutations`, the marks of lazy values as stale (:meth:`defer`), not
        #: changes as such.
        self.stale_marks = 0

    def _bump(self, base: str) -> None:
        raise NotImplementedError  # provided by the store

    def defer(self, names: Iterable[str], fill: Callable[[], None]) -> None:
        """Mark the variables ``names`` stale: the first :meth:`read` or :meth:`get` of any of
        them calls ``fill()`` once, which sets them (e.g. with :meth:`set_system`).

        The simulated robot computes its published readings this way only when someone
        looks: a robot nobody reads costs no formatting. The names form a group filled
        together; several groups may be stale at once (a reader of ``$AXIS_ACT`` does not pay
        for the forward kinematics of ``$POS_ACT``). Deferring a name again replaces the
        earlier, unfilled group it was in.
        """
        # a frozenset is taken as it is (the robot defers the same names every cycle)
        group = (
            names if isinstance(names, frozenset) else frozenset(n.strip().upper() for n in names)
        )
        entry = (group, fill)
        stale = self._stale
        self.stale_marks += len(group)
        for name in group:
            stale[name] = entry
            self._bump(name)  # its value changes when it is filled

    def fill_stale(self, base: str) -> None:
        """Fill the lazy value ``base`` if it is stale (see :meth:`defer`); else nothing."""
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
            group, fill = entry
            for name in group:
                if stale.get(name) is entry:
                    del stale[name]
            fill()
            if base is not None:
                return
