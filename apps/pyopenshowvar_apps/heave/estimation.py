"""What the control server knows about the platform and the robot: fits, prediction, delay.

* :class:`RecentFit` — a least-squares quadratic through the last ``window`` seconds of samples
  of one signal: its value, rate and acceleration at any time near now, with far less noise than
  a difference quotient and no lag for waves (a sine is locally quadratic).
* :class:`PlatformEstimator` — heave from the PLC (Modbus), roll and pitch from the PLC corrected
  by the accelerometer (or from either alone); :meth:`~PlatformEstimator.pose_at` evaluates the fits at
  any time, so the same call gives the pose "now" (for x_c, eq. 4.14) and the pose predicted for
  when a command will have been executed (the feed-forward). The board's low-pass delays its
  angles by about 1/(2π·f_c); the estimator shifts them back by that much.
* :class:`LagEstimator` — how long the robot takes to realise a command (KVP write, the KRL
  advance run, interpolation, servo): the shift that best aligns the measured base-frame flange
  positions with the commanded ones, re-estimated every half second while the robot moves.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from .geometry import FloatArray, PlatformPose

__all__ = ["ATTITUDES", "ClockMapper", "LagEstimator", "PlatformEstimator", "RecentFit"]

#: Physical bounds of any estimate: the legs' stroke (±130 mm) and a tilt the plate can reach.
MAX_HEAVE, MAX_TILT = 130.0, 15.0


class ClockMapper:
    """Maps a device's own clock (the PLC's TIME_MS, the board's millis()) onto ours.

    Samples reach us late by a varying amount (a busy network, USB packets, a starved process);
    the least-delayed sample seen fixes the offset, and the offset may creep up by ``drift``
    (s/s) so two clocks running at slightly different rates stay matched. The sample then
    counts at the moment it was taken, not when it arrived, so a burst of late samples still
    draws the right curve.
    """

    def __init__(self, drift: float = 2e-4) -> None:
        self.drift = drift
        self.offset: float | None = None
        self._last = 0.0

    def to_local(self, remote: float, received: float) -> float:
        candidate = received - remote
        if self.offset is None or remote < self._last - 1.0:  # first sample, or a restart
            self.offset = candidate
        else:
            self.offset = min(self.offset + self.drift * max(remote - self._last, 0.0), candidate)
        self._last = remote
        return remote + self.offset


class RecentFit:
    """Quadratic least-squares fit of (t, x) samples from the last ``window`` seconds."""

    def __init__(self, window: float = 0.4, max_samples: int = 256) -> None:
        self.window = window
        self._t: deque[float] = deque(maxlen=max_samples)
        self._x: deque[float] = deque(maxlen=max_samples)
        self._coef: FloatArray | None = None
        self._t_ref = 0.0

    def add(self, t: float, x: float) -> None:
        if self._t and t <= self._t[-1]:
            return  # a repeated sample (the PLC had not scanned since the last read)
        self._t.append(t)
        self._x.append(x)
        while self._t and self._t[0] < t - self.window:
            self._t.popleft()
            self._x.popleft()
        self._coef = None

    @property
    def ready(self) -> bool:
        return len(self._t) >= 1

    @property
    def last_time(self) -> float:
        return self._t[-1] if self._t else -math.inf

    def _fit(self) -> FloatArray:
        if self._coef is None:
            t = np.fromiter(self._t, float)
            x = np.fromiter(self._x, float)
            self._t_ref = float(t[-1])
            # a quadratic needs enough points to average its noise; a line does with fewer
            degree = 2 if len(t) >= 6 else min(1, len(t) - 1)
            if degree <= 0 or float(t[-1] - t[0]) < 1e-6:
                self._coef = np.array([0.0, 0.0, float(x[-1])])
            else:
                h = t - self._t_ref
                design = np.vander(h, degree + 1)  # columns h², h, 1 (or h, 1)
                coef = np.linalg.lstsq(design, x, rcond=None)[0]
                self._coef = np.concatenate([np.zeros(3 - len(coef)), coef])
        return self._coef

    def at(self, t: float) -> float:
        """The fitted value at ``t`` (extrapolated past the last sample)."""
        if not self._t:
            return 0.0
        a, b, c = self._fit()
        h = t - self._t_ref
        return float(a * h * h + b * h + c)

    def rate(self, t: float) -> float:
        if not self._t:
            return 0.0
        a, b, _ = self._fit()
        return float(2.0 * a * (t - self._t_ref) + b)


ATTITUDES = ("fused", "accel", "plc")


class PlatformEstimator:
    """Heave, roll and pitch of the platform from the PLC and the accelerometer stream.

    Heave always comes from the PLC (the thesis: forward kinematics of the measured joints, over
    Modbus). Roll and pitch, by ``attitude``:

    * ``"accel"`` — the accelerometer alone, as in the thesis. Its angles are noisy (≈0.1° after
      the board's filter), so they are fitted over a longer window (``accel_window``), which
      suits the thesis' slow waves and lags fast ones;
    * ``"plc"`` — the PLC's forward kinematics alone (noise-free, blind to anything the joint
      encoders do not see: a compliant plate, a mis-mounted sensor, a tilted floor);
    * ``"fused"`` — a complementary filter: the PLC's angles carry the motion and the
      accelerometer corrects their slowly varying offset (time constant ``fuse_tau``), so the
      estimate is as quick as the PLC and as absolute as the accelerometer.
    """

    def __init__(
        self,
        *,
        attitude: str = "fused",
        window: float = 0.15,
        accel_window: float = 1.0,
        accel_lag: float = 0.0,
        fuse_tau: float = 2.0,
    ) -> None:
        if attitude not in ATTITUDES:
            raise ValueError(f"attitude must be one of {', '.join(ATTITUDES)}, not {attitude!r}")
        self.attitude = attitude
        self.accel_lag = accel_lag
        self.fuse_tau = fuse_tau
        self.z = RecentFit(window)
        angle_window = accel_window if attitude == "accel" else window
        self.phi = RecentFit(angle_window)
        self.theta = RecentFit(angle_window)
        #: fused: accelerometer minus PLC angle, low-passed (deg)
        self.offset = np.zeros(2)
        self._last_accel: float | None = None

    def add_plc(self, t: float, z: float, phi: float, theta: float) -> None:
        self.z.add(t, z)
        if self.attitude != "accel":
            self.phi.add(t, phi)
            self.theta.add(t, theta)

    def add_accel(self, t: float, roll: float, pitch: float) -> None:
        t_true = t - self.accel_lag
        if self.attitude == "accel":
            self.phi.add(t_true, roll)
            self.theta.add(t_true, pitch)
        elif self.attitude == "fused" and self.phi.ready:
            diff = np.array([roll - self.phi.at(t_true), pitch - self.theta.at(t_true)])
            if self._last_accel is None:
                self.offset = diff
            else:
                gain = 1.0 - math.exp(-max(t - self._last_accel, 0.0) / self.fuse_tau)
                self.offset += gain * (diff - self.offset)
            self._last_accel = t

    @property
    def ready(self) -> bool:
        accel_ok = (
            self.attitude == "plc" or self._last_accel is not None or self.attitude == "accel"
        )
        return self.z.ready and self.phi.ready and self.theta.ready and accel_ok

    def pose_at(self, t: float, *, max_ahead: float = math.inf) -> PlatformPose:
        """The pose at ``t``, extrapolating at most ``max_ahead`` seconds past each signal's
        newest sample, and never beyond what the platform can do (its stroke, ±15°)."""
        z, phi, theta = (
            fit.at(min(t, fit.last_time + max_ahead)) for fit in (self.z, self.phi, self.theta)
        )
        if self.attitude == "fused":
            phi, theta = phi + self.offset[0], theta + self.offset[1]
        return PlatformPose(
            min(max(z, -MAX_HEAVE), MAX_HEAVE),
            min(max(phi, -MAX_TILT), MAX_TILT),
            min(max(theta, -MAX_TILT), MAX_TILT),
        )


class LagEstimator:
    """Delay (s) between commanded and measured base-frame flange positions."""

    def __init__(
        self,
        initial: float = 0.05,
        *,
        window: float = 3.0,
        max_lag: float = 0.3,
        step: float = 0.004,
        min_motion: float = 1.0,
        smoothing: float = 0.3,
    ) -> None:
        self.value = initial
        self.window, self.max_lag, self.step = window, max_lag, step
        self.min_motion, self.smoothing = min_motion, smoothing
        self._cmd: deque[tuple[float, FloatArray]] = deque(maxlen=4096)
        self._meas: deque[tuple[float, FloatArray]] = deque(maxlen=4096)
        self._next = 0.0
        self.updates = 0

    def command(self, t: float, xyz: FloatArray) -> None:
        self._cmd.append((t, np.asarray(xyz, float)))

    def measured(self, t: float, xyz: FloatArray) -> None:
        self._meas.append((t, np.asarray(xyz, float)))
        if t >= self._next:
            self._next = t + 0.5
            self._update(t)

    def _update(self, now: float) -> None:
        horizon = now - self.window
        cmd = [(t, x) for t, x in self._cmd if t >= horizon - self.max_lag]
        meas = [(t, x) for t, x in self._meas if t >= horizon]
        if len(cmd) < 8 or len(meas) < 8:
            return
        tc = np.array([t for t, _ in cmd])
        xc = np.stack([x for _, x in cmd])
        tm = np.array([t for t, _ in meas])
        xm = np.stack([x for _, x in meas])
        if float(np.max(np.ptp(xc, axis=0))) < self.min_motion:
            return  # the robot barely moved: nothing to learn from
        lags = np.arange(0.0, self.max_lag + 1e-9, self.step)
        shifted = tm[None, :] - lags[:, None]  # (L, M)
        err = np.zeros(len(lags))
        for k in range(3):
            err += np.mean((np.interp(shifted, tc, xc[:, k]) - xm[None, :, k]) ** 2, axis=1)
        best = float(lags[int(np.argmin(err))])
        self.value += self.smoothing * (best - self.value)
        self.updates += 1
