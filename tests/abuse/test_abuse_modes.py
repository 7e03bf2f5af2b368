"""Abuse suite for the wire-faithful mode (``--wire kvp9``) and C3 Bridge (``--proxy
c3bridge``), as ``test_abuse_emulator.py`` is for the KVP core: the emulator in a subprocess,
a bystander in a process of its own, the abusers here.

Held to account in every scenario: the emulator survives and still stops cleanly; the
bystander never sees an error or a wrong value; the emulator's *peak* resident memory during
the abuse (``VmHWM``, reset just before) grows by at most 50 MB; the abusers' own counters
(errors, wrong replies, replies at all) are what a correct server gives them.

Latency is compared with a reference measured in the same module on the same machine (the
suite runs on loaded 2-core machines, where no fixed number of milliseconds holds): the
bystander's p99 while ten clients flood pipelined reads of the 24 KB ``$IN[]`` through the
robust framing, whose per-iteration work budget is the emulator's own promise (``server.py``,
docs/emulator.md "Bounds"). Under every abuse here the bystander's p99 must stay within
``bound(reference)`` — 20 ms on a quiet machine — which fails by far when one abuser stalls
the event loop (a blocking 64 KiB select left the bystander without an answer for seconds, a
kvp9 flood held it 110 ms where the robust mode held it 3 ms). Both p99s are of the *net*
round trips (:class:`kukavarproxy_emu.abuse.ProbeResult`: less the time the emulator's event
loop and the bystander waited for a core), as in ``test_abuse_emulator.py``: the time other
processes of a loaded machine take is not the emulator's, a stalled event loop still is.
"""

from __future__ import annotations

import asyncio
import sys
from collections.abc import Callable, Coroutine, Iterator
from typing import Any

import pytest

from kukavarproxy_emu.abuse import (
    Abuser,
    AbuseTally,
    EmulatorProcess,
    ProbeResult,
    big_module,
    c3_garbage,
    c3_selects,
    garbage,
    in_flood,
    long_names,
    non_reader,
)
from kukavarproxy_emu.abuse import modes as abuse_modes
from pyopenshowvar import sync

pytestmark = [
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RSS from /proc"),
    pytest.mark.timeout(120),
]

SECONDS = 2.5
MIN_REQUESTS = 60
PEAK_GROWTH_MB = 50.0
P99_MS = 20.0
CONFIG = "DEFDAT $CONFIG\nDECL INT ABUSE_PROBE=0\nENDDAT\n"
MODULE = "/R1/BIGMOD"


def bound(reference_p99: float) -> float:
    """What the bystander's p99 may be under abuse, from its p99 under the reference flood
    measured in this module: 20 ms on a quiet machine, more on a loaded one."""
    return max(P99_MS, 2.0 * reference_p99 + 10.0)


def run_abuse(
    emu: EmulatorProcess,
    abusers: list[Abuser],
    seconds: float = SECONDS,
    done: Callable[[AbuseTally], bool] | None = None,
) -> tuple[ProbeResult, AbuseTally, float]:
    """The abuse for ``seconds`` and then until ``done(tally)``: a slow machine makes a
    scenario longer, never its counts smaller; the bystander times at least MIN_REQUESTS."""
    return abuse_modes.run_abuse(emu, abusers, seconds, done=done, min_requests=MIN_REQUESTS)


def check_bystander(result: ProbeResult, growth: float, limit_ms: float, what: str) -> None:
    print(
        f"{what}: bystander p50/p99/max {result.p50_ms:.1f}/{result.p99_ms:.1f}/"
        f"{result.max_ms:.1f} ms (net p99 {result.net_p99_ms:.1f} ms) over {result.requests}"
        f" requests (net p99 bound {limit_ms:.1f} ms),"
        f" peak RSS growth {growth:+.1f} MB"
    )
    assert result.errors == 0 and result.wrong == 0, result.notes
    assert result.requests >= MIN_REQUESTS, result
    assert result.net_p99_ms <= limit_ms, (what, result, limit_ms)
    assert growth <= PEAK_GROWTH_MB, growth


@pytest.fixture(scope="module")
def config(tmp_path_factory: pytest.TempPathFactory) -> str:
    dat = tmp_path_factory.mktemp("abuse_modes") / "abuse.dat"
    dat.write_text(CONFIG)
    return str(dat)


def _emulator(*args: str) -> Iterator[EmulatorProcess]:
    emu = EmulatorProcess(*args).start()
    try:
        result, _, _ = run_abuse(emu, [], seconds=0.5)  # warm up
        assert result.errors == 0 and result.wrong == 0, result.notes
        yield emu
    finally:
        assert emu.alive()
        assert emu.stop() == 0  # and it still stops cleanly on SIGTERM


@pytest.fixture(scope="module")
def c3(config: str) -> Iterator[EmulatorProcess]:
    yield from _emulator("--proxy", "c3bridge", "--config", config)


@pytest.fixture(scope="module")
def kvp9(config: str) -> Iterator[EmulatorProcess]:
    yield from _emulator("--wire", "kvp9", "--config", config, "--max-clients", "30")


@pytest.fixture(scope="module")
def reference(config: str) -> float:
    """The bystander's net p99 (ms) under the reference flood (see the module docstring)."""
    for emu in _emulator("--config", config, "--max-clients", "30"):
        result, tally, _ = run_abuse(emu, [in_flood] * 10, done=lambda t: t.replies > 500)
        assert result.errors == 0 and result.wrong == 0, result.notes
        assert tally.errors == 0 and tally.wrong == 0 and tally.replies > 500, tally
        print(f"reference (robust mode, $IN[] flood): bystander net p99 {result.net_p99_ms:.1f} ms")
    return result.net_p99_ms


# ------------------------------------------------------------------------ --wire kvp9


def test_kvp9_flood_of_whole_array_reads_is_bounded_like_the_robust_mode(
    reference: float, kvp9: EmulatorProcess
) -> None:
    """The reference flood against the wire-faithful mode: it keeps the robust mode's
    per-iteration budget, so the bystander fares as there (it used to see a p99 of 110 ms
    against the robust mode's 3 ms on a quiet machine)."""
    result, tally, growth = run_abuse(kvp9, [in_flood] * 10, done=lambda t: t.replies > 500)
    check_bystander(result, growth, bound(reference), "kvp9 $IN[] flood")
    # the flooders are served too (not dropped: they read their replies), none saw a wrong one
    assert tally.errors == 0 and tally.wrong == 0 and tally.replies > 500, tally


def test_kvp9_garbage_and_clients_that_do_not_read(reference: float, kvp9: EmulatorProcess) -> None:
    abusers: list[Abuser] = [
        lambda h, p, t, seed=seed: garbage(h, p, t, seed=seed) for seed in range(2)
    ]
    abusers += [non_reader] * 4
    result, tally, growth = run_abuse(kvp9, abusers, done=lambda t: t.errors >= 4)
    check_bystander(result, growth, bound(reference), "kvp9 garbage + non-readers")
    # KVP drops a client that does not read (its failed Write): each non-reader ends in an
    # error of its own, and nothing else does (garbage never closes a kvp9 connection)
    assert 4 <= tally.connections and tally.errors == 4, tally
    assert tally.wrong == 0


# ------------------------------------------------------------------------ C3 Bridge


def test_c3_selects_of_a_64_kib_module_do_not_stall_other_clients(
    reference: float, c3: EmulatorProcess
) -> None:
    """Eight clients selecting a 64 KiB module again and again: each select parses for about
    0.2 s, in slices; the bystander is answered between them (it used to wait seconds)."""
    with sync.Client(c3.host, c3.port, timeout=10.0, keepalive=None) as kvp:
        kvp.program_upload(big_module("BIGMOD", 64 * 1024 - 512), "BIGMOD.src")

    def selects(h: str, p: int, t: AbuseTally) -> Coroutine[Any, Any, None]:
        return c3_selects(h, p, t, module=MODULE)

    result, tally, growth = run_abuse(c3, [selects] * 8, done=lambda t: t.replies >= 1)
    check_bystander(result, growth, bound(reference), "C3 64 KiB selects")
    # every answer the selecting clients got was a success with their tag; at least one
    # select went through in the time (about 0.2 s of work each; more on a loaded machine)
    assert tally.errors == 0 and tally.wrong == 0 and tally.replies >= 1, tally
    assert tally.connections == 8


def test_c3_malformed_messages_and_long_names(reference: float, c3: EmulatorProcess) -> None:
    abusers: list[Abuser] = [
        lambda h, p, t, seed=seed: c3_garbage(h, p, t, seed=seed) for seed in range(3)
    ]
    abusers.append(long_names)
    result, tally, growth = run_abuse(c3, abusers, done=lambda t: t.replies >= 20)
    check_bystander(result, growth, bound(reference), "C3 malformed messages")
    # C3 Bridge answers every message of a handled type, malformed or not: no connection of
    # the garbage clients was closed on them, every reply carried its tag
    assert tally.errors == 0 and tally.wrong == 0, tally
    # one message at a time each, some of them 10 000-operation benchmarks: a few hundred
    # replies on a quiet machine, tens on a loaded one
    assert tally.replies >= 20, tally


def test_c3_clients_that_do_not_read(reference: float, c3: EmulatorProcess) -> None:
    result, tally, growth = run_abuse(c3, [non_reader] * 8, done=lambda t: t.requests >= 8 * 200)
    check_bystander(result, growth, bound(reference), "C3 non-readers")
    # output backpressure: the emulator stops reading them, never drops or grows
    assert tally.errors == 0 and tally.connections == 8, tally
    assert tally.requests >= 8 * 200


def test_the_abusers_count_what_they_should(config: str) -> None:
    """The counters the scenarios rely on are not blind: a select of a module that does not
    exist is counted wrong, and a server that is not there is an error."""

    async def select_missing(host: str, port: int, tally: AbuseTally) -> None:
        task = asyncio.create_task(c3_selects(host, port, tally, module="/R1/NOPE"))
        for _ in range(2000):  # two answers (refusals) or 20 s
            if tally.replies >= 2:
                break
            await asyncio.sleep(0.01)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)

    for emu in _emulator("--proxy", "c3bridge", "--config", config):
        tally = AbuseTally()
        asyncio.run(select_missing(emu.host, emu.port, tally))
        assert tally.replies >= 2 and tally.wrong >= 2 and tally.errors == 0, tally
        port = emu.port
    tally = AbuseTally()
    asyncio.run(in_flood("127.0.0.1", port, tally))  # the emulator is gone: refused
    assert tally.errors == 1 and tally.replies == 0
