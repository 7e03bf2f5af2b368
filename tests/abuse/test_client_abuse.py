"""Abuse suite, client side: a misbehaving server against both clients (issue 16).

A seeded chaotic proxy answers most requests correctly but also sends replies for ids nobody
sent, sends a reply twice, swaps two replies, drops requests (alone or mid-batch), stalls and
closes connections in the middle of a batch. The clients (auto-reconnecting, short timeouts)
keep reading and writing through it. Asserted: not one wrong value returned as a success,
no unretrieved-future or other unhandled asyncio error, no failed future left alive, and
enough successes that the run means something. Bounded: a fixed number of rounds, ~2 s.
"""

from __future__ import annotations

import asyncio
import gc
import logging
import random
import threading

import pytest

from pyopenshowvar import Client, KvpError, sync
from pyopenshowvar.protocol import Mode, Reply, Request, encode_reply
from pyopenshowvar.testing import FakeProxy, ReadHandler, answer

ROUNDS = 80
NAMES = [f"V{i}" for i in range(24)]


def _chaos(seed: int, counts: dict[str, int]) -> ReadHandler:
    rng = random.Random(seed)
    # every kind at least once whatever the draws (they depend on how the client batches)
    forced = ["unsolicited", "twice", "swap", "drop", "stall", "close"]
    seen = [0]

    async def on_read(reqs: list[Request], w: asyncio.StreamWriter) -> None:
        frames: list[bytes] = []
        for r in reqs:
            act = rng.choices(
                ["ok", "unsolicited", "twice", "swap", "drop", "stall", "close"],
                [96, 1, 1, 1, 1, 0.5, 0.5],
            )[0]
            seen[0] += 1
            if seen[0] % 97 == 50 and forced and (forced[0] != "swap" or len(frames) >= 2):
                act = forced.pop(0)
            if r.name == "$OV_PRO":  # the client's id probe: answered, so ids are proven
                act = "ok"
            counts[act] = counts.get(act, 0) + 1
            if act == "close":
                w.write(b"".join(frames))
                w.transport.abort()
                return
            if act == "stall":
                await asyncio.sleep(0.15)
            if act == "drop":
                continue
            frames.append(answer(r))
            if act == "twice":
                frames.append(answer(r))
            elif act == "unsolicited":
                frames.append(encode_reply(Reply(60000 + rng.randrange(5000), Mode.READ, b"v:X")))
            elif act == "swap" and len(frames) >= 2:
                frames[-1], frames[-2] = frames[-2], frames[-1]
        w.write(b"".join(frames))

    return on_read


def _check(results: dict[str, object], wrong: list[str]) -> int:
    ok = 0
    for name, outcome in results.items():
        if isinstance(outcome, str):
            ok += 1
            if outcome != f"v:{name}":
                wrong.append(f"{name} -> {outcome}")
    return ok


async def _async_rounds(port: int, wrong: list[str]) -> int:
    rng = random.Random(7)
    ok = 0
    async with Client(port=port, timeout=0.1, auto_reconnect=True, keepalive=None) as kvp:
        for _ in range(ROUNDS):
            names = rng.sample(NAMES, rng.randint(1, len(NAMES)))
            try:
                res = await kvp.read_many(names)
                ok += _check({n: r.text if r.ok else r.error for n, r in res.items()}, wrong)
                value = str(rng.randrange(1000))
                echoed = await kvp.write("W", value)
                ok += _check({"W": "v:W" if echoed == value else echoed}, wrong)
                ok += _check({"S": await kvp.read("S")}, wrong)
            except KvpError:
                pass  # failing loudly is allowed; a wrong value is not
    return ok


def _sync_rounds(port: int, wrong: list[str]) -> int:
    rng = random.Random(8)
    ok = 0
    with sync.Client(port=port, timeout=0.1, auto_reconnect=True, keepalive=None) as kvp:
        for _ in range(ROUNDS):
            names = rng.sample(NAMES, rng.randint(1, len(NAMES)))
            try:
                res = kvp.read_many(names)
                ok += _check({n: r.text if r.ok else r.error for n, r in res.items()}, wrong)
                ok += _check({"S": kvp.read("S")}, wrong)
            except KvpError:
                pass
    return ok


@pytest.mark.timeout(30)
async def test_chaotic_server_never_yields_a_wrong_value(
    asyncio_errors: list[logging.LogRecord],
) -> None:
    counts: dict[str, int] = {}
    wrong: list[str] = []
    async with FakeProxy(on_read=_chaos(1, counts)) as port:
        ok = await _async_rounds(port, wrong)
    assert wrong == []
    assert ok > ROUNDS * 4, (ok, counts)  # many calls still succeed through the chaos
    assert all(counts.get(k, 0) > 0 for k in ("unsolicited", "twice", "swap", "drop", "close")), (
        counts
    )
    gc.collect()
    leaked = [
        o
        for o in gc.get_objects()
        if isinstance(o, asyncio.Future) and o.done() and not o.cancelled() and o.exception()
    ]
    assert leaked == []
    assert asyncio_errors == []  # no "Future exception was never retrieved", no send errors


@pytest.mark.timeout(30)
def test_chaotic_server_never_yields_a_wrong_value_sync() -> None:
    counts: dict[str, int] = {}
    wrong: list[str] = []
    with FakeProxy(on_read=_chaos(2, counts)) as port:
        ok = _sync_rounds(port, wrong)
    assert wrong == []
    assert ok > ROUNDS * 4, (ok, counts)
    assert all(counts.get(k, 0) > 0 for k in ("unsolicited", "twice", "swap", "drop", "close")), (
        counts
    )
    assert threading.active_count() < 20  # keep-alive threads end with their connections
