"""The latency model: sampler statistics (no wall time) and the global serialisation."""

from __future__ import annotations

import asyncio
import random
import statistics
import time

import pytest

from kukavarproxy_emu.latency import PROFILES, LatencyProfile, ServiceQueue, resolve_profile

# the fixtures (the root conftest may also load them as a plugin)
from kukavarproxy_emu.testing import *  # noqa: F403
from kukavarproxy_emu.testing import EmulatorFactory, RawClient
from pyopenshowvar.protocol import encode_read, encode_write

N = 40_000


def samples(profile: LatencyProfile, kind: str, seed: int = 1, n: int = N) -> list[float]:
    rng = random.Random(seed)
    return [profile.sample(kind, rng) * 1000 for _ in range(n)]  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("name", "kind", "median", "mean"),
    [
        ("kvp", "read", 2.3, 2.6),
        ("kvp", "write", 3.3, 3.6),
        ("thesis", "read", 4.2, 4.3),
        ("thesis", "write", 4.2, 4.3),
    ],
)
def test_profile_median_and_mean(name: str, kind: str, median: float, mean: float) -> None:
    ms = samples(PROFILES[name], kind)
    assert statistics.median(ms) == pytest.approx(median, abs=0.05)
    # stalls make the mean noisy; without them it sits on the documented value
    assert statistics.fmean(m for m in ms if m < 30) == pytest.approx(mean, abs=0.06)


def test_kvp_floor_and_stalls() -> None:
    ms = samples(PROFILES["kvp"], "read", n=200_000)
    assert min(ms) >= 1.5
    stalls = [m for m in ms if m >= 30]
    # p = 2e-4 → about 40 stalls in 200k requests, each within 30..600 ms (+ the body)
    assert 15 <= len(stalls) <= 80
    assert max(stalls) < 620


def test_sampler_is_reproducible() -> None:
    assert samples(PROFILES["kvp"], "write", seed=7, n=100) == samples(
        PROFILES["kvp"], "write", seed=7, n=100
    )
    assert samples(PROFILES["kvp"], "write", seed=7, n=100) != samples(
        PROFILES["kvp"], "write", seed=8, n=100
    )


def test_resolve_profile() -> None:
    assert resolve_profile("none") is None and resolve_profile(None) is None
    assert resolve_profile("KVP") is PROFILES["kvp"]
    fixed = resolve_profile("fixed:0.005")
    assert fixed is not None and fixed.sample("read", random.Random()) == 0.005
    for bad in ("fast", "fixed:x", "fixed:-1"):
        with pytest.raises(ValueError):
            resolve_profile(bad)


async def test_service_queue_throughput_does_not_drift() -> None:
    # 100 back-to-back 2 ms requests: chained deadlines keep the total near 0.2 s even though
    # each asyncio.sleep may overshoot by up to a millisecond.
    queue = ServiceQueue(LatencyProfile.fixed(0.002), random.Random(0))
    start = time.perf_counter()
    await asyncio.gather(*(queue.run("read", lambda: None) for _ in range(100)))
    assert 0.19 <= time.perf_counter() - start < 0.3
    assert queue.served == 100


async def _client_run(host: str, port: int, n: int) -> float:
    c = await RawClient.connect(host, port)
    start = time.perf_counter()
    for i in range(n):
        await c.request(encode_read(i, "$OV_PRO") if i % 2 else encode_write(i, "MYINT", "1"))
    elapsed = time.perf_counter() - start
    await c.close()
    return elapsed


async def test_global_serialisation(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(latency=LatencyProfile.fixed(0.01))
    alone = await _client_run(emu.host, emu.port, 10)
    together = await asyncio.gather(*(_client_run(emu.host, emu.port, 10) for _ in range(3)))
    assert 0.09 <= alone < 0.2
    # three clients share one worker: each sees about three times the latency
    for elapsed in together:
        assert 2.0 * alone <= elapsed <= 4.5 * alone


async def test_ping_costs_no_service_time(emulator_factory: EmulatorFactory) -> None:
    emu = await emulator_factory(latency=LatencyProfile.fixed(0.05))
    c = await RawClient.connect(emu.host, emu.port)
    start = time.perf_counter()
    await c.request(encode_read(1, "PING"))
    assert time.perf_counter() - start < 0.04
    await c.close()
