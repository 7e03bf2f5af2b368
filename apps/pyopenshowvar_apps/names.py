"""Variable names for tab completion and the list of motion variables that need confirmation.

Completion draws on three sources: a built-in list of common KRC4 system variables, the
names an emulator's store declares (``--emulate``), and the globals of ``$CONFIG.DAT``-style
files given with ``--config`` (parsed with :func:`pyopenshowvar.krl.datfile.parse_dat`).

Names that can only read as unknown are not offered: a bare 1-D array or text name
(KUKAVARPROXY reads ``NAME[]`` or ``NAME[i]``, so only ``NAME[]`` is offered), ``NAME[]`` of a
2-D array, and, with an emulator, the built-in names it does not have. Names that read as
unknown *now* but can be written are offered with a mark saying why (:class:`Names`): a
variable never given a value (``MYE6ARRAY[]`` and ``MYE6POS`` on a fresh emulator, a
``--config`` declaration without one), a 2-D array's bare name. With an emulator the marks are
live: a variable written since is no longer marked.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: Common KRC4 system variables readable through KUKAVARPROXY (``[]``: whole 1-D array).
KRC4_SYSTEM_VARIABLES: tuple[str, ...] = (
    "$ACC", "$ACC_AXIS[]", "$ACC_EXTAX[]", "$ADVANCE", "$ALARM_STOP", "$ANIN[]", "$ANOUT[]",
    "$APO", "$AXIS_ACT", "$AXIS_ACT_MEAS", "$AXIS_BACK", "$AXIS_FOR", "$AXIS_HOME[]",
    "$AXIS_INT", "$AXIS_RET", "$BASE", "$BASE_C", "$BWDSTART", "$CIRC_TYPE", "$CMD",
    "$CURR_ACT[]", "$DATE", "$DIST_NEXT", "$DRIVES_ON", "$FLAG[]", "$IN[]", "$IPO_MODE",
    "$KR_SERIALNO", "$LOAD", "$MODE_OP", "$MODEL_NAME[]", "$MOT_TEMP[]", "$NULLFRAME",
    "$ORI_TYPE", "$OUT[]", "$OV_JOG", "$OV_PRO", "$PERI_RDY", "$POS_ACT", "$POS_ACT_MES",
    "$POS_BACK", "$POS_FOR", "$POS_INT", "$POS_RET", "$POWER_FAIL", "$PRO_IP", "$PRO_MODE",
    "$PRO_NAME0[]", "$PRO_NAME1[]", "$PRO_STATE0", "$PRO_STATE1", "$ROBNAME[]", "$ROBROOT",
    "$RCV_INFO[]", "$SOFTN_END[]", "$SOFTP_END[]", "$STOPMESS", "$TIMER[]", "$TIMER_STOP[]",
    "$TOOL", "$TOOL_C", "$TORQUE_AXIS_ACT[]", "$TORQUE_AXIS_MAX[]", "$TRAFONAME[]", "$USER_SAF",
    "$VEL", "$VEL_ACT", "$VEL_AXIS[]", "$VEL_AXIS_ACT[]", "$VEL_AXIS_MA[]", "$WORLD",
    "@PROXY_TYPE", "@PROXY_VERSION",
)  # fmt: skip

#: Writing one of these can move the robot or change how it moves: the monitor asks first.
MOTION_VARIABLES: frozenset[str] = frozenset(
    {
        "MYAXIS", "MYPOS", "MYE6POS", "MYE6ARRAY", "MYPOSARRAY", "PATH_START", "PATH_COUNT",
        "OUTPUT_VARS", "$OV_PRO", "$OV_JOG", "$VEL", "$ACC", "$VEL_AXIS", "$ACC_AXIS",
        "$APO", "$TOOL", "$BASE", "$LOAD", "$ADVANCE", "$OUT",
    }
)  # fmt: skip

_BASE = re.compile(r"^\s*([$@A-Za-z_][\w$]*)")


def base_name(name: str) -> str:
    """``MYE6ARRAY[3].A1`` → ``MYE6ARRAY`` (upper case)."""
    m = _BASE.match(name)
    return m.group(1).upper() if m else name.strip().upper()


def is_motion_variable(name: str) -> bool:
    """True when writing ``name`` (or a part of it) may move the robot."""
    return base_name(name) in MOTION_VARIABLES


GRID_NOTE = "2-D array: read NAME[i, j]"
UNSET_NOTE = "no value yet: reads as unknown"


@dataclass
class Names:
    """Names to complete, each with a note ("" when it reads) that may be computed live."""

    notes: dict[str, str] = field(default_factory=dict)
    live: Callable[[str], str | None] | None = None

    def __iter__(self) -> Any:
        return iter(sorted(self.notes, key=lambda n: (n.lstrip("$@"), n)))

    def __len__(self) -> int:
        return len(self.notes)

    def note(self, name: str) -> str:
        """Why ``name`` would read as unknown now, or ""."""
        if self.live is not None:
            live = self.live(name)
            if live is not None:
                return live
        return self.notes.get(name, "")


def store_names(store: Any) -> Names:
    """The names an emulator's :class:`VariableStore` declares (1-D arrays and texts as
    ``NAME[]``), marked live by reading them."""
    notes: dict[str, str] = {}
    for name in store.snapshot():
        decl = store.declaration(name)
        dims = tuple(getattr(decl, "dims", ()))
        if getattr(decl, "text_len", 0) or len(dims) == 1:  # text or 1-D array: NAME[]
            notes[f"{name}[]"] = ""
        elif dims:  # a KRC prints no 2-D array whole
            notes[name] = GRID_NOTE
        else:
            notes[name] = ""

    def live(name: str) -> str | None:
        if notes.get(name) or name not in notes:
            return None  # arrays keep their static note; foreign names are not ours
        try:
            store.read(name)
        except Exception:  # the store's UnknownVariable: declared, never given a value
            return (
                UNSET_NOTE if not name.endswith("[]") else "not every element set: reads as unknown"
            )
        return ""

    return Names(notes, live)


def dat_names(paths: Iterable[Path]) -> Names:
    """Global names declared in ``$CONFIG.DAT``-style files (1-D arrays as ``NAME[]``)."""
    from pyopenshowvar.krl.datfile import parse_dat

    notes: dict[str, str] = {}
    for path in paths:
        dat = parse_dat(Path(path).read_text(encoding="latin-1"), str(path))
        assigned = {base_name(a.target) for a in dat.assignments}
        for decl in dat.declarations:
            unset = decl.init is None and decl.name.upper() not in assigned
            if len(decl.dims) == 1:
                notes[f"{decl.name}[]"] = f"no value in {Path(path).name}" if unset else ""
            elif decl.dims:
                notes[decl.name] = GRID_NOTE
            else:
                notes[decl.name] = f"no value in {Path(path).name}" if unset else ""
    return Names(notes)


def completion_names(store: Any = None, config_files: Iterable[Path] = ()) -> Names:
    """Every name to complete, with notes: built-in system variables (those the emulator has,
    with one) + the emulator's names + config globals."""
    builtin = Names({n: "" for n in KRC4_SYSTEM_VARIABLES})
    if store is None:
        names = builtin
    else:
        names = store_names(store)
        for n in KRC4_SYSTEM_VARIABLES:
            if n.startswith("@"):  # answered by the proxy itself, not the controller
                names.notes[n] = ""
    for n, note in dat_names(config_files).notes.items():
        names.notes.setdefault(n, note)
    return names
