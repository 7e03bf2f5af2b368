"""The platform PLC's Modbus register map, shared by the simulator and the control server.

Every value is one 16-bit register, a signed integer (two's complement) in a fixed unit, so any
stock Modbus client or HMI reads it without a float word-order convention. docs/heave.md has
the same table.

Coils (read 0x01, write 0x05/0x0F):

===  ===========  ==================================================================
0    ENABLE       drives on; off: the motors brake to a stop and hold
1    WAVE         the PLC's own wave generator (eq. 4.13, seed WAVE_SEED) drives it
2    RESET        write 1 to acknowledge a fault (reads back 0)
===  ===========  ==================================================================

A write of any other coil is refused with exception 2 (ILLEGAL DATA ADDRESS).

Holding registers (read 0x03, write 0x06/0x10), the commands:

===  ===========  ===========  =======================================================
0    SP_HEAVE     0.01 mm      heave set-point, −13000…13000 (±130 mm)
1    SP_ROLL      0.001°       roll set-point, −20000…20000
2    SP_PITCH     0.001°       pitch set-point, −20000…20000
3    MODE         –            0: pose set-points (the PLC solves eq. 4.6), 1: joint set-points
4–6  SP_BETA1..3  0.01°        joint set-points for MODE 1, 0…12500
7    WATCHDOG     ms           a master write must arrive this often while enabled, in
                               every mode; else fault 1 and the drives stop. 1…the
                               start-up value (default 1000): a write may shorten it,
                               never switch it off (0 only when started off)
8    SPEED        %            motor speed override, 1…100
9    WAVE_SEED    –            seed of the PLC's wave generator (0…65535)
10   HEARTBEAT    –            any value; a write feeds the watchdog
===  ===========  ===========  =======================================================

Input registers (read 0x04), the state, refreshed every PLC cycle; the same block is readable
as holding registers 100–116 for masters that only read holding registers:

=====  ============  ===========  ====================================================
0–2    BETA1..3      0.01°        measured joint angles
3–5    BETA_DOT1..3  0.01°/s      joint speeds
6      HEAVE         0.01 mm      heave z (forward kinematics of the measured joints)
7      ROLL          0.001°       roll φ
8      PITCH         0.001°       pitch θ
9      HEAVE_RATE    0.01 mm/s
10     ROLL_RATE     0.001°/s
11     PITCH_RATE    0.001°/s
12     STATUS        bits         0 enabled, 1 moving, 2 set-point saturated, 3 fault,
                                  4 wave generator on, 5 joint set-point mode
13     FAULT         –            0 none, 1 master watchdog
14     CYCLE         –            PLC cycle counter (wraps at 65536)
15–16  TIME_MS       ms           PLC time, high word then low word
=====  ============  ===========  ====================================================

A write whose value is outside the range above is refused as a whole with exception 3
(ILLEGAL DATA VALUE); a write to the state block is refused with exception 2. A pose set-point
in range that a leg cannot reach is clamped into the stroke and sets STATUS bit 2.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

__all__ = [
    "COILS",
    "HOLDING",
    "HOLDING_LIMITS",
    "INPUT",
    "STATE_MIRROR",
    "STATUS",
    "PlatformState",
    "decode_state",
    "from_register",
    "to_register",
]

COILS = {"ENABLE": 0, "WAVE": 1, "RESET": 2}
HOLDING = {
    "SP_HEAVE": 0,
    "SP_ROLL": 1,
    "SP_PITCH": 2,
    "MODE": 3,
    "SP_BETA1": 4,
    "SP_BETA2": 5,
    "SP_BETA3": 6,
    "WATCHDOG": 7,
    "SPEED": 8,
    "WAVE_SEED": 9,
    "HEARTBEAT": 10,
}
HOLDING_COUNT = 11
#: Inclusive raw ranges of the command registers (values as signed 16-bit, except the seed).
HOLDING_LIMITS: dict[int, tuple[int, int]] = {
    0: (-13000, 13000),
    1: (-20000, 20000),
    2: (-20000, 20000),
    3: (0, 1),
    4: (0, 12500),
    5: (0, 12500),
    6: (0, 12500),
    7: (0, 60000),
    8: (1, 100),
    9: (0, 65535),
    10: (0, 65535),
}
#: Registers whose raw value is unsigned.
UNSIGNED = frozenset({7, 9, 10})
INPUT = {
    "BETA1": 0,
    "BETA_DOT1": 3,
    "HEAVE": 6,
    "ROLL": 7,
    "PITCH": 8,
    "HEAVE_RATE": 9,
    "ROLL_RATE": 10,
    "PITCH_RATE": 11,
    "STATUS": 12,
    "FAULT": 13,
    "CYCLE": 14,
    "TIME_MS": 15,
}
INPUT_COUNT = 17
#: The state block mirrored into the holding registers from this address on.
STATE_MIRROR = 100
STATUS = {"enabled": 0, "moving": 1, "saturated": 2, "fault": 3, "wave": 4, "joint_mode": 5}
FAULT_NONE, FAULT_WATCHDOG = 0, 1
#: Units: value = raw × scale.
SCALE_MM, SCALE_DEG, SCALE_BETA = 0.01, 0.001, 0.01


def to_register(value: float, scale: float, lo: int = -32768, hi: int = 32767) -> int:
    """A physical value as the 16-bit register word; ValueError outside ``lo…hi`` raw."""
    raw = round(value / scale)
    if not lo <= raw <= hi:
        raise ValueError(f"{value:g} is outside the register range {lo * scale:g}…{hi * scale:g}")
    return raw & 0xFFFF


def from_register(word: int, scale: float = 1.0) -> float:
    """The signed value of a register word times ``scale``."""
    signed = word - 0x10000 if word & 0x8000 else word
    return signed * scale


@dataclass(frozen=True)
class PlatformState:
    """One read of the state block, in physical units (mm, deg, s)."""

    beta: tuple[float, float, float]
    beta_dot: tuple[float, float, float]
    heave: float
    roll: float
    pitch: float
    heave_rate: float
    roll_rate: float
    pitch_rate: float
    status: int
    fault: int
    cycle: int
    time: float

    def flag(self, name: str) -> bool:
        return bool(self.status >> STATUS[name] & 1)


def decode_state(words: Sequence[int]) -> PlatformState:
    """Decode the 17 input registers."""
    if len(words) < INPUT_COUNT:
        raise ValueError(f"the state block has {INPUT_COUNT} registers, got {len(words)}")
    w = [int(x) & 0xFFFF for x in words]
    beta = tuple(from_register(w[i], SCALE_BETA) for i in range(3))
    beta_dot = tuple(from_register(w[3 + i], SCALE_BETA) for i in range(3))
    return PlatformState(
        beta=beta,  # type: ignore[arg-type]
        beta_dot=beta_dot,  # type: ignore[arg-type]
        heave=from_register(w[6], SCALE_MM),
        roll=from_register(w[7], SCALE_DEG),
        pitch=from_register(w[8], SCALE_DEG),
        heave_rate=from_register(w[9], SCALE_MM),
        roll_rate=from_register(w[10], SCALE_DEG),
        pitch_rate=from_register(w[11], SCALE_DEG),
        status=w[12],
        fault=w[13],
        cycle=w[14],
        time=((w[15] << 16) | w[16]) / 1000.0,
    )
