"""Where a serial read's time goes: the synchronous client against py-openshowvar.

``bench/client_roundtrip.py`` measures the whole round trip, which the emulator and the
scheduler dominate; this script puts the two clients side by side and takes their costs apart:

1. **the serial round trip, interleaved, 5 runs**: in every round each client reads once on
   the same emulator (order alternating), so drifts of the machine's load hit both alike; each
   run gives the ratio of the two medians, and the figure is **the median of the runs'
   ratios** (target ≤ 1.05: both clients make one send and one receive per read, so parity
   is the physical limit). Blocks of reads per client (``client_roundtrip.py``) spread by
   several µs between runs;
2. **the client's CPU per read against the emulator** (user + system time of this process,
   in alternating blocks of reads): what the client and the kernel's side of its two system
   calls cost, net of the emulator (a separate process), next to a bare socket's ``sendall``
   and ``recv`` of the same request (the floor under both clients);
3. **without the network**: ``read("$AXIS_ACT")`` on a connected client whose socket is
   replaced by an in-process fake that answers at once with the right id (the same fake for
   both clients): the client's own CPU per read (``process_time``, best and median of
   ``--repeat`` runs) and its time on the round trip's critical path (from the reply's
   delivery to the next request's send, median);
4. **system calls per read** against the emulator (``bench/_emu_server.py``, latency ``none``):
   each client runs in a child process under ``strace -c``, once with no reads and once with
   ``N`` reads, and the difference is divided by ``N`` (start-up cancels out). Skipped when
   ``strace`` is not installed or not permitted;
5. with ``--callgrind``: **instructions per read** of each client on the fake socket under
   valgrind's callgrind (two read counts, the difference divided by the reads between them):
   a count the machine's load does not disturb, unlike every clock above. About 3 minutes.

Run (the coordinator's command for the closing figures, on a quiet machine)::

    .venv/bin/python bench/sync_read_cost.py [--quick] [--repeat 5] [--callgrind] [--json out.json]
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import EmuProcess, Row, base_parser, median, print_rows, write_json

from pyopenshowvar import sync
from pyopenshowvar.blocking import BlockingConnection
from pyopenshowvar.protocol import Mode, Reply, encode_read, encode_reply

try:
    import py_openshowvar
except ImportError:  # optional peer (the `test` and `bench` extras install it)
    py_openshowvar = None

NAME = "$AXIS_ACT"
VALUE = (
    b"{E6AXIS: A1 0.0, A2 -90.0000, A3 90.0000, A4 0.0, A5 0.0, A6 0.0,"
    b" E1 0.0, E2 0.0, E3 0.0, E4 0.0, E5 0.0, E6 0.0}"
)


class _FakeSocket:
    """Answers every request at once with ``VALUE`` under the request's own id, and times the
    client's critical path: from a reply's delivery to the next request's send (what the
    client adds to a serial round trip; work between a send and its recv overlaps the server's)."""

    def __init__(self) -> None:
        self._tail = encode_reply(Reply(0, Mode.READ, VALUE))[2:]
        self._id = b"\0\0"
        self._delivered = 0.0
        self.critical: list[float] = []

    def sendall(self, data: bytes) -> None:
        now = time.perf_counter()
        if self._delivered:
            self.critical.append(now - self._delivered)
        self._id = data[:2]

    def recv(self, size: int) -> bytes:
        data = self._id + self._tail
        self._delivered = time.perf_counter()
        return data

    def setsockopt(self, *args: Any) -> None:
        pass

    def close(self) -> None:
        pass


class _Fake:
    """A client connected to a :class:`_FakeSocket`: ``read()`` and its socket."""

    def __init__(self, read: Callable[[], object], sock: _FakeSocket) -> None:
        self.read = read
        self.sock = sock

    def cpu(self, n: int) -> float:
        """CPU seconds per read (everything the client does, hidden or not)."""
        for _ in range(1000):
            self.read()
        read = self.read
        t0 = time.process_time()
        for _ in range(n):
            read()
        return (time.process_time() - t0) / n

    def critical(self, n: int) -> float:
        """Median seconds from a reply's delivery to the next request's send."""
        self.sock.critical.clear()
        read = self.read
        for _ in range(n):
            read()
        return median(self.sock.critical)


def _ours_fake() -> _Fake:
    client = sync.Client("127.0.0.1", 1, keepalive=None, id_policy="strict")
    conn = BlockingConnection("127.0.0.1", 1, keepalive=None, id_policy="strict")
    sock = _FakeSocket()
    conn._sock = sock  # type: ignore[assignment]
    conn.use_stats(client.stats)
    client._conn = conn
    assert client.read(NAME) == VALUE.decode()
    return _Fake(lambda: client.read(NAME), sock)


def _peer_fake() -> _Fake:
    assert py_openshowvar is not None
    client = py_openshowvar.openshowvar.__new__(py_openshowvar.openshowvar)
    client.msg_id = 1
    client.sock = sock = _FakeSocket()
    assert client.read(NAME, debug=False) == VALUE
    return _Fake(lambda: client.read(NAME, debug=False), sock)


# --------------------------------------------------------------------------- interleaved


def _pair(port: int) -> tuple[Callable[[], object], Callable[[], object], Callable[[], None]]:
    """Our client and py-openshowvar's, connected to ``port``: their reads and a closer."""
    assert py_openshowvar is not None
    peer = py_openshowvar.openshowvar("127.0.0.1", port)
    ours = sync.Client("127.0.0.1", port, keepalive=None)
    ours.connect()

    def close() -> None:
        ours.close()
        peer.close()

    return (lambda: ours.read(NAME)), (lambda: peer.read(NAME, debug=False)), close


def _interleaved(port: int, rounds: int) -> dict[str, float]:
    """Median round trip of each client when every round reads once with each (same drift)."""
    ours, peer, close = _pair(port)
    clients: list[tuple[str, Callable[[], object]]] = [("ours", ours), ("peer", peer)]
    times: dict[str, list[float]] = {"ours": [], "peer": []}
    clock = time.perf_counter
    try:
        for i in range(rounds + 200):
            clients.reverse()  # neither always goes first
            for key, read in clients:
                t0 = clock()
                read()
                if i >= 200:
                    times[key].append(clock() - t0)
    finally:
        close()
    return {k: median(v) for k, v in times.items()}


def _cpu_on_emulator(port: int, blocks: int, block: int = 500) -> dict[str, float]:
    """CPU seconds (user + system) of this process per read, each client in alternating blocks
    of ``block`` reads; the median block. The emulator runs in another process. ``raw`` is a
    bare socket's ``sendall`` + ``recv`` of the same request: the floor under both clients."""
    ours, peer, close = _pair(port)
    bare = socket.create_connection(("127.0.0.1", port))
    frame = encode_read(7, NAME)

    def raw() -> object:
        bare.sendall(frame)
        return bare.recv(65536)

    clients: list[tuple[str, Callable[[], object]]] = [("ours", ours), ("peer", peer), ("raw", raw)]
    cpu: dict[str, list[float]] = {key: [] for key, _ in clients}
    try:
        for i in range(blocks + 1):
            clients.insert(0, clients.pop())  # rotate: each takes every place in turn
            for key, read in clients:
                t0 = time.process_time()
                for _ in range(block):
                    read()
                if i:  # the first block of each warms up
                    cpu[key].append((time.process_time() - t0) / block)
    finally:
        close()
        bare.close()
    return {k: median(v) for k, v in cpu.items()}


# --------------------------------------------------------------------------- instructions

_CALLGRIND_CHILD = """
import sys
sys.path.insert(0, sys.argv[3])
import sync_read_cost as bench
fake = bench._ours_fake() if sys.argv[1] == "ours" else bench._peer_fake()
read = fake.read
for _ in range(int(sys.argv[2])):
    read()
"""


def _instructions(which: str, n: int) -> int:
    """Instructions executed by a child process that makes ``n`` reads on the fake socket."""
    out = subprocess.run(
        [
            "valgrind",
            "--tool=callgrind",
            "--callgrind-out-file=/dev/null",
            sys.executable,
            "-c",
            _CALLGRIND_CHILD,
            which,
            str(n),
            str(Path(__file__).resolve().parent),
        ],
        env={**os.environ, "PYTHONHASHSEED": "0"},
        capture_output=True,
        text=True,
        check=True,
    ).stderr
    match = re.search(r"Collected : (\d+)", out)
    assert match is not None, out[-2000:]
    return int(match.group(1))


def _instructions_per_read(which: str, n: int) -> float:
    """Per read: the difference of two runs (``n`` and ``6 n`` reads), so start-up, imports
    and the first reads (which learn the variable's shape) cancel out."""
    return (_instructions(which, 6 * n) - _instructions(which, n)) / (5 * n)


# --------------------------------------------------------------------------- system calls

_CHILD = """
import sys
from pyopenshowvar import sync
which, port, n = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
if which == "ours":
    c = sync.Client("127.0.0.1", port, keepalive=None)
    c.connect()
    read = lambda: c.read("$AXIS_ACT")
else:
    import py_openshowvar
    c = py_openshowvar.openshowvar("127.0.0.1", port)
    read = lambda: c.read("$AXIS_ACT", debug=False)
read()
for _ in range(n):
    read()
c.close()
"""


def _strace_calls(which: str, port: int, n: int) -> dict[str, int]:
    """System calls of the child process by name (strace -c summary)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "calls.txt"
        subprocess.run(
            [
                "strace",
                "-c",
                "-o",
                str(out),
                sys.executable,
                "-c",
                _CHILD,
                which,
                str(port),
                str(n),
            ],
            check=True,
            capture_output=True,
        )
        calls: dict[str, int] = {}
        for line in out.read_text().splitlines():
            parts = line.split()
            # "% time  seconds  usecs/call  calls  [errors]  syscall"
            if len(parts) >= 5 and parts[0][0].isdigit() and parts[-1] != "total":
                calls[parts[-1]] = int(parts[3])
        return calls


def _calls_per_read(which: str, port: int, n: int) -> dict[str, float]:
    base, loaded = _strace_calls(which, port, 0), _strace_calls(which, port, n)
    per = {k: (loaded.get(k, 0) - base.get(k, 0)) / n for k in loaded.keys() | base.keys()}
    return {k: v for k, v in sorted(per.items()) if abs(v) >= 0.01}


def _strace_works() -> bool:
    if shutil.which("strace") is None:
        return False
    probe = subprocess.run(["strace", "-c", "-o", "/dev/null", "true"], capture_output=True)
    return probe.returncode == 0


def run(quick: bool, repeat: int, callgrind: bool) -> tuple[list[Row], dict[str, Any]]:
    rows: list[Row] = []
    extra: dict[str, Any] = {}
    if py_openshowvar is not None:
        rows += _emulator_rows(quick)
    rows += _fake_rows(5_000 if quick else 200_000, repeat)
    if callgrind and shutil.which("valgrind") is not None:
        n = 200 if quick else 2000
        ours = _instructions_per_read("ours", n)
        peer = _instructions_per_read("peer", n) if py_openshowvar is not None else None
        rows.append(
            Row(
                "instructions per serial read, no network (callgrind)",
                ours,
                "instructions",
                peer=peer,
                peer_name="py-openshowvar",
                note="the fake socket's own Python code included (the same for both);"
                " independent of the machine's load",
            )
        )
    if _strace_works() and py_openshowvar is not None:
        reads = 200 if quick else 2000
        with EmuProcess("--latency", "none") as emu:
            ours_calls = _calls_per_read("ours", emu.port, reads)
            theirs = _calls_per_read("peer", emu.port, reads)
        extra["syscalls_per_read"] = {"ours": ours_calls, "py-openshowvar": theirs}
        rows.append(
            Row(
                "system calls per serial read (strace -c)",
                # per read, to the strace counts' resolution: start-up differences of a call or
                # two over the run must not read as a missed target
                round(sum(ours_calls.values()), 2),
                "calls",
                peer=round(sum(theirs.values()), 2),
                peer_name="py-openshowvar",
                target=("ratio", "<=", 1.0),
                note="ours "
                + ", ".join(f"{k} {v:.2f}" for k, v in ours_calls.items())
                + "; py-openshowvar "
                + ", ".join(f"{k} {v:.2f}" for k, v in theirs.items()),
            )
        )
    return rows, extra


def _emulator_rows(quick: bool, runs: int = 5) -> list[Row]:
    """The interleaved round trips (``runs`` runs, the median of their ratios) and the CPU
    per read against the emulator."""
    rounds = 400 if quick else 20_000
    results: list[dict[str, float]] = []
    with EmuProcess("--latency", "none") as emu:
        for _ in range(runs):
            results.append(_interleaved(emu.port, rounds))
        cpu = _cpu_on_emulator(emu.port, 2 if quick else 20, 100 if quick else 500)
    ratios = [r["ours"] / r["peer"] for r in results]
    return [
        Row(
            f"serial read round trip `$AXIS_ACT`, interleaved: median ratio of {runs} runs",
            median(ratios),
            "×",
            target=("ours", "<=", 1.05),
            runs=ratios,
            note="runs (ours / py-openshowvar, µs): "
            + ", ".join(
                f"{r['ours'] * 1e6:.1f}/{r['peer'] * 1e6:.1f} = {q:.3f}"
                for r, q in zip(results, ratios, strict=True)
            )
            + f"; {rounds} rounds each, one read per client per round, same emulator",
        ),
        Row(
            "serial read round trip `$AXIS_ACT`, interleaved (median of the runs' medians)",
            median([r["ours"] for r in results]) * 1e6,
            "µs",
            peer=median([r["peer"] for r in results]) * 1e6,
            peer_name="py-openshowvar",
            target=("ratio", "<=", 1.05),
        ),
        Row(
            "client CPU per serial read against the emulator (user + system, median block)",
            cpu["ours"] * 1e6,
            "µs",
            peer=cpu["peer"] * 1e6,
            peer_name="py-openshowvar",
            note="the client's work and the kernel's side of its send and recv (the emulator's"
            f" CPU is not counted); a bare socket's sendall + recv: {cpu['raw'] * 1e6:.1f} µs,"
            f" so the clients' own share: ours {(cpu['ours'] - cpu['raw']) * 1e6:.1f} µs,"
            f" py-openshowvar {(cpu['peer'] - cpu['raw']) * 1e6:.1f} µs",
        ),
    ]


def _fake_rows(n: int, repeat: int) -> list[Row]:
    """CPU per read and critical-path time on the in-process fake socket."""
    fakes = {"ours": _ours_fake()}
    if py_openshowvar is not None:
        fakes["peer"] = _peer_fake()
    cpu: dict[str, list[float]] = {k: [] for k in fakes}
    crit: dict[str, list[float]] = {k: [] for k in fakes}
    for _ in range(repeat):  # alternate, so load drifts hit both alike
        for key, fake in fakes.items():
            cpu[key].append(fake.cpu(n) * 1e6)
            crit[key].append(fake.critical(n) * 1e6)
    peer_cpu, peer_crit = cpu.get("peer"), crit.get("peer")
    return [
        Row(
            "client CPU per serial read, no network (best run)",
            min(cpu["ours"]),
            "µs",
            peer=min(peer_cpu) if peer_cpu else None,
            peer_name="py-openshowvar",
            runs=cpu["ours"],
            note=f"median of the runs: ours {median(cpu['ours']):.2f} µs"
            + (f", py-openshowvar {median(peer_cpu):.2f} µs" if peer_cpu else ""),
        ),
        Row(
            "client time on a serial read's critical path, no network (reply to next send, median)",
            median(crit["ours"]),
            "µs",
            peer=median(peer_crit) if peer_crit else None,
            peer_name="py-openshowvar",
            runs=crit["ours"],
            note="the client's share of a serial round trip: what it does between a send and"
            " its recv overlaps the server's work",
        ),
    ]


def main() -> None:
    ap = base_parser(__doc__)
    ap.add_argument(
        "--callgrind",
        action="store_true",
        help="also count instructions per read under valgrind (about 3 minutes)",
    )
    args = ap.parse_args()
    repeat = args.repeat or (1 if args.quick else 5)
    rows, extra = run(args.quick, repeat, args.callgrind)
    print_rows(f"Serial read cost (CPU: best of {repeat} runs)", rows)
    write_json(args.json, "sync_read_cost", rows, extra)


if __name__ == "__main__":
    main()
