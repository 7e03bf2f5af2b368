"""Variable names for tab completion and the list of motion variables that need confirmation.

Completion draws on three sources: a built-in list of common KRC4 system variables, the
names an emulator's store declares (``--emulate``), and the globals of ``$CONFIG.DAT``-style
files given with ``--config`` (parsed with :func:`kukavarproxy_emu.datfile.parse_dat`).
Arrays are offered both bare and as ``NAME[]`` (the whole-array read).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
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


def store_names(store: Any) -> list[str]:
    """The names an emulator's :class:`VariableStore` declares, arrays also as ``NAME[]``."""
    out: list[str] = []
    for name, value in store.snapshot().items():
        out.append(name)
        if isinstance(value, list):
            out.append(f"{name}[]")
    return out


def dat_names(paths: Iterable[Path]) -> list[str]:
    """Global names declared in ``$CONFIG.DAT``-style files (arrays also as ``NAME[]``)."""
    from kukavarproxy_emu.datfile import parse_dat

    out: list[str] = []
    for path in paths:
        dat = parse_dat(Path(path).read_text(encoding="latin-1"), str(path))
        for decl in dat.declarations:
            out.append(decl.name)
            if decl.dims:
                out.append(f"{decl.name}[]")
    return out


def completion_names(store: Any = None, config_files: Iterable[Path] = ()) -> list[str]:
    """Every name to complete: built-in system variables + store + config globals, sorted."""
    names = set(KRC4_SYSTEM_VARIABLES)
    if store is not None:
        names.update(store_names(store))
    names.update(dat_names(config_files))
    return sorted(names, key=lambda n: (n.lstrip("$@"), n))
