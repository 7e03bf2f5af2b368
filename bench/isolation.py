"""Isolation of the wire-faithful and C3 Bridge modes, and the legacy-id proxy's price.

The emulator runs in its own process (``kukavarproxy-emu``), the bystander
(:func:`kukavarproxy_emu.abuse.run_probe`: write/read-back/read, one request at a time, every
5 ms) in another; the abusers run in this process. Figures:

1. ``--wire kvp9`` (and, for comparison, ``--wire robust``): ten clients flooding pipelined
   reads of the 24 KB ``$IN[]`` (:func:`kukavarproxy_emu.abuse.in_flood`): the
   bystander's p50/p99/max and the emulator's peak RSS growth;
2. ``--proxy c3bridge``: eight clients selecting a 64 KiB module again and again
   (:func:`~kukavarproxy_emu.abuse.c3_selects`): bystander p50/p99/max, and the time of
   one such select alone;
3. ``--proxy c3bridge``: a #11 PTP to ``{A1 <400 digits>}`` — the reply's error code, or
   "closed" when the connection was closed without one;
4. ``--quirks legacy-ids --fault drop@4,conn=1``: ``read_many`` of four INTs with both
   clients — how many values of *other* variables came back as success;
5. the cost of the legacy-id rule: ``read_many`` of 20 INTs per second against an emulator
   that echoes ids (pipelined) and one with the pre-9.0 bug (one request in flight), without
   latency and with the ``kvp`` latency profile;
6. how long one event-loop iteration holds the loop, with the emulator in this process and
   the abusers in another: under the ``$IN[]`` flood the CPU time of the loop thread per
   iteration (``time.thread_time``, blind to other processes' load), for ``--wire kvp9`` and
   ``--wire robust``; during eight 64 KiB C3 selects the wall time per iteration (a select's
   slices run in a worker thread while the loop thread waits).

Like every benchmark it asserts nothing::

    .venv/bin/python bench/isolation.py [--quick] [--repeat 3] [--json out.json]
"""

from __future__ import annotations

import asyncio
import gc
import multiprocessing as mp
import socket
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import Row, base_parser, machine_info, median, print_rows, write_json

from kukavarproxy_emu import Emulator, EmulatorConfig
from kukavarproxy_emu.abuse import (
    AbuseTally,
    EmulatorProcess,
    ProbeResult,
    big_module,
    c3_selects,
    in_flood,
    run_abuse,
)
from pyopenshowvar import Client, sync
from pyopenshowvar.c3.messages import Motion, ProgramSelect
from pyopenshowvar.protocol import HEADER_SIZE, decode_reply

CONFIG = (
    "DEFDAT $CONFIG\nDECL INT ABUSE_PROBE=0\n"
    + "".join(f"DECL INT ISO_{i}={i * 11}\n" for i in range(1, 21))
    + "ENDDAT\n"
)
MODULE = "/R1/BIGMOD"


def _abuse(
    emu: EmulatorProcess, abusers: list[object], seconds: float
) -> tuple[ProbeResult, AbuseTally, float]:
    """Bystander + abusers for ``seconds``: (probe, tally, peak RSS growth in MB)."""
    return run_abuse(emu, abusers, seconds)  # type: ignore[arg-type]


#: The bystander's socket timeout (s): a probe that errs waited at least this long.
PROBE_TIMEOUT_MS = 2000.0


def _probe_rows(label: str, runs: list[tuple[ProbeResult, AbuseTally, float]]) -> list[Row]:
    # a bystander that timed out (it gives up after 2 s) counts as a p99 of at least 2 s
    p99 = [max(r.p99_ms, PROBE_TIMEOUT_MS) if r.errors else r.p99_ms for r, _, _ in runs]
    note = "; ".join(
        f"run {i + 1}: p50/p99/max {r.p50_ms:.1f}/{r.p99_ms:.1f}/{r.max_ms:.1f} ms, "
        f"{r.requests} requests, wrong {r.wrong + t.wrong}, errors {r.errors}/{t.errors}, "
        f"abuser replies {t.replies}, peak RSS +{g:.1f} MB"
        for i, (r, t, g) in enumerate(runs)
    )
    return [
        Row(f"{label}: bystander p99", median(p99), "ms", target=("ours", "<=", 20.0),
            note=note, runs=p99),
        Row(f"{label}: peak RSS growth", median([g for _, _, g in runs]), "MB",
            runs=[g for _, _, g in runs]),
    ]  # fmt: skip


def kvp9_flood(wire: str, seconds: float, repeat: int, config: str) -> list[Row]:
    runs = []
    with EmulatorProcess("--wire", wire, "--config", config, "--max-clients", "30") as emu:
        for _ in range(repeat):
            runs.append(_abuse(emu, [in_flood] * 10, seconds))
    return _probe_rows(f"--wire {wire}, 10 clients flooding $IN[] reads", runs)


def _upload(port: int, size: int) -> None:
    with sync.Client("127.0.0.1", port, timeout=10.0, keepalive=None) as kvp:
        kvp.program_upload(big_module("BIGMOD", size), "BIGMOD.src")


def _select_once(port: int) -> float:
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        start = time.perf_counter()
        sock.sendall(_program_select_frame())
        data = b""
        while len(data) < HEADER_SIZE or len(data) < HEADER_SIZE + int.from_bytes(data[2:4], "big"):
            data += sock.recv(65536)
        elapsed = time.perf_counter() - start
        assert decode_reply(data).ok, data
    return elapsed


def _program_select_frame() -> bytes:
    return ProgramSelect(MODULE).frame(7)


def c3_select(seconds: float, repeat: int, config: str, size: int) -> list[Row]:
    runs = []

    def selects(h: str, p: int, t: AbuseTally) -> object:
        return c3_selects(h, p, t, module=MODULE)

    with EmulatorProcess("--proxy", "c3bridge", "--config", config) as emu:
        _upload(emu.port, size)
        alone = [_select_once(emu.port) * 1e3 for _ in range(repeat)]
        for _ in range(repeat):
            runs.append(_abuse(emu, [selects] * 8, seconds))
            _select_once(emu.port)  # returns once the abusers' selects queued before it are done
    rows = _probe_rows(f"C3 Bridge, 8 clients selecting a {size // 1024} KiB module", runs)
    rows.append(Row(f"one select of the {size // 1024} KiB module, alone", median(alone), "ms",
                    runs=alone))  # fmt: skip
    return rows


def c3_motion_overflow() -> list[Row]:
    frame = Motion(1, "{A1 " + "9" * 400 + "}").frame(3)
    with EmulatorProcess("--proxy", "c3bridge") as emu:
        with socket.create_connection((emu.host, emu.port), timeout=5) as sock:
            sock.sendall(frame)
            data = b""
            try:
                while chunk := sock.recv(4096):
                    data += chunk
                    if len(data) >= HEADER_SIZE + int.from_bytes(data[2:4], "big") >= 4:
                        break
            except OSError:
                pass
        alive = emu.alive()
    if data:
        out = decode_reply(data)
        code = int.from_bytes(out.code, "big")
        note = f"answered: error code {code}, success flag {out.status}"
    else:
        code, note = -1, "closed without a reply"
    return [Row("#11 PTP {A1 <400 digits>}: error code (-1 = closed)", code, "",
                note=f"{note}; emulator alive: {alive}")]  # fmt: skip


NAMES4 = [f"ISO_{i}" for i in range(1, 5)]


def _wrong(results: dict[str, object]) -> int:
    wrong = 0
    for name, res in results.items():
        ok = getattr(res, "ok", False)
        if ok and res.text != str(int(name.split("_")[1]) * 11):  # type: ignore[attr-defined]
            wrong += 1
    return wrong


def legacy_drop(config: str) -> list[Row]:
    args = ("--config", config, "--quirks", "legacy-ids", "--fault", "drop@4,conn=1")
    with EmulatorProcess(*args) as emu:
        with sync.Client(emu.host, emu.port, timeout=0.5, keepalive=None) as kvp:
            res = kvp.read_many(NAMES4)
        sync_wrong = _wrong(dict(res))
        sync_outcome = ", ".join(
            f"{n}={r.text if r.ok else type(r.error).__name__}" for n, r in res.items()
        )
    with EmulatorProcess(*args) as emu:

        async def run() -> dict[str, object]:
            async with Client(emu.host, emu.port, timeout=0.5, keepalive=None) as kvp:
                return dict(await kvp.read_many(NAMES4))

        ares = asyncio.run(run())
        async_wrong = _wrong(ares)
        async_outcome = ", ".join(
            f"{n}={r.text if r.ok else type(r.error).__name__}"  # type: ignore[attr-defined]
            for n, r in ares.items()
        )
    return [
        Row("legacy ids + one dropped reply: wrong values, sync client", sync_wrong, "",
            target=("ours", "<=", 0), note=sync_outcome),
        Row("legacy ids + one dropped reply: wrong values, asyncio client", async_wrong, "",
            target=("ours", "<=", 0), note=async_outcome),
    ]  # fmt: skip


def _many_per_s(port: int, seconds: float) -> float:
    names = [f"ISO_{i}" for i in range(1, 21)]
    with sync.Client("127.0.0.1", port, timeout=5.0, keepalive=None) as kvp:
        kvp.read_many(names)  # the id probe is answered, the rule is known
        n = 0
        end = time.perf_counter() + seconds
        start = time.perf_counter()
        while time.perf_counter() < end:
            kvp.read_many(names)
            n += 1
        return n / (time.perf_counter() - start)


def legacy_cost(seconds: float, repeat: int, config: str) -> list[Row]:
    rows = []
    for latency in ("none", "kvp"):
        figures = {}
        for quirk in ((), ("--quirks", "legacy-ids")):
            args = ("--config", config, "--latency", latency, "--seed", "1", *quirk)
            with EmulatorProcess(*args) as emu:
                figures[bool(quirk)] = [_many_per_s(emu.port, seconds) for _ in range(repeat)]
        rows.append(Row(
            f"read_many of 20 INTs per s, latency {latency}: one in flight (legacy ids)",
            median(figures[True]), "/s", peer=median(figures[False]),
            peer_name="pipelined (ids echoed)", runs=figures[True],
            note=f"pipelined runs {[round(x, 1) for x in figures[False]]}",
        ))  # fmt: skip
    return rows


def _flood_process(port: int, seconds: float, module: str | None) -> None:
    async def main() -> None:
        tally = AbuseTally()
        if module is None:
            tasks = [asyncio.create_task(in_flood("127.0.0.1", port, tally)) for _ in range(10)]
        else:
            tasks = [
                asyncio.create_task(c3_selects("127.0.0.1", port, tally, module=module))
                for _ in range(8)
            ]
        await asyncio.sleep(seconds)
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)

    asyncio.run(main())


async def _iterations(config: EmulatorConfig, seconds: float, c3: bool, size: int) -> list[float]:
    """Seconds each event-loop iteration took (CPU of the loop thread, or wall time for C3)."""
    clock = time.perf_counter if c3 else time.thread_time
    gaps: list[float] = []
    async with Emulator(config) as emu:
        gc.collect()
        gc.freeze()  # as kukavarproxy-emu does: the start-up heap is never scanned again
        module = None
        if c3:
            assert emu.c3 is not None
            path = "KRC:\\R1\\Program\\BIGMOD.SRC"
            emu.c3.vfs.write(path, big_module("BIGMOD", size), overwrite=True)
            module = MODULE
        proc = mp.get_context("spawn").Process(
            target=_flood_process, args=(emu.port, seconds, module)
        )
        proc.start()
        t = clock()
        while proc.is_alive():
            await asyncio.sleep(0)
            now = clock()
            gaps.append(now - t)
            t = now
    gc.unfreeze()
    return sorted(gaps)


def loop_holds(seconds: float, repeat: int, size: int) -> list[Row]:
    rows = []
    base = EmulatorConfig(port=0, discovery=False, robot=False, max_clients=30)
    cases = [
        ("--wire kvp9, $IN[] flood: loop CPU per iteration", replace(base, wire="kvp9"), False),
        ("--wire robust, $IN[] flood: loop CPU per iteration", base, False),
        ("C3 Bridge, 8 selects: loop wall time per iteration",
         replace(base, proxy="c3bridge", robot=True, plant="ideal"), True),
    ]  # fmt: skip
    for label, config, c3 in cases:
        runs = [asyncio.run(_iterations(config, seconds, c3, size)) for _ in range(repeat)]
        worst = [g[-1] * 1e3 for g in runs]
        p99 = [g[int(len(g) * 0.99)] * 1e3 for g in runs]
        rows.append(Row(f"{label}, max", median(worst), "ms", runs=worst,
                        note=f"p99 per run {[round(x, 2) for x in p99]} ms"))  # fmt: skip
    return rows


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument("--seconds", type=float, default=None)
    ap.add_argument(
        "--only", nargs="*", default=None, help="kvp9 robust c3select motion legacy cost holds"
    )
    args = ap.parse_args()
    seconds = args.seconds or (1.0 if args.quick else 3.0)
    repeat = args.repeat or (1 if args.quick else 3)
    size = 8 * 1024 if args.quick else 64 * 1024 - 512
    only = set(args.only or ["kvp9", "robust", "c3select", "motion", "legacy", "cost", "holds"])
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as tmp:
        config = str(Path(tmp) / "iso.dat")
        Path(config).write_text(CONFIG)
        if "kvp9" in only:
            rows += kvp9_flood("kvp9", seconds, repeat, config)
        if "robust" in only:
            rows += kvp9_flood("robust", seconds, repeat, config)
        if "c3select" in only:
            rows += c3_select(seconds, repeat, config, size)
        if "motion" in only:
            rows += c3_motion_overflow()
        if "legacy" in only:
            rows += legacy_drop(config)
        if "cost" in only:
            rows += legacy_cost(seconds, repeat, config)
        if "holds" in only:
            rows += loop_holds(seconds, repeat, size)
    print_rows("Isolation of the kvp9 and C3 Bridge modes; legacy-id proxies", rows)
    write_json(args.json, "isolation", rows, {"machine": machine_info()})


if __name__ == "__main__":
    main()
