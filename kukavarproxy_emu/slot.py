"""A compiled variable path of the store: one part of one variable, read and set without parsing.

:class:`~.store.VariableStore` takes names as text, so every access parses the name, finds the
declaration, the element and the member types, and (for a typed value) converts and checks it
again. That is right for requests from the network; the KRL interpreter's compiled statement
plans (:mod:`.krl.plan`) instead touch the same few paths every cycle (an SPS snapshot copies
a few dozen of them each 12 ms). A :class:`Slot` resolves its path once and then applies the
store's own rules to it: lazy values are filled before a read or a write, a value put at a member path
merges as KRL does (:func:`~.values.rebuild`), declared limits are checked, the read cache and
the change counters move exactly as :meth:`VariableStore.set_system` moves them.

A slot belongs to one declaration: :meth:`Slot.current` is False once the variable was
declared anew (a data list loaded later), and its user compiles it again.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pyopenshowvar.krl import KrlValue, Struct

from .names import Var, parse_name
from .values import Refused, check, check_ranges, rebuild

if TYPE_CHECKING:
    from .store import VariableStore

__all__ = ["Slot"]


class Slot:
    """``Slot.compile(store, name)``: the part ``name`` of a declared variable (not a whole array, not
    a character of a text)."""

    __slots__ = ("chain", "declared", "index", "members", "name", "store", "type_name", "var")

    def __init__(self, store: VariableStore, var: Var, index: int, members: tuple[str, ...]):
        self.store, self.var, self.index, self.members = store, var, index, members
        #: The store's declarations (``declared.get(var.name) is var``: still current).
        self.declared = store.declared
        self.chain = var.chain(store.registry, members)
        self.type_name = self.chain[-1][1]
        self.name = var.name + "".join(f".{m}" for m in members)

    @classmethod
    def compile(cls, store: VariableStore, name: str) -> Slot | None:
        """The slot of ``name``, or None for what it does not cover (an unknown name, a whole
        array, a text or one of its characters, a bad index or member: the store's text
        interface words those)."""
        path = parse_name(name)
        var = store.declaration(path.base) if path is not None else None
        if path is None or var is None or var.text_len or path.index == ():
            return None
        try:
            return cls(store, var, var.slot(path), path.members)
        except Refused:
            return None

    def current(self) -> bool:
        """Still the declaration the slot was compiled for."""
        return self.declared.get(self.var.name) is self.var

    def get(self) -> KrlValue | None:
        """The value, None when it is not initialised."""
        store, base = self.store, self.var.name
        store.fill_stale(base)  # a lazy reading: fill it first
        value: KrlValue | None = self.var.elems[self.index]
        for member in self.members:
            value = value._members.get(member) if isinstance(value, Struct) else None
        return value

    def set(self, value: KrlValue, *, valid: bool = False) -> None:
        """Put ``value`` (already of the slot's kind, as KRL converts: see
        :func:`~.krl.runtime.convert`) there; ``valid``: it is a value of the slot's very type
        read from the store, not checked again. Raises :class:`Refused` (nothing changed)."""
        var, store = self.var, self.store
        store.fill_stale(var.name)  # a pending value first, then this write over it
        if not valid:
            check(value, *self.chain[-1], store.registry)
        old = var.elems[self.index]
        members = self.members
        if (
            len(members) == 1
            and type(old) is Struct
            and members[0] in old._members
            and not isinstance(value, Struct)
        ):
            # one member of a plain STRUC replaced: a copy of the members with the new value,
            # in their order (what rebuild() makes, without merging or re-sorting): values
            # are shared, never changed, so a variable copied from this one keeps its own
            new: KrlValue = Struct._new(old._type_name, {**old._members, members[0]: value})
        else:
            new = rebuild(old, self.chain, members, value)
        check_ranges(var.ranges, var.name, new)
        var.elems[self.index] = new
        store.changed(var, self.index)
