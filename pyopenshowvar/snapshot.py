"""Consistent snapshots: many variables copied by the controller in one SPS pass, read in ONE request.

KUKAVARPROXY answers one variable per request, 2–3 ms each on a KRC4, so twenty variables read
one by one take ~50 ms and come from several interpolation cycles. A :class:`Snapshot` lets the
controller pack them instead: it lays the variables out as members of a KRL ``STRUC``, and
:mod:`pyopenshowvar.snapshot_krl` writes the KRL to install — the ``STRUC`` and ``DECL`` lines
for ``$CONFIG.DAT`` and an SPS fold that copies every variable into a work copy, counts the pass
in a ``CYCLE`` member and assigns the whole structure at once. The PC then reads that one
global (``Client.read_snapshot``) and gets typed values keyed by the original names, all from
one SPS pass, with the pass counter telling how old the snapshot is (docs/snapshots.md)::

    snap = Snapshot("CELL", ["$AXIS_ACT", "$POS_ACT", "$TORQUE_AXIS_ACT[]", ("MYREAL", "REAL")])
    snap.write_krl("out/")                    # out/CELL.dat, out/CELL.sub
    reading = await kvp.read_snapshot(snap)   # reading["$AXIS_ACT"] -> E6Axis; reading.cycle

KRL's limits decide the layout (:class:`SnapshotLimits`): names of at most 24 characters, no
array inside a ``STRUC`` (KUKA documents only CHAR arrays there; a whole array ``X[]`` becomes
one member per element; CHAR text needs STRCOPY and is refused), and — our choices, since KUKA documents no maximum — STRUC declarations of at most
``struc_line`` characters (longer ones become nested group structures, still one read) and at
most ``max_text`` characters of reply text per read (more makes several top-level structures,
read pipelined and checked to come from the same pass). This module does no I/O: the read is
an operation (:mod:`pyopenshowvar.core`) both clients run.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from .core import Op
from .errors import KrlValueError, UnknownVariableError, VariableError
from .krl import BUILTIN_TYPES, KrlValue, Struct, TypeRegistry, parse_value
from .snapshot_krl import dat_text, sub_text
from .snapshot_layout import (
    COUNTER,
    KRL_KEYWORDS,
    Part,
    SnapshotLimits,
    Variable,
    check_name,
    layout,
    resolve_variable,
    struc_line,
    unique_names,
)

__all__ = [
    "COUNTER",
    "KRL_KEYWORDS",
    "Snapshot",
    "SnapshotLimits",
    "SnapshotReading",
    "SnapshotTornError",
    "read_snapshot",
    "struc_line",
]


class SnapshotTornError(VariableError):
    """The parts of a multi-part snapshot kept coming from different SPS passes."""


class Snapshot:
    """A named group of variables the controller copies together; see the module docstring.

    ``variables``: names (system variables' types are known, :mod:`pyopenshowvar.krl.systypes`)
    or ``(name, type)`` pairs (``("MYPOS", "POS")``, ``("MYARR[]", "REAL[10]")``, the type of
    the value the name addresses), or a mapping name → type (None: look it up). ``registry``
    declares user STRUC/ENUM types used by them. Raises ``ValueError`` for anything KRL cannot
    hold, with the reason.
    """

    def __init__(
        self,
        name: str,
        variables: Iterable[str | tuple[str, str]] | Mapping[str, str | None],
        *,
        registry: TypeRegistry | None = None,
        limits: SnapshotLimits | None = None,
    ) -> None:
        self.limits = limits or SnapshotLimits()
        self.name = check_name(name, self.limits, "snapshot")
        self._registry = registry if registry is not None else BUILTIN_TYPES
        items: list[tuple[str, str | None]]
        if isinstance(variables, Mapping):
            items = list(variables.items())
        else:
            items = [(v, None) if isinstance(v, str) else (v[0], v[1]) for v in variables]
        if not items:
            raise ValueError("a snapshot needs at least one variable")
        taken = {COUNTER}
        self.variables: tuple[Variable, ...] = tuple(
            resolve_variable(n, t, taken, self._registry, self.limits)
            for n, t in unique_names(items)
        )
        self.parts: tuple[Part, ...] = tuple(layout(self.name, self.variables, self.limits))
        self._types = self._build_registry()

    # ------------------------------------------------------------------ public

    @property
    def names(self) -> tuple[str, ...]:
        """The variables as given, in order (the keys of a :class:`SnapshotReading`)."""
        return tuple(v.name for v in self.variables)

    @property
    def read_names(self) -> tuple[str, ...]:
        """The globals the PC reads: one, unless the limits split the snapshot."""
        return tuple(p.variable for p in self.parts)

    @property
    def registry(self) -> TypeRegistry:
        """The user registry plus the generated STRUC types (what the reply is parsed with)."""
        return self._types

    def krl_dat(self) -> str:
        """The ``$CONFIG.DAT`` declarations (a data list the emulator loads with ``--config``)."""
        return dat_text(self)

    def krl_sub(self) -> str:
        """The SPS that copies the variables each pass (``--sps`` of the emulator)."""
        return sub_text(self)

    def write_krl(self, directory: str | Path) -> tuple[Path, Path]:
        """Write ``DIR/<name>.dat`` and ``DIR/<name>.sub`` (latin-1, CRLF as a KRC expects)."""
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        paths = (out / f"{self.name}.dat", out / f"{self.name}.sub")
        for path, text in zip(paths, (self.krl_dat(), self.krl_sub()), strict=True):
            path.write_bytes(text.replace("\n", "\r\n").encode("latin-1"))
        return paths

    def parse(self, texts: Sequence[str], endpoint: str = "") -> SnapshotReading:
        """Typed values from the replies to :attr:`read_names` (same order).

        Raises :class:`KrlValueError` when a reply does not have this snapshot's layout (the
        controller runs other KRL than this definition generates) and
        :class:`SnapshotTornError` when the parts come from different SPS passes.
        """
        if len(texts) != len(self.parts):
            raise ValueError(f"expected {len(self.parts)} replies, got {len(texts)}")
        values: dict[str, KrlValue] = {}
        cycles: list[int] = []
        slot_values: dict[int, KrlValue] = {}
        for part, text in zip(self.parts, texts, strict=True):
            top = self._parse_part(part, text, endpoint)
            cycle = top.get(COUNTER)
            if not isinstance(cycle, int) or isinstance(cycle, bool):
                raise self._mismatch(part, f"no INT {COUNTER} member", endpoint)
            cycles.append(cycle)
            for path, slot in part.paths:
                try:
                    slot_values[id(slot)] = _member(top, path)
                except KeyError:
                    raise self._mismatch(
                        part, f"no member {path} (other KRL installed?)", endpoint
                    ) from None
        if len(set(cycles)) > 1:
            raise SnapshotTornError(
                f"parts {', '.join(self.read_names)} come from SPS passes {cycles}",
                name=self.name,
                endpoint=endpoint,
            )
        for var in self.variables:
            got = [slot_values[id(s)] for s in var.slots]
            values[var.name] = got if var.whole_array else got[0]
        return SnapshotReading(self, values, cycles[0])

    def __repr__(self) -> str:
        return f"Snapshot({self.name!r}, {list(self.names)!r})"

    # ------------------------------------------------------------------ variables

    # ------------------------------------------------------------------ layout

    def _build_registry(self) -> TypeRegistry:
        reg = self._registry.copy()
        for part in self.parts:
            for t in part.types:
                reg.add_struct(t.name, t.members)
        return reg

    # ------------------------------------------------------------------ parsing

    def _parse_part(self, part: Part, text: str, endpoint: str) -> Struct:
        try:
            value = parse_value(text, part.type_name, registry=self._types)
        except KrlValueError as exc:
            raise self._mismatch(part, str(exc), endpoint) from None
        if not isinstance(value, Struct) or value.type_name not in (None, part.type_name):
            raise self._mismatch(part, f"not a {part.type_name}", endpoint)
        return value

    def _mismatch(self, part: Part, why: str, endpoint: str) -> KrlValueError:
        where = f" on {endpoint}" if endpoint else ""
        return KrlValueError(
            f"snapshot {self.name!r}: {part.variable}{where} does not match this definition"
            f" ({why}); install the KRL generated for it (kvp snapshot krl)"
        )


class SnapshotReading(Mapping[str, KrlValue]):
    """One snapshot read: typed values keyed by the variable names as given, plus the pass.

    ``cycle`` is the SPS pass counter of the snapshot: two readings with the same cycle are the
    same copy, and its growth over time shows the SPS runs (docs/snapshots.md, "Age").
    """

    __slots__ = ("_values", "cycle", "snapshot")

    def __init__(self, snapshot: Snapshot, values: dict[str, KrlValue], cycle: int) -> None:
        self.snapshot = snapshot
        self._values = values
        self.cycle = cycle

    def __getitem__(self, name: str) -> KrlValue:
        return self._values[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        return f"SnapshotReading({self.snapshot.name!r}, cycle={self.cycle}, {self._values!r})"


def read_snapshot(
    io: Any, snapshot: Snapshot, *, retries: int = 3, timeout: float | None = None
) -> Op[SnapshotReading]:
    """Read ``snapshot`` in ONE request (one per part when its limits split it).

    Returns a :class:`SnapshotReading`: typed values keyed by the names the snapshot was made
    with, and the SPS pass counter. A multi-part snapshot whose parts come from different passes
    is read again, up to ``retries`` times, then :class:`SnapshotTornError`. A snapshot that is
    not on the controller (or that the SPS never filled) raises :class:`UnknownVariableError`
    saying so.
    """
    names = snapshot.read_names
    for attempt in range(retries + 1):
        try:
            if len(names) == 1:
                texts = [(yield ("read", (names[0],), {"timeout": timeout}))]
            else:
                results = yield ("read_many", (names,), {"timeout": timeout})
                texts = [results[n].unwrap() for n in names]
        except UnknownVariableError as exc:
            raise UnknownVariableError(
                f"snapshot {snapshot.name!r} is not readable: install its KRL (kvp snapshot krl,"
                " docs/snapshots.md) and check that the SPS runs",
                name=exc.name,
                endpoint=io.endpoint,
            ) from exc
        try:
            return snapshot.parse(texts, io.endpoint)
        except SnapshotTornError:
            if attempt == retries:
                raise
    raise AssertionError("unreachable")  # pragma: no cover


# --------------------------------------------------------------------------- helpers


def _member(top: Struct, path: str) -> KrlValue:
    value: KrlValue = top
    for key in path.split("."):
        if not isinstance(value, Struct) or key not in value:
            raise KeyError(path)
        value = value[key]
    return value
