"""Declared types of the KRC4 system variables a PC commonly reads, for code that must know them.

KUKAVARPROXY sends text, and the text alone does not always say the type (``0`` may be an INT
or a BOOL-less counter, ``#AUT`` names no ENUM type, an array's length is not in an element's
reply). Generating KRL that copies a variable (:mod:`pyopenshowvar.snapshot`) needs the
declared type, so this table holds it for the system variables of KSS 8.x on a KRC4:
element type and dimensions for arrays (``"REAL[12]"``: ``$TORQUE_AXIS_ACT[1..12]``, axes
7..12 being E1..E6). Sources: KUKA's KSS 8 system variable descriptions, as texts captured from
KRC4s in public clients show them, and the KRL quick guide; a test checks that the
emulator declares every name it shares with this table with the same type.

User globals are not here: give their type where you use them (``("MYPOS", "POS")``).
"""

from __future__ import annotations

__all__ = ["SYSTEM_TYPES", "system_type"]

#: KRL type expression of each system variable (upper-case name without ``[]``).
SYSTEM_TYPES: dict[str, str] = {
    # position and motion state
    "$AXIS_ACT": "E6AXIS",
    "$AXIS_ACT_MEAS": "E6AXIS",
    "$POS_ACT": "E6POS",
    "$POS_ACT_MES": "E6POS",
    "$VEL_ACT": "REAL",
    "$DIST_NEXT": "REAL",
    # drives, one element per axis (7..12 = E1..E6)
    "$TORQUE_AXIS_ACT": "REAL[12]",
    "$TORQUE_AXIS_MAX": "REAL[12]",
    "$CURR_ACT": "REAL[12]",
    "$VEL_AXIS_ACT": "REAL[12]",
    "$MOT_TEMP": "INT[12]",
    "$SOFTN_END": "REAL[12]",
    "$SOFTP_END": "REAL[12]",
    # overrides and motion parameters
    "$OV_PRO": "INT",
    "$OV_JOG": "INT",
    "$VEL": "CP",
    "$ACC": "CP",
    "$VEL_AXIS": "INT[12]",
    "$ACC_AXIS": "INT[12]",
    "$APO": "APO",
    "$ADVANCE": "INT",
    "$TOOL": "FRAME",
    "$BASE": "FRAME",
    "$LOAD": "LOAD",
    "$NULLFRAME": "FRAME",
    "$WORLD": "FRAME",
    "$ROBROOT": "FRAME",
    "$TIMER": "INT[32]",
    "$TIMER_STOP": "BOOL[32]",
    # controller state
    "$MODE_OP": "MODE_OP",
    "$PRO_STATE0": "PRO_STATE",
    "$PRO_STATE1": "PRO_STATE",
    "$PRO_NAME0": "CHAR[24]",
    "$PRO_NAME1": "CHAR[24]",
    "$DRIVES_ON": "BOOL",
    "$STOPMESS": "BOOL",
    "$PERI_RDY": "BOOL",
    "$ALARM_STOP": "BOOL",
    "$POWER_FAIL": "BOOL",
    # I/O
    "$IN": "BOOL[4096]",
    "$OUT": "BOOL[4096]",
    "$ANIN": "REAL[32]",
    "$ANOUT": "REAL[32]",
    # identity
    "$ROBNAME": "CHAR[32]",
    "$MODEL_NAME": "CHAR[32]",
    "$TRAFONAME": "CHAR[32]",
    "$KR_SERIALNO": "INT",
}


def system_type(base: str) -> str | None:
    """The declared type of system variable ``base`` (any case, no index), or None."""
    return SYSTEM_TYPES.get(base.strip().upper())
