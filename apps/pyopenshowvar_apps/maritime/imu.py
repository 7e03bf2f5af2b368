"""The motion sensor a compensator reads: the vessel's η and ν with noise, bias and drift.

The crane-head paper's controller uses η = [x y z φ θ ψ] and ν = [u v w p q r] "from the
IMU" (its §7: accelerations integrated to velocities and positions, the drift removed by GNSS
aiding in an inertial navigation system); the paper's own simulation leaves measurement
errors out. Here every channel gets three errors, each drawn from its own seed:

* white **noise** (σ per sample);
* a constant **bias** drawn once per run (σ);
* a **drift**: a first-order Gauss–Markov process of stationary σ and time constant τ, the
  usual model of an aided INS's slowly wandering error (τ → ∞ makes it a random walk, the
  unaided integration drift).

The default figures are this toolkit's assumption for a marine-grade motion reference unit
(roll/pitch to a few hundredths of a degree, heave to a few centimetres), not a datasheet's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from .vessel import Motion

__all__ = ["IMU", "Channel", "Measurement"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Channel:
    """Error model of one group of three measured quantities (SI units)."""

    noise: float = 0.0
    bias: float = 0.0
    drift: float = 0.0
    tau: float = 100.0  # s; math.inf: random walk with σ(t) = drift·√(t/1 s)

    def scaled(self, k: float) -> Channel:
        return replace(self, noise=self.noise * k, bias=self.bias * k, drift=self.drift * k)

    def errors(self, t: FloatArray, rng: np.random.Generator) -> FloatArray:
        """The error of three channels along ``t``: ``(len(t), 3)``."""
        n = len(t)
        out = rng.normal(0.0, 1.0, (n, 3)) * self.noise + rng.normal(0.0, self.bias, 3)
        if self.drift > 0.0 and n > 1:
            dt = np.diff(t, prepend=t[0])
            w = rng.normal(0.0, 1.0, (n, 3))
            if math.isinf(self.tau):
                d = np.cumsum(w * self.drift * np.sqrt(dt)[:, None], axis=0)
            else:
                from scipy.signal import lfilter

                # d_i = a d_{i-1} + q w_i on a uniform grid; q keeps the stationary σ = drift
                a = math.exp(-float(np.median(dt[1:])) / self.tau)
                q = self.drift * math.sqrt(1.0 - a * a)
                w[0] = rng.normal(0.0, 1.0, 3) * self.drift / q  # start in the stationary law
                d = lfilter([q], [1.0, -a], w, axis=0)
            out = out + d
        return np.asarray(out)


DEG = math.pi / 180.0


@dataclass(frozen=True)
class IMU:
    """Error models of position, attitude, linear velocity and angular rate."""

    position: Channel = field(default_factory=lambda: Channel(0.01, 0.01, 0.02, 100.0))
    attitude: Channel = field(default_factory=lambda: Channel(0.01 * DEG, 0.01 * DEG, 0.02 * DEG))
    velocity: Channel = field(default_factory=lambda: Channel(0.01, 0.005, 0.005, 100.0))
    rate: Channel = field(default_factory=lambda: Channel(0.02 * DEG, 0.01 * DEG, 0.01 * DEG))

    @classmethod
    def ideal(cls) -> IMU:
        z = Channel()
        return cls(z, z, z, z)

    def scaled(self, k: float) -> IMU:
        """Every error multiplied by ``k`` (0: a perfect sensor)."""
        return IMU(*(c.scaled(k) for c in (self.position, self.attitude, self.velocity, self.rate)))

    def measure(self, motion: Motion, seed: int = 0) -> Measurement:
        """η̂ and ν̂ along the motion's record."""
        rng = np.random.default_rng(seed)
        t = motion.t
        nu = motion.nu()
        eta_hat = motion.eta.copy()
        nu_hat = nu.copy()
        eta_hat[:, :3] += self.position.errors(t, rng)
        eta_hat[:, 3:] += self.attitude.errors(t, rng)
        nu_hat[:, :3] += self.velocity.errors(t, rng)
        nu_hat[:, 3:] += self.rate.errors(t, rng)
        return Measurement(t, eta_hat, nu_hat, motion.eta, nu)


@dataclass
class Measurement:
    """What the controller reads (``eta``, ``nu``) and the truth it came from."""

    t: FloatArray
    eta: FloatArray
    nu: FloatArray
    eta_true: FloatArray
    nu_true: FloatArray
