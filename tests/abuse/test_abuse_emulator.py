"""Abuse suite, emulator side (issue 16): misbehaving clients and runaway KRL against
``kukavarproxy-emu`` in a subprocess, with a bystander client in its own process.

Every scenario asserts what the issue promises: the emulator's resident memory grows by at
most 50 MB, the bystander's round trips stay at p99 <= 20 ms and max <= 100 ms, and no reply
anyone reads carries a wrong value. The round trips are net of the machine's load: each less
the time the emulator's event loop and the bystander waited for a core (Linux schedstats,
:class:`~kukavarproxy_emu.abuse.ProbeResult`), so what remains is the emulator's own doing
(its work for the bystander, the abusers' work it did first, any idle wait with the request
unanswered) and the bound holds however busy the machine is; the emulator's CPU time per
round trip (the work it did before answering, exact on any machine) is held to the same bound.
The wall-clock figures are printed beside them.

Each scenario abuses for ``SECONDS`` and then until its abusers have really done their
damage (a count: connections, requests, replies), with the bystander probing all along and
timing at least ``MIN_REQUESTS`` round trips: a slow machine makes a scenario longer, never
weaker.
"""

from __future__ import annotations

import socket
import sys
from collections.abc import Callable, Coroutine, Iterator
from pathlib import Path
from typing import Any

import pytest

from kukavarproxy_emu.abuse import (
    RUNAWAY_KRL,
    AbuseTally,
    EmulatorProcess,
    ProbeResult,
    costly_pipeline,
    garbage,
    long_names,
    mode3_flood,
    non_reader,
    run_abuse,
)
from pyopenshowvar.protocol import ReplyDecoder, encode_read

pytestmark = [
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RSS from /proc"),
    pytest.mark.timeout(90),
]

SECONDS = 3.0
#: The bystander's smallest sample (its p99 is then at worst its 2nd-largest round trip).
MIN_REQUESTS = 150
#: However slow the machine, a scenario gives up after this long (the test then fails).
PATIENCE = 40.0
RSS_GROWTH_MB = 50.0
P99_MS = 20.0
MAX_MS = 100.0
CONFIG = "DEFDAT $CONFIG\nDECL INT ABUSE_PROBE=0\nDECL INT ABUSE_WORDS[32000]\nENDDAT\n"

Abuser = Callable[[str, int, AbuseTally], Coroutine[Any, Any, None]]


class Session:
    """One emulator subprocess and the RSS it had once warmed up."""

    def __init__(self, emu: EmulatorProcess) -> None:
        self.emu = emu
        self.baseline = 0.0

    def abuse(
        self,
        abusers: list[Abuser],
        seconds: float = SECONDS,
        done: Callable[[AbuseTally], bool] = lambda tally: True,
    ) -> tuple[ProbeResult, AbuseTally, float]:
        """Run the bystander and ``abusers`` together for ``seconds`` and until ``done(tally)``
        (at most ``PATIENCE`` seconds more); (probe result, tally, peak RSS growth during the
        abuse: the kernel's high-water mark, not what is left after it)."""
        return run_abuse(
            self.emu, abusers, seconds, done=done, patience=PATIENCE, min_requests=MIN_REQUESTS
        )

    def check(self, result: ProbeResult, tally: AbuseTally, growth: float) -> None:
        # the figures, for `pytest tests/abuse -s` (the closing notes quote them)
        print(
            f"bystander p50/p99/max net {result.net_p50_ms:.1f}/{result.net_p99_ms:.1f}/"
            f"{result.net_max_ms:.1f} ms, wall {result.p50_ms:.1f}/{result.p99_ms:.1f}/"
            f"{result.max_ms:.1f} ms, emulator CPU {result.cpu_p50_ms:.1f}/"
            f"{result.cpu_p99_ms:.1f}/{result.cpu_max_ms:.1f} ms over {result.requests} requests,"
            f" wrong {result.wrong + tally.wrong}, abusers' errors {tally.errors}, peak RSS"
            f" growth {growth:+.1f} MB"
            f" (since start {self.emu.rss_mb() - self.baseline:+.1f})"
        )
        assert self.emu.alive()
        assert result.errors == 0 and result.wrong == 0, result.notes
        assert result.requests >= MIN_REQUESTS, result
        assert result.net_p99_ms <= P99_MS and result.net_max_ms <= MAX_MS, result
        assert result.cpu_p99_ms <= P99_MS and result.cpu_max_ms <= MAX_MS, result
        # an attack that silently did nothing must not pass
        assert tally.wrong == 0 and tally.errors == 0, tally
        assert growth <= RSS_GROWTH_MB, growth
        assert self.emu.rss_mb() - self.baseline <= RSS_GROWTH_MB


def _session(*args: str) -> Iterator[Session]:
    emu = EmulatorProcess(*args).start()
    try:
        session = Session(emu)
        result, _, _ = session.abuse([], seconds=0.5)  # warm up: caches, first formatting
        assert result.wrong == 0 and result.errors == 0, result.notes
        session.baseline = emu.rss_mb()
        yield session
    finally:
        assert emu.stop() == 0  # and it still stops cleanly on SIGTERM


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Session]:
    dat = tmp_path_factory.mktemp("abuse") / "abuse.dat"
    dat.write_text(CONFIG)
    yield from _session("--config", str(dat), "--max-clients", "30")


def test_garbage_frames_with_a_bystander(session: Session) -> None:
    abusers: list[Abuser] = [
        lambda h, p, t, seed=seed: garbage(h, p, t, seed=seed) for seed in range(4)
    ]
    result, tally, growth = session.abuse(abusers, done=lambda t: t.connections > 20)
    session.check(result, tally, growth)
    assert tally.connections > 20  # the garbage really went in, connection after connection


def test_non_reading_clients(session: Session) -> None:
    result, tally, growth = session.abuse(
        [non_reader] * 10, done=lambda t: t.connections == 10 and t.requests >= 10 * 200
    )
    session.check(result, tally, growth)
    assert tally.connections == 10 and tally.requests >= 10 * 200


def test_distinct_long_names(session: Session) -> None:
    result, tally, growth = session.abuse([long_names, long_names], done=lambda t: t.replies >= 200)
    session.check(result, tally, growth)
    assert tally.replies >= 200  # 200 distinct 65 000-character names at least


def test_pipelined_costly_requests(session: Session) -> None:
    def words(h: str, p: int, t: AbuseTally) -> Coroutine[Any, Any, None]:
        return mode3_flood(h, p, t, name="ABUSE_WORDS")

    # The case (300 write/whole-array-read pairs in one segment, again and again) and
    # 64 KB mode-3 frames; the abusers run in this process, on the same two cores.
    result, tally, growth = session.abuse(
        [costly_pipeline, words], done=lambda t: t.replies >= 1200
    )
    session.check(result, tally, growth)
    assert tally.replies >= 1200  # at least two whole 300-pair segments


def _read(host: str, port: int, name: str) -> str:
    with socket.create_connection((host, port), timeout=5) as sock:
        sock.sendall(encode_read(1, name))
        decoder = ReplyDecoder()
        while not (replies := decoder.feed_replies(sock.recv(4096))):
            pass
    return replies[0].text


def test_runaway_krl(tmp_path: Path) -> None:
    src = tmp_path / "runaway.src"
    src.write_text(RUNAWAY_KRL)
    dat = tmp_path / "abuse.dat"
    dat.write_text(CONFIG)
    for session in _session("--config", str(dat), "--program", str(src)):
        result, tally, growth = session.abuse([])  # the robot program is the abuser
        session.check(result, tally, growth)
        emu = session.emu
        assert _read(emu.host, emu.port, "$PRO_STATE1") == "#P_ACTIVE"  # still running
