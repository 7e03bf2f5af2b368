"""Access-time statistics: exact figures on known samples."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from pyopenshowvar.stats import AccessStats


def test_known_samples() -> None:
    s = AccessStats(window=100)
    for ms in (1, 2, 3, 4, 100):
        s.record(ms / 1000)
    snap = s.snapshot()
    assert snap.count == 5 and math.isclose(snap.mean, 0.022)
    assert snap.minimum == 0.001 and snap.maximum == 0.1
    assert math.isclose(snap.p50, 0.003)
    # EWMA, alpha 0.1: 1 -> 1.1 -> 1.29 -> 1.561 -> 11.4049 ms
    assert math.isclose(s.ewma, 0.0114049, rel_tol=1e-9)
    hist = s.histogram(bins=3, upper=0.004)
    assert [c for _, _, c in hist] == [1, 1, 3]  # 100 ms clipped into the last bin
    assert snap.as_ms()["max"] == 100


def test_ewma_converges_and_window_is_bounded() -> None:
    s = AccessStats(window=10, alpha=0.5)
    s.record(0.010)
    assert s.ewma == 0.010  # seeded by the first sample
    for _ in range(50):
        s.record(0.002)
    assert abs(s.ewma - 0.002) < 1e-9
    assert len(s.samples()) == 10 and s.count == 51


def test_empty_stats() -> None:
    snap = AccessStats().snapshot()
    assert snap.count == 0 and math.isnan(snap.mean) and math.isnan(snap.p99)
    assert AccessStats().histogram() == []


@given(st.lists(st.floats(0, 1), min_size=1, max_size=200), st.floats(0, 1))
def test_percentile_matches_numpy(xs: list[float], q: float) -> None:
    s = AccessStats()
    for x in xs:
        s.record(x)
    assert math.isclose(
        s.percentile(q), float(np.percentile(xs, q * 100)), rel_tol=1e-9, abs_tol=1e-12
    )
