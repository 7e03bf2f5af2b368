"""The emulator's variable store: KRC4 system variables plus the globals of ``$CONFIG.DAT``.

The server calls :meth:`VariableStore.read` / :meth:`VariableStore.write` with the name and value
text of a KUKAVARPROXY request and gets back exactly what a KRC4 would print; the robot model
and apps use :meth:`~VariableStore.get` / :meth:`~VariableStore.set_system` with typed values.

KRL semantics implemented here (see docs/emulator-variables.md): names are case-insensitive;
``NAME.MEMBER.MEMBER``, ``NAME[i]`` / ``NAME[i,j]`` (1-based, bounds checked) and
``NAME[i].MEMBER`` address parts of a variable; ``NAME[]`` is the whole 1-D array (a CHAR array
prints as one quoted text). A partial aggregate ``{X 10}`` changes only the members it names.

Every write parses and validates first and then swaps in one fully built value, so a reader
never sees a half-written struct and a refused write changes nothing. The store is used from a
single asyncio thread; it has no locks.

The name grammar and array addressing live in :mod:`kukavarproxy_emu.names`, the type rules
(coercion, validation, struct merging) in :mod:`kukavarproxy_emu.values`; this module ties them
to the declared variables and the read-text cache; lazy values (:meth:`~VariableStore.defer`)
are in :mod:`kukavarproxy_emu.store_lazy`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from functools import lru_cache, partial
from importlib.metadata import PackageNotFoundError, version
from typing import Protocol, cast

from pyopenshowvar.errors import KrlValueError
from pyopenshowvar.krl import (
    BUILTIN_TYPES,
    Kind,
    KrlValue,
    Struct,
    TypeRegistry,
    TypeSpec,
    format_krc4,
)
from pyopenshowvar.krl.datfile import DatFile, parse_dat
from pyopenshowvar.sysvars import system_variables

from .default_config import load_default_config
from .names import Var, VarPath, parse_name
from .store_lazy import LazyValues
from .values import CHAR_LEN, Range, Refused, check, check_ranges, coerce, parse_text, rebuild

__all__ = ["Range", "UnknownVariable", "VariableStore", "WriteRefused"]

log = logging.getLogger(__name__)

#: Cached read texts per variable before its cache starts afresh (bounds memory, not speed).
TEXT_CACHE_PATHS = 4096
#: Names :meth:`VariableStore.warm` formats ahead at most (a client polling a few variables
#: every cycle; more names than this are simply formatted when they are read).
HOT_NAMES = 32
#: Elements of the largest array a whole-array read can answer: 2 bytes each at least (one
#: character and a blank as text, one word in mode 2) under the 65 529-byte reply value.
WHOLE_ARRAY_LIMIT = 32_764


@lru_cache(maxsize=65_536)
def _real_word_text(word: int) -> str:
    """A mode-3 word stored in a REAL element, as the KRC prints it (cached: 65 536 at most)."""
    return format_krc4(float(word))


def _proxy_version() -> str:
    try:
        return f"pyopenshowvar {version('pyopenshowvar')}"
    except PackageNotFoundError:  # running from a source tree without metadata
        return "pyopenshowvar"


DEFAULT_INFO = {"@PROXY_TYPE": "KUKAVARPROXY EMULATOR", "@PROXY_VERSION": _proxy_version()}


class UnknownVariable(LookupError):
    """No such variable, index out of bounds, or a value never initialised.

    KUKAVARPROXY 9.0 answers all of these with an empty value and success status.
    """

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.name = name


class WriteRefused(ValueError):
    """A write the controller would refuse; the store is unchanged."""

    def __init__(self, name: str, reason: str) -> None:
        super().__init__(f"write to {name!r} refused: {reason}")
        self.name = name
        self.reason = reason


class _Producer(Protocol):
    """Builds the new value for a target of the given type (parses text or coerces a value)."""

    def __call__(self, spec: TypeSpec, type_name: str) -> KrlValue: ...


class VariableStore(LazyValues):
    """KRL variables by name: typed values inside, KRC4 text at the edges.

    ``strict``: refuse REAL text for INT targets (a KRC converts ``50.0``) and raise on a bad
    declaration in a data list instead of skipping it with a warning. ``default_config``: load
    the bundled ``default_config.dat`` globals (MYAXIS, MYE6ARRAY, the path handshake, ...).
    ``overrides`` replaces initial literals of system variables, e.g. ``{"$MODE_OP": "#T1"}``.
    ``info`` adds or replaces the read-only ``@PROXY_*`` texts.
    """

    def __init__(
        self,
        registry: TypeRegistry | None = None,
        *,
        strict: bool = False,
        system: bool = True,
        default_config: bool = True,
        overrides: Mapping[str, str | Sequence[str]] | None = None,
        info: Mapping[str, str] | None = None,
    ) -> None:
        self.registry = (registry if registry is not None else BUILTIN_TYPES).copy()
        self.strict = strict
        self._vars: dict[str, Var] = {}
        self._info = {**DEFAULT_INFO, **{k.upper(): v for k, v in (info or {}).items()}}
        # read() text per base name and path; dropped whenever the variable changes
        self._text: dict[str, dict[VarPath, str]] = {}
        self._system: set[str] = set()
        #: Changes of any variable so far, and per variable (base name): a KRL pass that read
        #: only unchanged variables and wrote nothing would do exactly the same again.
        self.mutations = 0
        self._init_lazy()  # lazy values (see defer)
        #: Variables declared so far (declared anew included): a compiled path is current
        #: while this has not moved.
        self.declarations = 0
        #: Called before every write from :meth:`write`, :meth:`write_words` and untrusted
        #: :meth:`set_system`: the simulated robot brings a coasting clock up to date first,
        #: so a change from outside its tick is acted on by the next regular tick.
        self.on_write: Callable[[], None] | None = None
        self._versions: dict[str, int] = {}
        # names read since the last warm() and in the cycle before it (see warm)
        self._hot: dict[str, None] = {}
        self._hot_before: dict[str, None] = {}
        if system:
            for sv in system_variables(overrides):
                self.declare(sv.name, sv.type_name, sv.dims, sv.init, sv.read_only, sv.value_range)
                self._system.add(sv.name)
        if default_config:
            self.load_dat(load_default_config())

    # --- declarations ------------------------------------------------------------------------
    def declare(
        self,
        name: str,
        type_name: str,
        dims: tuple[int, ...] = (),
        init: str | Sequence[str] | None = None,
        read_only: bool = False,
        ranges: Range | Mapping[str, Range] | None = None,
        *,
        replace: bool = False,
    ) -> None:
        """Declare a variable; ``init`` is KRL literal text (one per element, or one for all).

        ``type_name`` is the element type; text is ``CHAR`` with ``dims=(length,)``.
        ``ranges`` limits a numeric value (or every element), or maps member paths such as
        ``"CP"`` to limits. Raises ``ValueError`` (or ``KrlValueError``) for a bad declaration.
        """
        key = name.strip().upper()
        path = parse_name(key)
        if path is None or path.index is not None or path.members or key.startswith("@"):
            raise ValueError(f"invalid variable name {name!r}")
        if key in self._vars and (not replace or key in self._system):
            raise ValueError(f"variable {key} is already declared")
        self.fill_stale(key)  # a pending fill sets the old declaration, not the new one
        type_name = type_name.strip().upper()
        sized = CHAR_LEN.match(type_name)
        if sized is not None and not dims:  # "CHAR[32]" is the same as CHAR with dims (32,)
            type_name, dims = "CHAR", (int(sized.group(1)),)
        spec = self.registry.resolve(type_name)
        if spec.kind is Kind.ARRAY or any(d < 1 for d in dims):
            raise ValueError(f"invalid type/dimensions for {key}: {type_name}{list(dims)}")
        if spec.kind is Kind.STR and len(dims) > 1:
            raise ValueError(f"{key}: multi-dimensional CHAR arrays are not supported")
        var = Var(key, type_name, spec, tuple(dims))
        var.ranges = ranges
        texts = [init] if isinstance(init, str) or init is None else list(init)
        if len(texts) > len(var.elems):
            raise ValueError(f"{key}: {len(texts)} initial values for {len(var.elems)} elements")
        chain = var.chain(self.registry, ())
        parsed: dict[str, KrlValue] = {}  # "FALSE" x 4096 is parsed once
        for i, text in enumerate(texts):
            if text is None:
                continue
            if text not in parsed:
                try:
                    parsed[text] = self._parse(*chain[0], text)
                except Refused as exc:
                    raise ValueError(f"initial value of {key}: {exc}") from None
            var.elems[i] = parsed[text]
        if var.is_array and len(texts) == 1 and texts[0] is not None:
            var.elems = [var.elems[0]] * len(var.elems)  # one value for all: no per-element loop
        var.read_only = read_only
        self._vars[key] = var
        self.declarations += 1
        self._text.pop(key, None)
        self._bump(key)

    def load_dat(
        self,
        dat: DatFile | str,
        *,
        all_global: bool | None = None,
        checkpoint: Callable[[], None] | None = None,
    ) -> list[str]:
        """Declare the globals of a data list (text or parsed); returns the names declared.

        In ``$CONFIG.DAT`` (or a list without DEFDAT) every declaration is global; elsewhere
        only ``DECL GLOBAL`` ones in a ``PUBLIC`` list. A later data list may redeclare a user
        global (your own $CONFIG.DAT replaces the bundled one), never a system variable.
        ``checkpoint`` is called before every declaration (a long list lets other work in).
        """
        if isinstance(dat, str):
            dat = parse_dat(dat)
        if all_global is None:
            all_global = dat.name is None or dat.name == "$CONFIG"
        for enum in dat.enums:
            try:
                self.registry.add_enum(enum.name, enum.values)
            except ValueError as exc:
                self._dat_problem(dat, enum.line, 1, f"ENUM {enum.name}: {exc}")
        for struc in dat.structs:
            try:
                self.registry.add_struct(struc.name, struc.members)
            except ValueError as exc:
                self._dat_problem(dat, struc.line, 1, f"STRUC {struc.name}: {exc}")
        declared: list[str] = []
        for decl in dat.declarations:
            if not (all_global or (decl.is_global and dat.public)):
                continue
            if checkpoint is not None:
                checkpoint()
            try:
                self.declare(
                    decl.name, decl.type_name, decl.dims, decl.init, decl.is_const, replace=True
                )
                declared.append(decl.name)
            except (ValueError, WriteRefused) as exc:
                self._dat_problem(dat, decl.line, decl.column, f"declaration of {decl.name}: {exc}")
        names = set(declared)
        for assign in dat.assignments:
            path = parse_name(assign.target)
            if path is None or path.base not in names:
                self._dat_problem(
                    dat, assign.line, assign.column, f"{assign.target} is not declared here"
                )
                continue
            try:
                produce = partial(self._parse, text=assign.value)
                self._assign(assign.target, produce, bypass_read_only=True)
            except WriteRefused as exc:
                self._dat_problem(dat, assign.line, assign.column, str(exc))
        return declared

    def _dat_problem(self, dat: DatFile, line: int, column: int, message: str) -> None:
        text = f"{dat.filename}:{line}:{column}: {message}"
        if self.strict:
            raise ValueError(text)
        log.warning("%s (skipped)", text)

    # --- text interface (the server) ---------------------------------------------------------
    def read(self, name: str) -> str:
        """The KRC4 text of ``name``; raises :class:`UnknownVariable` (KVP: empty + success)."""
        hot = self._hot
        if len(hot) < HOT_NAMES:
            hot[name] = None
        return self._read(name)

    def warm(self) -> None:
        """Format now the texts a client will ask for: the names read during each of the last
        two cycles (a client polling every cycle), after the robot's tick changed them.

        The simulated robot calls it at the end of its tick, which runs where it delays no
        reply (:func:`kukavarproxy_emu.latency.tick_gate`): the reply then only looks its text
        up. A name read less often than every cycle is not formatted ahead (the text would be
        stale again before it is read).
        """
        again = self._hot.keys() & self._hot_before.keys()
        self._hot_before, self._hot = self._hot, {}
        for name in again:
            try:
                self._read(name)
            except UnknownVariable:
                pass

    def _read(self, name: str) -> str:
        path = parse_name(name)
        if path is None:
            raise UnknownVariable(name)
        if self._stale and path.base in self._stale:
            self._refresh(path.base)
        cache = self._text.get(path.base)
        if cache is not None:
            text = cache.get(path)
            if text is not None:
                return text
        if path.base in self._info and path.base not in self._vars:
            if path.index is not None or path.members:
                raise UnknownVariable(name)
            return self._info[path.base]
        var = self._vars.get(path.base)
        try:
            if var is not None and var.is_array and path.index == () and not path.members:
                text = self._whole_array_text(var, name)
            else:
                text = format_krc4(self._lookup(path, name))
        except KrlValueError:
            raise UnknownVariable(name) from None
        if cache is None:
            cache = self._text[path.base] = {}
        elif len(cache) >= TEXT_CACHE_PATHS:
            cache.clear()  # a client walking every element of a huge array: keep memory flat
        cache[path] = text
        return text

    def too_long_for_reply(self, name: str) -> bool:
        """Whether ``name`` is a whole array of more than ``WHOLE_ARRAY_LIMIT`` elements, whose
        text no KUKAVARPROXY reply can carry: the server answers a failure without formatting
        it, so the cost of one read stays bounded by the largest reply."""
        path = parse_name(name)
        if path is None or path.index != () or path.members:
            return False
        var = self._vars.get(path.base)
        return var is not None and var.is_array and len(var.elems) > WHOLE_ARRAY_LIMIT

    def _whole_array_text(self, var: Var, name: str) -> str:
        """``NAME[]`` of a 1-D array from per-element texts, so that after a write to one
        element a whole-array read formats that element only.
        """
        if len(var.dims) > 1:  # a KRC prints only 1-D arrays whole
            raise UnknownVariable(name)
        elems = var.elems
        texts = var.elem_text
        if texts is None:
            if None in elems:
                raise UnknownVariable(name)
            if var.spec.kind is Kind.INT:  # str() is the KRC's INT text, mapped in C
                texts = var.elem_text = list(map(str, elems))
            else:
                texts = var.elem_text = [None] * len(elems)
        i = 0
        while True:  # list.index scans in C: a read after one write formats one element
            try:
                i = texts.index(None, i)
            except ValueError:
                break
            elem = elems[i]
            if elem is None:
                raise UnknownVariable(name)
            texts[i] = format_krc4(elem)
        # A KRC ends every element with a blank.
        return " ".join(texts) + " "  # type: ignore[arg-type]  # no None left

    def write_words(self, name: str, words: Sequence[int]) -> bool:
        """KUKAVARPROXY's mode-3 array write: word ``k`` (0..65535) becomes ``NAME[k]``, one
        element after the other, and only the last element's status is returned.

        Exactly what writing ``str(word)`` to each element would do, without the per-element
        cost, so one 64 KB frame (32 767 words) costs milliseconds, not a second: only INT and
        REAL elements accept digits, elements beyond the array fail, out-of-range values fail
        one by one.
        """
        if self.on_write is not None:
            self.on_write()
        path = parse_name(f"{name}[1]")
        var = self._vars.get(path.base) if path is not None else None
        if var is not None:
            self.fill_stale(var.name)  # a pending value first, then the words over it
        if var is None or not words or var.read_only or var.text_len or len(var.dims) != 1:
            return False  # every element refused (unknown, read-only, not a 1-D array, text)
        kind = var.spec.kind
        if kind is not Kind.INT and kind is not Kind.REAL:
            return False  # digits are no BOOL, ENUM or struct literal
        n = min(len(words), len(var.elems))
        values: Sequence[KrlValue] = words[:n] if kind is Kind.INT else list(map(float, words[:n]))
        ok = True
        if var.ranges is None:
            var.elems[:n] = values
            texts = var.elem_text
            self._text.pop(var.name, None)
            self._bump(var.name)
            if texts is not None:  # keep the per-element texts warm: no cold re-formatting
                if kind is Kind.INT:
                    texts[:n] = map(str, words[:n])
                else:
                    texts[:n] = map(_real_word_text, words[:n])
            return len(words) <= len(var.elems)
        for i, value in enumerate(values):  # limits: each element is refused on its own
            try:
                check_ranges(var.ranges, var.name, value)
            except Refused:
                ok = False
                continue
            var.elems[i] = value
            ok = True
        self.changed(var, None)
        return ok and len(words) <= len(var.elems)

    def write(self, name: str, text: str) -> str:
        """Parse ``text`` with the target's type and store it; returns the text to echo.

        Raises :class:`WriteRefused` (store unchanged) for unknown or read-only targets, bad
        indices, type mismatches, unknown members and values out of range.
        """
        if self.on_write is not None:
            self.on_write()
        self._assign(name, partial(self._parse, text=text), bypass_read_only=False)
        return text

    # --- typed interface (robot model, apps) -------------------------------------------------
    def get(self, name: str) -> KrlValue:
        """The typed value of ``name``; a whole array (``NAME`` or ``NAME[]``) is a new list,
        row-major for N-D arrays. Raises :class:`UnknownVariable` like :meth:`read`."""
        path = parse_name(name)
        if path is None:
            raise UnknownVariable(name)
        if self._stale and path.base in self._stale:
            self._refresh(path.base)
        var = self._vars.get(path.base)
        if var is not None and var.is_array and path.index is None and not path.members:
            path = VarPath(path.base, (), ())
        return self._lookup(path, name, nd_whole=True)

    def set_system(self, name: str, value: object, *, trusted: bool = False) -> None:
        """Set a value bypassing read-only (robot model, simulated I/O, apps).

        ``value`` is a KRL value (numpy scalars are accepted for numbers; a whole array takes a
        list of every element). It is checked against the type exactly like written text; a
        partial struct changes only its members. Raises :class:`UnknownVariable` or :class:`WriteRefused`.

        ``trusted``: the caller built a complete value of the declared type itself (the
        simulated robot's readings, every cycle): a whole variable is swapped in unchecked.
        """
        if not trusted and self.on_write is not None:
            self.on_write()
        path = parse_name(name)
        var = self._vars.get(path.base) if path is not None else None
        if path is None or var is None:
            raise UnknownVariable(name)
        if self._stale and var.name in self._stale:
            self._refresh(var.name)  # a pending value first, then this write over it
        if trusted and not path.index and not path.members:
            if var.is_array:
                if not isinstance(value, list) or len(value) != len(var.elems):
                    raise WriteRefused(name, f"needs a list of {len(var.elems)} values")
                var.elems = cast("list[KrlValue | None]", list(value))
            else:
                var.elems[0] = cast("KrlValue", value)
            self.changed(var, None)
            return
        reg = self.registry
        if var.is_array and not path.index and not path.members:  # whole array: a list
            if not isinstance(value, list) or len(value) != len(var.elems):
                raise WriteRefused(name, f"needs a list of {len(var.elems)} values")
            try:
                elems: list[KrlValue | None] = [coerce(v, var.spec, reg) for v in value]
                for elem in elems:
                    assert elem is not None
                    check(elem, var.spec, var.type_name, reg)
                    check_ranges(var.ranges, var.name, elem)
            except Refused as exc:
                raise WriteRefused(name, str(exc)) from None
            var.elems = elems
            self.changed(var, None)
            return

        def produce(spec: TypeSpec, type_name: str) -> KrlValue:
            coerced = coerce(value, spec, reg)
            check(coerced, spec, type_name, reg)
            return coerced

        self._assign(name, produce, bypass_read_only=True)

    def put_valid(self, name: str, value: KrlValue) -> None:
        """Set ``name`` (any path) to ``value``, which is a valid value of its declared type
        already (the KRL interpreter copying a structure from a variable of that very type):
        like :meth:`set_system` without converting and re-checking it; declared limits are
        still checked. Raises :class:`UnknownVariable` or :class:`WriteRefused`."""
        if self.on_write is not None:
            self.on_write()
        path = parse_name(name)
        if path is None or path.base not in self._vars:
            raise UnknownVariable(name)
        self._assign(name, lambda spec, type_name: value, bypass_read_only=True)

    @property
    def declared(self) -> Mapping[str, Var]:
        """The declarations by base name (the store's own mapping, not a copy: a compiled
        :class:`~.slot.Slot` checks ``declared.get(name) is var`` to know it is current)."""
        return self._vars

    def names(self) -> list[str]:
        """All variable names, sorted (arrays without brackets), for tab completion."""
        return sorted({*self._vars, *self._info})

    def is_system(self, base: str) -> bool:
        """Whether ``base`` (upper-case, no index) is one of the controller's own variables."""
        return base in self._system

    def declaration(self, base: str) -> Var | None:
        """The declared variable ``base`` (upper-case, no index): type, dimensions, flags.

        The KRL interpreter needs the declared type to convert values as KRL does (REAL to INT
        rounds) before the store validates them. None when ``base`` is not declared.
        """
        return self._vars.get(base)

    def is_read_only(self, name: str) -> bool:
        """Whether KUKAVARPROXY writes to ``name`` (or any part of it) are refused."""
        path = parse_name(name)
        if path is None or (path.base not in self._vars and path.base not in self._info):
            raise UnknownVariable(name)
        var = self._vars.get(path.base)
        return var is None or var.read_only

    def snapshot(self) -> dict[str, KrlValue | list[KrlValue | None] | None]:
        """Every variable's value(s) (arrays as new lists, None = uninitialised)."""
        self._refresh()
        return {k: (list(v.elems) if v.is_array else v.elems[0]) for k, v in self._vars.items()}

    # --- internals ---------------------------------------------------------------------------
    def _lookup(self, path: VarPath, name: str, *, nd_whole: bool = False) -> KrlValue:
        var = self._vars.get(path.base)
        if var is None:
            raise UnknownVariable(name)
        if var.is_array and path.index == ():
            # a KRC prints only 1-D arrays whole; get() returns N-D ones flat (row-major)
            multi = len(var.dims) > 1 and not nd_whole
            if path.members or multi or any(e is None for e in var.elems):
                raise UnknownVariable(name)
            return [e for e in var.elems if e is not None]
        try:
            value = var.elems[var.slot(path)]
        except Refused:
            raise UnknownVariable(name) from None
        if var.text_len and path.index:
            # one character of the text; beyond the current text it is uninitialised
            i = path.index[0]
            if not isinstance(value, str) or not 1 <= i <= min(len(value), var.text_len):
                raise UnknownVariable(name)
            return value[i - 1]
        for member in path.members:
            if not isinstance(value, Struct):
                raise UnknownVariable(name)
            value = value.get(member)
        if value is None:
            raise UnknownVariable(name)
        return value

    def _parse(self, spec: TypeSpec, type_name: str, text: str) -> KrlValue:
        """Parse ``text`` as a fully validated value of the given type."""
        return parse_text(text, spec, type_name, self.registry, strict=self.strict)

    def _assign(self, name: str, produce: _Producer, *, bypass_read_only: bool) -> None:
        """Resolve ``name``, build its new value with ``produce`` and swap it in."""
        path = parse_name(name)
        try:
            if path is None:
                raise Refused("not a variable name")
            var = self._vars.get(path.base)
            if var is None:
                raise Refused("read-only" if path.base in self._info else "unknown variable")
            self.fill_stale(var.name)  # a pending value first, then this write over it
            if var.read_only and not bypass_read_only:
                raise Refused("read-only")
            if var.is_array and path.index == ():
                raise Refused("whole-array writes are only possible for CHAR arrays")
            slot = var.slot(path)
            chain = var.chain(self.registry, path.members)
            new_elem: KrlValue
            if var.text_len and path.index:
                new_elem = var.put_char(path.index[0], produce(chain[0][0], "CHAR"))
            else:
                value = produce(*chain[-1])
                new_elem = rebuild(var.elems[slot], chain, path.members, value)
            check_ranges(var.ranges, var.name, new_elem)
        except Refused as exc:
            raise WriteRefused(name, str(exc)) from None
        # The new value is complete: swapping it in is the only mutation.
        var.elems[slot] = new_elem
        self.changed(var, slot)

    def _bump(self, base: str) -> None:
        self.mutations += 1
        self._versions[base] = self._versions.get(base, 0) + 1

    def version(self, base: str) -> int:
        """How often variable ``base`` (upper-case, no index) has changed: equal numbers,
        equal value."""
        return self._versions.get(base, 0)

    def changed(self, var: Var, slot: int | None) -> None:
        """Drop the cached texts of ``var``. A changed element of an array that is read whole
        gets its text at once: one format per write, so a whole-array read never has to
        format hundreds of elements in one go (512 E6AXIS: ~10 ms)."""
        self._text.pop(var.name, None)
        self._bump(var.name)
        texts = var.elem_text
        if texts is not None:
            if slot is None:
                var.elem_text = None
                return
            elem = var.elems[slot]
            try:
                texts[slot] = None if elem is None else format_krc4(elem)
            except KrlValueError:
                texts[slot] = None
