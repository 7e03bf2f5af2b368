"""Access-time statistics for one connection.

Control loops need the access time Δt continuously (thesis eq. 4.2: x_t = x_a + ẋ_d·Δt), and
users want the thesis' Figure 4.17 analysis (mean, spread, histogram) without extra tooling.
Recording must be cheap because it runs on every reply: a bounded window of recent samples for
percentiles, running totals for the all-time mean, and an exponentially weighted mean as the
"current Δt" estimate.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

__all__ = ["AccessStats", "StatsSnapshot"]


@dataclass(frozen=True, slots=True)
class StatsSnapshot:
    """A consistent copy of the statistics, all times in seconds."""

    count: int
    mean: float
    ewma: float
    minimum: float
    maximum: float
    p50: float
    p90: float
    p99: float
    window: int

    def as_ms(self) -> dict[str, float]:
        """The times in milliseconds, handy for printing a table."""
        return {
            "count": self.count,
            "mean": self.mean * 1e3,
            "ewma": self.ewma * 1e3,
            "min": self.minimum * 1e3,
            "max": self.maximum * 1e3,
            "p50": self.p50 * 1e3,
            "p90": self.p90 * 1e3,
            "p99": self.p99 * 1e3,
        }


def _percentile(ordered: list[float], q: float) -> float:
    """Linear-interpolated percentile (same definition as numpy's default)."""
    if not ordered:
        return math.nan
    pos = (len(ordered) - 1) * q
    lo = int(pos)
    hi = min(lo + 1, len(ordered) - 1)
    return ordered[lo] + (ordered[hi] - ordered[lo]) * (pos - lo)


class AccessStats:
    """Round-trip times of the requests on one connection.

    ``window`` recent samples are kept for percentiles and histograms; count, mean, min and max
    cover the whole life of the connection. ``alpha`` is the weight of a new sample in the EWMA.
    """

    def __init__(self, window: int = 10_000, alpha: float = 0.1) -> None:
        self._recent: deque[float] = deque(maxlen=window)
        self._alpha = alpha
        self.reset()

    def reset(self) -> None:
        self._recent.clear()
        self.count = 0
        self.total = 0.0
        self.minimum = math.inf
        self.maximum = 0.0
        self.ewma = math.nan

    def record(self, seconds: float) -> None:
        self._recent.append(seconds)
        self.count += 1
        self.total += seconds
        if seconds < self.minimum:
            self.minimum = seconds
        if seconds > self.maximum:
            self.maximum = seconds
        # The first sample seeds the EWMA so Δt is usable from the first reply on.
        self.ewma = (
            seconds if self.ewma != self.ewma else self.ewma + self._alpha * (seconds - self.ewma)
        )

    @property
    def mean(self) -> float:
        return self.total / self.count if self.count else math.nan

    def samples(self) -> list[float]:
        """The recent samples, oldest first."""
        return list(self._recent)

    def percentile(self, q: float) -> float:
        """``q`` in [0, 1] over the recent window."""
        return _percentile(sorted(self._recent), q)

    def snapshot(self) -> StatsSnapshot:
        ordered = sorted(self._recent)
        return StatsSnapshot(
            count=self.count,
            mean=self.mean,
            ewma=self.ewma,
            minimum=self.minimum if self.count else math.nan,
            maximum=self.maximum if self.count else math.nan,
            p50=_percentile(ordered, 0.50),
            p90=_percentile(ordered, 0.90),
            p99=_percentile(ordered, 0.99),
            window=len(ordered),
        )

    def histogram(
        self, bins: int = 20, *, upper: float | None = None
    ) -> list[tuple[float, float, int]]:
        """Equal-width bins over the recent window: ``(low, high, count)`` in seconds.

        ``upper`` clips the range (e.g. to the p99) so one stall does not squash every bar;
        samples above it are counted in the last bin.
        """
        data = list(self._recent)
        if not data:
            return []
        lo = min(data)
        hi = upper if upper is not None else max(data)
        if hi <= lo:
            return [(lo, lo, len(data))]
        width = (hi - lo) / bins
        counts = [0] * bins
        for x in data:
            counts[min(int((x - lo) / width), bins - 1)] += 1
        return [(lo + i * width, lo + (i + 1) * width, c) for i, c in enumerate(counts)]
