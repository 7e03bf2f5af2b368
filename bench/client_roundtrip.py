"""Client benchmark: our asyncio client against py-openshowvar and JOpenShowVar-style access.

The emulator runs in a separate process (``bench/_emu_server.py``, same options as
``kukavarproxy-emu``). Figures, each the median of ``--repeat`` runs, ours and the peer's
measured alternately in the same run:

1. serial read round trip of ``$AXIS_ACT`` (one request in flight), latency ``none``, against
   ``py_openshowvar.openshowvar(ip, port).read(name, debug=False)``: the synchronous client
   ``pyopenshowvar.sync.Client.read`` (target ≤ 1.0×), the asyncio ``Client.read`` run by
   ``pyopenshowvar.run`` (uvloop when installed; target ≤ 1.5×), and the asyncio client on
   the stock asyncio loop (informative);
2. 100 variables (``MYE6ARRAY[1..100]``) in one ``read_many`` vs a loop of 100 py-openshowvar
   reads, latency ``none``;
3. ``read_joint_torques()`` vs six sequential element reads ``$TORQUE_AXIS_ACT[1..6]`` (what
   JOpenShowVar's ``readJointTorques`` does), our client for both, latency profile ``kvp``
   (seeded);
4. a read-modify-write control cycle (read ``$AXIS_ACT``, compute, write ``MYAXIS``) at the
   ``kvp`` profile vs the limit its service times allow: one worker serialises every request,
   so the best possible rate is 1 / (mean read + mean write service time, stalls included).

Run::

    .venv/bin/python bench/client_roundtrip.py [--quick] [--repeat 5] [--json out.json]
"""

from __future__ import annotations

import asyncio
import math
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import EmuProcess, Row, median, repeat_main

from kukavarproxy_emu.latency import PROFILES, LatencyProfile
from pyopenshowvar import Client, parse_value, sync
from pyopenshowvar import run as run_client

try:
    import py_openshowvar
except ImportError:  # optional peer (the `test` and `bench` extras install it)
    py_openshowvar = None

SEED = 1
E6AXIS_TEXT = "{E6AXIS: A1 10.5, A2 -80.25, A3 95.125, A4 0.0, A5 30.0, A6 -12.5, E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"


# --------------------------------------------------------------------------- latency none


async def _ours_serial(port: int, n: int) -> float:
    """Median seconds of one ``read`` with nothing else in flight."""
    async with Client("127.0.0.1", port, keepalive=None) as kvp:
        for _ in range(min(200, n)):
            await kvp.read("$AXIS_ACT")
        times = []
        clock = time.perf_counter
        for _ in range(n):
            t0 = clock()
            await kvp.read("$AXIS_ACT")
            times.append(clock() - t0)
    return median(times)


def _sync_serial(port: int, n: int) -> float:
    """Median seconds of one blocking ``read``."""
    with sync.Client("127.0.0.1", port, keepalive=None) as kvp:
        for _ in range(min(200, n)):
            kvp.read("$AXIS_ACT")
        times = []
        clock = time.perf_counter
        for _ in range(n):
            t0 = clock()
            kvp.read("$AXIS_ACT")
            times.append(clock() - t0)
    return median(times)


def _uvloop_name() -> str:
    try:
        import uvloop  # noqa: F401
    except ImportError:
        return "asyncio (uvloop not installed)"
    return "uvloop"


def _peer_serial(port: int, n: int) -> float:
    assert py_openshowvar is not None
    client = py_openshowvar.openshowvar("127.0.0.1", port)
    try:
        for _ in range(min(200, n)):
            client.read("$AXIS_ACT", debug=False)
        times = []
        clock = time.perf_counter
        for _ in range(n):
            t0 = clock()
            value = client.read("$AXIS_ACT", debug=False)
            times.append(clock() - t0)
        assert value and value.startswith(b"{"), value
    finally:
        client.close()
    return median(times)


async def _prepare_array(port: int, count: int) -> list[str]:
    names = [f"MYE6ARRAY[{i}]" for i in range(1, count + 1)]
    async with Client("127.0.0.1", port, keepalive=None) as kvp:
        await kvp.write_many([(n, E6AXIS_TEXT) for n in names])
    return names


async def _ours_many(port: int, names: list[str], calls: int) -> float:
    """Snapshots of ``len(names)`` variables per second with one ``read_many`` each."""
    async with Client("127.0.0.1", port, keepalive=None) as kvp:
        res = await kvp.read_many(names)
        assert all(r.ok for r in res.values())
        t0 = time.perf_counter()
        for _ in range(calls):
            await kvp.read_many(names)
        return calls / (time.perf_counter() - t0)


def _peer_many(port: int, names: list[str], calls: int) -> float:
    assert py_openshowvar is not None
    client = py_openshowvar.openshowvar("127.0.0.1", port)
    try:
        for name in names:
            assert client.read(name, debug=False)
        t0 = time.perf_counter()
        for _ in range(calls):
            for name in names:
                client.read(name, debug=False)
        return calls / (time.perf_counter() - t0)
    finally:
        client.close()


# --------------------------------------------------------------------------- latency kvp


async def _ours_torques(port: int, calls: int) -> float:
    async with Client("127.0.0.1", port, keepalive=None) as kvp:
        await kvp.read_joint_torques()
        t0 = time.perf_counter()
        for _ in range(calls):
            tau = await kvp.read_joint_torques()
        assert tau.shape == (6,)
        return calls / (time.perf_counter() - t0)


async def _six_reads_torques(port: int, calls: int) -> float:
    """JOpenShowVar's readJointTorques: six sequential element reads (our client, one at a time)."""
    names = [f"$TORQUE_AXIS_ACT[{i}]" for i in range(1, 7)]
    async with Client("127.0.0.1", port, keepalive=None) as kvp:
        await kvp.read(names[0])
        t0 = time.perf_counter()
        for _ in range(calls):
            tau = [float(parse_value(await kvp.read(n), "REAL")) for n in names]  # type: ignore[arg-type]
        assert len(tau) == 6
        return calls / (time.perf_counter() - t0)


async def _control_cycle(port: int, seconds: float) -> float:
    """Cycles/s of: read $AXIS_ACT, compute a new target, write MYAXIS (awaiting each)."""
    async with Client("127.0.0.1", port, keepalive=None) as kvp:
        await kvp.read("$AXIS_ACT")
        cycles = 0
        t0 = time.perf_counter()
        end = t0 + seconds
        while time.perf_counter() < end:
            q = await kvp.read_joint_angles()
            target = q.copy()
            target[0] = 5.0 * math.sin(cycles * 0.01)  # a slow sweep of A1, the rest held
            await kvp.write(
                "MYAXIS", "{" + ", ".join(f"A{i + 1} {v:.4f}" for i, v in enumerate(target)) + "}"
            )
            cycles += 1
        return cycles / (time.perf_counter() - t0)


def service_limit(profile: LatencyProfile) -> tuple[float, float, float]:
    """(mean read s, mean write s, cycles/s) a single serialising worker allows for read+write."""
    stall = 0.0
    if profile.stall_probability:
        lo, hi = profile.stall_min, profile.stall_max
        stall = profile.stall_probability * (hi - lo) / math.log(hi / lo)  # log-uniform mean
    read = profile.read.mean + stall
    write = profile.write.mean + stall
    return read, write, 1.0 / (read + write)


# --------------------------------------------------------------------------- main


def run(quick: bool, repeat: int) -> tuple[list[Row], dict[str, Any]]:
    rows = _latency_none(quick, repeat) + _kvp_profile(quick, repeat)
    return rows, {"seeds": [SEED + i for i in range(repeat)]}


def _latency_none(quick: bool, repeat: int) -> list[Row]:
    """Figures 1 and 2: serial round trips and ``read_many``, one emulator, no latency."""
    rows: list[Row] = []
    n_serial = 300 if quick else 3000
    many_calls = 3 if quick else 40
    has_peer = py_openshowvar is not None
    with EmuProcess("--latency", "none") as emu:
        sync_rt, fast_rt, ours_rt, peer_rt = [], [], [], []
        names = asyncio.run(_prepare_array(emu.port, 100))
        ours_many, peer_many = [], []
        for _ in range(repeat):
            # alternate the clients within each run, so load drifts hit all of them alike
            if has_peer:
                peer_rt.append(_peer_serial(emu.port, n_serial))
            sync_rt.append(_sync_serial(emu.port, n_serial))
            fast_rt.append(run_client(_ours_serial(emu.port, n_serial)))
            ours_rt.append(asyncio.run(_ours_serial(emu.port, n_serial)))
            ours_many.append(asyncio.run(_ours_many(emu.port, names, many_calls)))
            if has_peer:
                peer_many.append(_peer_many(emu.port, names, max(1, many_calls // 4)))
    peer = median(peer_rt) * 1e6 if peer_rt else None
    note = "" if has_peer else "py-openshowvar not installed: peer skipped"
    rows.append(
        Row(
            "serial read round trip `$AXIS_ACT`, sync client (latency none, median)",
            median(sync_rt) * 1e6,
            "µs",
            peer=peer,
            peer_name="py-openshowvar",
            target=("ratio", "<=", 1.0),
            runs=[x * 1e6 for x in sync_rt],
            note=note,
        )
    )
    rows.append(
        Row(
            f"same, asyncio client on {_uvloop_name()} (`pyopenshowvar.run`)",
            median(fast_rt) * 1e6,
            "µs",
            peer=peer,
            peer_name="py-openshowvar",
            target=("ratio", "<=", 1.5),
            runs=[x * 1e6 for x in fast_rt],
            note=note,
        )
    )
    rows.append(
        Row(
            "same, asyncio client on the stock asyncio loop (`asyncio.run`)",
            median(ours_rt) * 1e6,
            "µs",
            peer=peer,
            peer_name="py-openshowvar",
            runs=[x * 1e6 for x in ours_rt],
            note="informative: the stock loop's own cost per wake-up",
        )
    )
    rows.append(
        Row(
            "100 variables per call: `read_many` vs loop of reads",
            median(ours_many),
            "snapshots/s",
            peer=median(peer_many) if peer_many else None,
            peer_name="py-openshowvar loop",
            target=("ratio", ">=", 10.0),
            runs=ours_many,
            note=f"ours {1e3 / median(ours_many):.2f} ms per 100 variables"
            + (f", loop {1e3 / median(peer_many):.2f} ms" if peer_many else ""),
        )
    )
    return rows


def _kvp_profile(quick: bool, repeat: int) -> list[Row]:
    """Figures 3 and 4: torques and the control cycle, an emulator per run (seeded ``kvp``)."""
    rows: list[Row] = []
    profile = PROFILES["kvp"]
    t_read, t_write, limit = service_limit(profile)
    torque_calls = 8 if quick else 120
    cycle_seconds = 0.3 if quick else 4.0
    ours_tq, six_tq, cycles, cycles_robot = [], [], [], []
    for i in range(repeat):
        # the proxy model alone (--no-robot): nothing else competes for the emulator's loop
        with EmuProcess("--latency", "kvp", "--seed", str(SEED + i), "--no-robot") as emu:
            ours_tq.append(asyncio.run(_ours_torques(emu.port, torque_calls)))
            six_tq.append(asyncio.run(_six_reads_torques(emu.port, max(1, torque_calls // 4))))
            cycles.append(asyncio.run(_control_cycle(emu.port, cycle_seconds)))
        # the same cycle with the simulated robot following MYAXIS (the default emulator)
        with EmuProcess("--latency", "kvp", "--seed", str(SEED + i)) as emu:
            cycles_robot.append(asyncio.run(_control_cycle(emu.port, cycle_seconds)))
    rows.append(
        Row(
            "`read_joint_torques()` vs six sequential element reads (kvp)",
            median(ours_tq),
            "reads/s",
            peer=median(six_tq),
            peer_name="6 sequential reads",
            target=("ratio", ">=", 4.0),
            runs=ours_tq,
            note=f"ours {1e3 / median(ours_tq):.2f} ms, six reads {1e3 / median(six_tq):.2f} ms per torque vector",
        )
    )
    rows.append(
        Row(
            "read-modify-write cycle ($AXIS_ACT → MYAXIS, kvp, no robot) vs service-time limit",
            median(cycles),
            "cycles/s",
            peer=limit,
            peer_name="limit",
            runs=cycles,
            note=(
                f"limit = 1 / (mean read {t_read * 1e3:.3f} ms + mean write {t_write * 1e3:.3f} ms,"
                f" stalls included) = {limit:.1f} /s: a client with no turnaround of its own. The"
                " profile's samples are round trips as seen by a client, so this"
                " client's own time per cycle and the wake-ups of both processes count on top"
                " of them, as they would against a real KRC"
            ),
        )
    )
    rows.append(
        Row(
            "same cycle, emulator's simulated robot following MYAXIS, vs the cycle without it",
            median(cycles_robot),
            "cycles/s",
            peer=median(cycles),
            peer_name="no robot",
            target=("ratio", ">=", 0.95),
            runs=cycles_robot,
            note=(
                "the robot's tick runs in the shadow of booked replies and formats"
                " the polled texts, so it costs the cycle nothing measurable;"
                f" {median(cycles_robot) / limit:.3f} of the limit in this run"
            ),
        )
    )
    return rows


def main() -> None:
    repeat_main(__doc__, "Client (median of {repeat} runs)", "client", run, repeat=5)


if __name__ == "__main__":
    main()
