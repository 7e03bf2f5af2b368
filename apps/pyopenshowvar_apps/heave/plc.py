"""The platform's PLC program, without I/O: set-points in, three speed-limited motors, state out.

One :meth:`PlatformPLC.step` is one PLC scan. The simulator (:mod:`.simulator`) runs it on a
timer and maps its registers onto Modbus; tests drive it directly. The motors are position
loops with a speed limit (× the SPEED override) and an acceleration limit: each scan the speed
moves towards ``sign(e)·min(vmax, √(2·amax·|e|), |e|/dt)`` by at most ``amax·dt``, the
time-optimal approach that brakes in time to stop on the target.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import registers as reg
from .geometry import THESIS_PLATFORM, FloatArray, PlatformGeometry, PlatformPose, UnreachablePose
from .waves import WaveGenerator

__all__ = ["MotorLimits", "PlatformPLC"]

#: Joint error (deg) within which a slow drive counts as in position and stops.
IN_POSITION = 1e-3


@dataclass(frozen=True)
class MotorLimits:
    """Joint speed (deg/s) and acceleration (deg/s²) of the three geared DC motors."""

    speed: float = 90.0
    accel: float = 360.0

    def __post_init__(self) -> None:
        if not (self.speed > 0 and self.accel > 0):
            raise ValueError("motor speed and acceleration limits must be > 0")


class PlatformPLC:
    """Set-points, motors and state of the wave platform; times are PLC seconds."""

    def __init__(
        self,
        geometry: PlatformGeometry = THESIS_PLATFORM,
        motors: MotorLimits | None = None,
        *,
        watchdog: float = 1.0,
    ) -> None:
        self.geometry = geometry
        self.motors = motors or MotorLimits()
        neutral = geometry.inverse(PlatformPose())
        self.beta: FloatArray = neutral.copy()
        self.beta_dot: FloatArray = np.zeros(3)
        self.target: FloatArray = neutral.copy()
        self.time = 0.0
        self.cycle = 0
        self.enabled = False
        self.wave_on = False
        self.wave_seed = 0
        self.wave: WaveGenerator | None = None
        self._wave_t0 = 0.0
        self.joint_mode = False
        self.sp_pose = PlatformPose()
        self.sp_beta: FloatArray = neutral.copy()
        #: The master watchdog (s, 0 = off); the register may shorten it, never lengthen or
        #: switch it off: that takes this start-up value (``kvp platform --watchdog 0``).
        self.watchdog = watchdog
        self.watchdog_limit = watchdog
        self.speed_pct = 100
        self.fault = reg.FAULT_NONE
        self.saturated = False
        self._last_master = 0.0
        self.pose = geometry.forward(self.beta)
        self.rates: FloatArray = np.zeros(3)  # dz/dt mm/s, dφ/dt, dθ/dt deg/s
        self.heave_accel = 0.0  # mm/s², for the accelerometer

    # --- commands (the Modbus layer calls these after validating the raw values) ------------
    def master_alive(self) -> None:
        """A write from the master arrived: feed the watchdog."""
        self._last_master = self.time

    @property
    def last_master(self) -> float:
        """PLC time of the last master write (what the watchdog counts from)."""
        return self._last_master

    def set_enable(self, on: bool) -> None:
        if on and self.fault != reg.FAULT_NONE:
            return  # a faulted PLC needs RESET first
        if on and not self.enabled:
            self._last_master = self.time
        self.enabled = on

    def set_wave(self, on: bool, generator: WaveGenerator | None = None) -> None:
        """Start (with ``generator``, default: a random thesis sea from WAVE_SEED) or stop."""
        if on and not self.wave_on:
            self.wave = generator or WaveGenerator.random(self.wave_seed, ramp=2.0)
            self._wave_t0 = self.time
        self.wave_on = on

    def reset_fault(self) -> None:
        self.fault = reg.FAULT_NONE

    def set_pose_setpoint(self, pose: PlatformPose) -> None:
        self.sp_pose = pose

    # --- one scan ------------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        """Advance the PLC by ``dt`` seconds: watchdog, set-point, motors, state."""
        self.time += dt
        self.cycle = (self.cycle + 1) & 0xFFFF
        # In every mode, the PLC's own waves included: drives that run on with nobody there
        # to stop them are what the watchdog exists to prevent.
        if self.enabled and self.watchdog > 0 and self.time - self._last_master > self.watchdog:
            self.fault = reg.FAULT_WATCHDOG
            self.enabled = False
        if self.enabled:
            self.target = self._setpoint_joints()
            self._drive(dt)
        else:
            self._brake(dt)
        self._update_state(dt)

    def _setpoint_joints(self) -> FloatArray:
        if self.wave_on and self.wave is not None:
            pose = self.wave.pose(self.time - self._wave_t0)
        elif self.joint_mode:
            self.saturated = False
            return np.clip(self.sp_beta, 0.0, self.geometry.beta_max)
        else:
            pose = self.sp_pose
        heights = self.geometry.corner_heights(pose)
        clamped = self.geometry.clamp_heights(heights)
        self.saturated = bool(np.any(np.abs(clamped - heights) > 1e-9))
        try:
            return self.geometry.leg_angle(clamped)
        except UnreachablePose:  # pragma: no cover - clamped heights are always reachable
            return self.beta.copy()

    def _drive(self, dt: float) -> None:
        vmax = self.motors.speed * self.speed_pct / 100.0
        amax = self.motors.accel
        error = self.target - self.beta
        magnitude = np.minimum(vmax, np.sqrt(2.0 * amax * np.abs(error)))
        wanted = np.sign(error) * np.minimum(magnitude, np.abs(error) / dt)
        speed = self.beta_dot + np.clip(wanted - self.beta_dot, -amax * dt, amax * dt)
        self._integrate(speed, dt)
        # in-position window: a drive that is there and slow stops (no endless creeping)
        there = (np.abs(self.target - self.beta) < IN_POSITION) & (
            np.abs(self.beta_dot) < amax * dt
        )
        self.beta = np.where(there, self.target, self.beta)
        self.beta_dot = np.where(there, 0.0, self.beta_dot)

    def _brake(self, dt: float) -> None:
        amax = self.motors.accel
        speed = self.beta_dot - np.clip(self.beta_dot, -amax * dt, amax * dt)
        self._integrate(speed, dt)
        self.target = self.beta.copy()

    def _integrate(self, speed: FloatArray, dt: float) -> None:
        new = self.beta + 0.5 * (self.beta_dot + speed) * dt
        self.beta = np.clip(new, 0.0, self.geometry.beta_max)
        self.beta_dot = np.where(self.beta == new, speed, 0.0)

    def _update_state(self, dt: float) -> None:
        old, old_rate = self.pose, self.rates[0]
        self.pose = self.geometry.forward(self.beta)
        self.rates = (self.pose.as_array() - old.as_array()) / dt
        self.heave_accel = (self.rates[0] - old_rate) / dt

    # --- registers -----------------------------------------------------------------------------
    @property
    def status(self) -> int:
        bits = {
            "enabled": self.enabled,
            "moving": bool(np.any(np.abs(self.beta_dot) > 1e-6)),
            "saturated": self.saturated,
            "fault": self.fault != reg.FAULT_NONE,
            "wave": self.wave_on,
            "joint_mode": self.joint_mode,
        }
        return sum(1 << reg.STATUS[name] for name, on in bits.items() if on)

    def state_words(self) -> list[int]:
        """The 17 input registers (see :mod:`.registers`)."""

        def word(value: float, scale: float) -> int:
            raw = max(-32768, min(32767, round(value / scale)))
            return raw & 0xFFFF

        p, r = self.pose, self.rates
        words = [word(b, reg.SCALE_BETA) for b in self.beta]
        words += [word(b, reg.SCALE_BETA) for b in self.beta_dot]
        words += [word(p.z, reg.SCALE_MM), word(p.phi, reg.SCALE_DEG), word(p.theta, reg.SCALE_DEG)]
        words += [word(r[0], reg.SCALE_MM), word(r[1], reg.SCALE_DEG), word(r[2], reg.SCALE_DEG)]
        ms = int(self.time * 1000.0) & 0xFFFFFFFF
        words += [self.status, self.fault, self.cycle, ms >> 16, ms & 0xFFFF]
        return words

    def command_words(self) -> list[int]:
        """The 11 holding registers as the PLC currently holds them."""
        sp = self.sp_pose
        values = [
            round(sp.z / reg.SCALE_MM),
            round(sp.phi / reg.SCALE_DEG),
            round(sp.theta / reg.SCALE_DEG),
            int(self.joint_mode),
            *(round(b / reg.SCALE_BETA) for b in self.sp_beta),
            round(self.watchdog * 1000.0),
            self.speed_pct,
            self.wave_seed,
            0,
        ]
        return [v & 0xFFFF for v in values]

    def apply_commands(self, words: list[int]) -> None:
        """Take a full, validated holding block (raw words) as the new commands."""
        signed = [
            int(reg.from_register(w)) if i not in reg.UNSIGNED else w for i, w in enumerate(words)
        ]
        self.sp_pose = PlatformPose(
            signed[0] * reg.SCALE_MM, signed[1] * reg.SCALE_DEG, signed[2] * reg.SCALE_DEG
        )
        self.joint_mode = bool(signed[3])
        self.sp_beta = np.array(signed[4:7], dtype=np.float64) * reg.SCALE_BETA
        self.watchdog = signed[7] / 1000.0
        self.speed_pct = signed[8]
        self.wave_seed = signed[9]
        self.master_alive()

    def check_commands(self, words: list[int]) -> str | None:
        """Why a holding block is refused (None when it may be applied): the register ranges
        and the watchdog, which a write may shorten (down to 1 ms) but not lengthen beyond the
        start-up value nor switch off, unless it was started off."""
        why = validate_commands(words)
        if why is not None:
            return why
        ms = words[reg.HOLDING["WATCHDOG"]]
        limit = round(self.watchdog_limit * 1000.0)
        if limit > 0 and not 1 <= ms <= limit:
            return f"WATCHDOG = {ms} ms: 1…{limit} (off or longer only by a start-up option)"
        return None


def validate_commands(words: list[int]) -> str | None:
    """Why a holding block is refused by the register ranges alone (None: all in range)."""
    for i, word in enumerate(words):
        lo, hi = reg.HOLDING_LIMITS[i]
        value = word if i in reg.UNSIGNED else int(reg.from_register(word))
        if not lo <= value <= hi:
            return f"holding register {i} = {value} outside {lo}…{hi}"
    return None
