"""Abusive clients, a bystander probe and an emulator subprocess: the abuse suite's tools.

The abuse suite (``tests/abuse``) and the soak benchmark (``bench/soak.py``) check the
emulator's promises under attack — bounded memory, no stalls, never a wrong value — with:

* :class:`EmulatorProcess` — ``kukavarproxy-emu`` in a subprocess, so its resident memory
  (:meth:`~EmulatorProcess.rss_mb`) is the emulator's own;
* :func:`run_probe` / ``python -m kukavarproxy_emu.abuse probe`` — the bystander: a well-behaved
  client in its own process (no GIL shared with the abusers) that writes a counter, reads it
  back and reads ``$OV_PRO``, one request at a time, and reports every round trip's latency
  and every wrong value (:class:`ProbeResult`); given the emulator's process id (Linux) it
  also reports each round trip less the time the emulator and the probe waited for a core,
  which a busy machine does not inflate, and the emulator's CPU time per round trip;
* the abusers, coroutines that misbehave until cancelled and count what they see in an
  :class:`AbuseTally`: :func:`garbage`, :func:`non_reader`, :func:`long_names`,
  :func:`costly_pipeline`, :func:`mode3_flood`; :data:`RUNAWAY_KRL` is a robot program that
  never stops wasting time (slow functions, nested calls, a big local array).

Nothing here asserts: the suite and the soak decide what is acceptable.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Self

from pyopenshowvar.protocol import (
    Reply,
    ReplyDecoder,
    encode_read,
    encode_write,
    encode_write_array,
)

__all__ = [
    "RUNAWAY_KRL",
    "AbuseTally",
    "EmulatorProcess",
    "ProbeResult",
    "costly_pipeline",
    "cpu_clock",
    "garbage",
    "long_names",
    "mode3_flood",
    "non_reader",
    "run_probe",
    "start_probe",
]

#: A robot program that wastes its whole budget every cycle, forever: a function called in a
#: loop that runs 20 000 iterations calling another function, and a routine with a 200 000
#: element local array. It never ends and never fails.
RUNAWAY_KRL = """\
DEF RUNAWAY()
  DECL INT R
  LOOP
    R = SLOW()
    BIG()
  ENDLOOP
END

DEFFCT INT SLOW()
  DECL INT I, S
  S = 0
  FOR I = 1 TO 20000
    S = S + ONE()
  ENDFOR
  RETURN S
ENDFCT

DEFFCT INT ONE()
  RETURN 1
ENDFCT

DEF BIG()
  DECL INT A[200000]
  A[1] = 1
END
"""

_E6 = "{A1 %d.125, A2 -90.0625, A3 90.03125, A4 1.5, A5 2.5, A6 3.5, E1 0, E2 0, E3 0, E4 0}"


# --------------------------------------------------------------------------- the emulator


class EmulatorProcess:
    """``kukavarproxy-emu --port 0 ARGS...`` in a subprocess; ``with`` stops it (SIGTERM)."""

    def __init__(self, *args: str, env: dict[str, str] | None = None) -> None:
        self.args = list(args)
        self.env = env
        self.proc: subprocess.Popen[str] | None = None
        self.host = "127.0.0.1"
        self.port = 0

    def start(self) -> Self:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "kukavarproxy_emu", "--port", "0", *self.args],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            env={**os.environ, **(self.env or {}), "PYTHONUNBUFFERED": "1"},
        )
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline().strip()
        if not line.startswith("listening on "):
            self.proc.kill()
            raise RuntimeError(f"kukavarproxy-emu did not start: {line!r}")
        host, _, port = line.removeprefix("listening on ").rpartition(":")
        self.host, self.port = host, int(port)
        return self

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def rss_mb(self) -> float:
        """Resident set size in MB (Linux ``/proc``)."""
        for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024 / 1e6
        raise RuntimeError("no VmRSS")

    def stop(self) -> int | None:
        """SIGTERM and wait; the exit status (None if it had to be killed)."""
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
            return None

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


# --------------------------------------------------------------------------- the bystander


@dataclass
class ProbeResult:
    """What the bystander saw: round trips (ms) and every wrong value or error."""

    requests: int = 0
    p50_ms: float = 0.0
    p99_ms: float = 0.0
    max_ms: float = 0.0
    #: Replies with a wrong id, mode, status or value.
    wrong: int = 0
    #: Timeouts, lost connections, refused connects.
    errors: int = 0
    notes: list[str] = field(default_factory=list)
    #: With the emulator's process id (else 0): each round trip less the time the emulator's
    #: threads (its event loop and the worker it hands sliced work to, which run in turn) and
    #: the probe spent waiting for a core (their run-queue delays, Linux schedstats), ms. On an idle machine it is the round trip; on a busy one it
    #: still shows what the emulator did (or failed to do) before it answered: its own work,
    #: the others' work it did first, and any time it sat idle with the request unanswered.
    net_p50_ms: float = 0.0
    net_p99_ms: float = 0.0
    net_max_ms: float = 0.0
    #: The emulator's CPU time (all its threads) per round trip, ms (same condition).
    cpu_p50_ms: float = 0.0
    cpu_p99_ms: float = 0.0
    cpu_max_ms: float = 0.0


def _percentile(sorted_ms: Sequence[float], q: float) -> float:
    if not sorted_ms:
        return 0.0
    return sorted_ms[min(len(sorted_ms) - 1, int(len(sorted_ms) * q))]


def cpu_clock(pid: int) -> int:
    """The clock id of process ``pid``'s CPU time, all threads, for :func:`time.clock_gettime`
    (Linux: the id ``clock_getcpuclockid(3)`` returns, a per-process ``CPUCLOCK_SCHED`` clock
    with nanosecond resolution; readable for any process of the same user)."""
    return (~pid << 3) | 2


class _RunQueueWait:
    """Nanoseconds a thread has waited for a core so far: the second field of its Linux
    ``schedstat`` (``/proc/<pid>/schedstat`` is the process's main thread)."""

    def __init__(self, path: str) -> None:
        self.fd = os.open(path, os.O_RDONLY)

    def __call__(self) -> int:
        return int(os.pread(self.fd, 128, 0).split()[1])

    def close(self) -> None:
        os.close(self.fd)


class _OtherThreadsWait:
    """Nanoseconds the process's other threads have waited for a core so far. The event loop
    hands sliced work (slices.py) to a worker thread and waits for it, so the worker's wait for
    a core is the loop's too. A thread that ended counts with the last figure read of it (never
    more than it waited: a round trip may look longer, never shorter)."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.seen: dict[str, int] = {}

    def __call__(self) -> int:
        for tid in os.listdir(f"/proc/{self.pid}/task"):
            if tid == str(self.pid):
                continue  # the main thread: its own _RunQueueWait
            try:
                with open(f"/proc/{self.pid}/task/{tid}/schedstat", "rb") as f:
                    self.seen[tid] = int(f.read().split()[1])
            except (FileNotFoundError, ProcessLookupError, IndexError):
                pass  # ended meanwhile
        return sum(self.seen.values())

    def close(self) -> None:
        pass


def run_probe(
    host: str,
    port: int,
    seconds: float,
    var: str,
    *,
    period: float = 0.005,
    ready: Callable[[], None] | None = None,
    emulator_pid: int | None = None,
    stop: Callable[[], bool] | None = None,
    min_requests: int = 0,
) -> ProbeResult:
    """Be the bystander for ``seconds`` (with ``stop``: until ``stop()`` is true, ``seconds``
    being then only a cap), and in any case until ``min_requests`` round trips are timed: every
    ``period`` write ``var`` = n, read it back, read ``$OV_PRO`` (expects 100), each request
    alone and timed. Blocking sockets; ``ready`` is called once connected. With
    ``emulator_pid`` (Linux) the net round trips and the emulator's CPU time are measured too
    (``net_*``, ``cpu_*`` of the result)."""
    result = ProbeResult()
    samples: list[float] = []
    net_samples: list[float] = []
    cpu_samples: list[float] = []
    clock = cpu_clock(emulator_pid) if emulator_pid is not None else None
    waits: list[_RunQueueWait | _OtherThreadsWait] = []
    if emulator_pid is not None:  # the emulator's event loop runs in its main thread
        waits = [_RunQueueWait(f"/proc/{emulator_pid}/schedstat"),
                 _OtherThreadsWait(emulator_pid),
                 _RunQueueWait("/proc/thread-self/schedstat")]  # fmt: skip
    sock = socket.create_connection((host, port), timeout=2.0)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    if ready is not None:
        ready()
    decoder = ReplyDecoder()
    pending: list[Reply] = []

    def request(frame: bytes) -> Reply:
        if clock is not None:
            waited = sum(wait() for wait in waits)
            cpu = time.clock_gettime(clock)
        start = time.perf_counter()
        sock.sendall(frame)
        while not pending:
            data = sock.recv(65536)
            if not data:
                raise ConnectionError("closed by the emulator")
            pending.extend(decoder.feed_replies(data))
        wall = (time.perf_counter() - start) * 1e3
        samples.append(wall)
        if clock is not None:
            cpu_samples.append((time.clock_gettime(clock) - cpu) * 1e3)
            net_samples.append(wall - (sum(wait() for wait in waits) - waited) / 1e6)
        return pending.pop(0)

    def check(reply: Reply, msg_id: int, expect: str, what: str) -> None:
        if reply.msg_id != msg_id or not reply.ok or reply.text != expect:
            result.wrong += 1
            if len(result.notes) < 10:
                result.notes.append(f"{what}: id {reply.msg_id} {reply.text[:40]!r}")

    end = time.monotonic() + seconds

    def more() -> bool:
        if len(samples) < min_requests:
            return True  # a busy machine slows the probe down: it still gets its sample
        return time.monotonic() < end and (stop is None or not stop())

    n = 0
    try:
        while more():
            tick = time.monotonic()
            n += 1
            msg_id = (3 * n) & 0xFFFF
            check(request(encode_write(msg_id, var, str(n))), msg_id, str(n), "write")
            check(request(encode_read(msg_id + 1 & 0xFFFF, var)), msg_id + 1 & 0xFFFF, str(n), var)
            check(request(encode_read(msg_id + 2 & 0xFFFF, "$OV_PRO")), msg_id + 2 & 0xFFFF, "100",
                  "$OV_PRO")  # fmt: skip
            rest = period - (time.monotonic() - tick)
            if rest > 0:
                time.sleep(rest)
    except (OSError, ConnectionError) as exc:
        result.errors += 1
        result.notes.append(f"error: {exc}")
    finally:
        sock.close()
        for wait in waits:
            wait.close()
    samples.sort()
    result.requests = len(samples)
    result.p50_ms = _percentile(samples, 0.50)
    result.p99_ms = _percentile(samples, 0.99)
    result.max_ms = samples[-1] if samples else 0.0
    net_samples.sort()
    result.net_p50_ms = _percentile(net_samples, 0.50)
    result.net_p99_ms = _percentile(net_samples, 0.99)
    result.net_max_ms = net_samples[-1] if net_samples else 0.0
    cpu_samples.sort()
    result.cpu_p50_ms = _percentile(cpu_samples, 0.50)
    result.cpu_p99_ms = _percentile(cpu_samples, 0.99)
    result.cpu_max_ms = cpu_samples[-1] if cpu_samples else 0.0
    return result


class Probe:
    """A bystander running in its own process (see :func:`start_probe`)."""

    def __init__(self, proc: subprocess.Popen[str]) -> None:
        self.proc = proc

    def result(self, timeout: float = 120.0) -> ProbeResult:
        """Wait for the probe to end (a probe started ``until_stopped`` is stopped first)."""
        out, _ = self.proc.communicate(timeout=timeout)  # closes its stdin: stop
        lines = [line for line in out.splitlines() if line.startswith("{")]
        if not lines:
            return ProbeResult(errors=1, notes=[f"probe failed: {out[-500:]!r}"])
        return ProbeResult(**json.loads(lines[-1]))


def start_probe(
    host: str,
    port: int,
    seconds: float,
    var: str,
    *,
    emulator_pid: int | None = None,
    until_stopped: bool = False,
    min_requests: int = 0,
) -> Probe:
    """Start the bystander process; returns once it is connected and about to start. With
    ``emulator_pid`` it reports net round trips and emulator CPU time too (see
    :class:`ProbeResult`); ``until_stopped``: it runs until :meth:`Probe.result` (``seconds``
    is then only a cap); it times at least ``min_requests`` round trips in any case."""
    extra = ["--min-requests", str(min_requests)]
    if emulator_pid is not None:
        extra += ["--emulator-pid", str(emulator_pid)]
    if until_stopped:
        extra.append("--until-eof")
    proc = subprocess.Popen(
        [sys.executable, "-m", "kukavarproxy_emu.abuse", "probe", host, str(port),
         str(seconds), var, *extra],
        stdin=subprocess.PIPE if until_stopped else subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )  # fmt: skip
    assert proc.stdout is not None
    proc.stdout.readline()  # "ready"
    return Probe(proc)


# --------------------------------------------------------------------------- abusers


@dataclass
class AbuseTally:
    """What the abusers did and saw (plain counters)."""

    connections: int = 0
    requests: int = 0
    replies: int = 0
    #: Replies with a wrong id or an impossible status/value (for abusers that read).
    wrong: int = 0
    errors: int = 0


class _Replies:
    """Replies off a stream, many per read (cheap for the abuser, so the emulator gets the CPU)."""

    def __init__(self, reader: asyncio.StreamReader) -> None:
        self.reader = reader
        self.decoder = ReplyDecoder()
        self.ready: deque[Reply] = deque()

    async def next(self, timeout: float = 10.0) -> Reply:
        async with asyncio.timeout(timeout):
            while not self.ready:
                data = await self.reader.read(262_144)
                if not data:
                    raise ConnectionError("closed by the emulator")
                self.ready.extend(self.decoder.feed_replies(data))
        return self.ready.popleft()


def _garbage_frame(rng: random.Random) -> bytes:
    kind = rng.randrange(6)
    if kind == 0:  # random bytes
        return rng.randbytes(rng.randint(1, 4096))
    if kind == 1:  # a good request, then a length field of 0 in the same segment
        return encode_read(1, "$OV_PRO") + b"\x00\x02\x00\x00"
    if kind == 2:  # a 64 KB frame that never completes
        return b"\x00\x03\xff\xff\x00" + rng.randbytes(2000)
    if kind == 3:  # blocks that do not add up to the length
        return bytes.fromhex("0004 0004 00 0009 41")
    if kind == 4:  # unknown modes and names full of control characters
        name = "".join(chr(rng.randrange(256)) for _ in range(40))
        return bytes((0, 5, 0, 3 + len(name), rng.randrange(4, 256), 0, len(name))) + name.encode(
            "latin-1"
        )
    return b"\x00\x06" + rng.randbytes(2)  # a header whose length is anything


async def garbage(host: str, port: int, tally: AbuseTally, *, seed: int = 0) -> None:
    """Connect, send garbage, wait briefly for the close, disconnect; again, until cancelled."""
    rng = random.Random(seed)
    while True:
        try:
            reader, writer = await asyncio.open_connection(host, port)
        except OSError:
            tally.errors += 1
            await asyncio.sleep(0.01)
            continue
        tally.connections += 1
        try:
            writer.write(_garbage_frame(rng))
            async with asyncio.timeout(0.2):
                while await reader.read(65536):
                    pass
        except (TimeoutError, OSError):
            pass
        finally:
            writer.close()


async def non_reader(host: str, port: int, tally: AbuseTally, *, name: str = "$IN[]") -> None:
    """Send reads of a large variable as fast as the emulator takes them, never read a reply."""
    loop = asyncio.get_running_loop()
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.setblocking(False)
    try:
        await loop.sock_connect(sock, (host, port))
        tally.connections += 1
        chunk = b"".join(encode_read(i, name) for i in range(200))
        while True:
            await loop.sock_sendall(sock, chunk)  # waits once the emulator stops reading
            tally.requests += 200
    except OSError:
        tally.errors += 1
    finally:
        sock.close()


async def long_names(
    host: str, port: int, tally: AbuseTally, *, size: int = 65_000, depth: int = 4
) -> None:
    """Read variables with distinct ``size``-character names, ``depth`` at a time."""
    reader, writer = await asyncio.open_connection(host, port)
    replies = _Replies(reader)
    tally.connections += 1
    # One frame, patched in place: id in bytes 0-1, a 9-digit counter after the "N".
    template = bytearray(encode_read(0, "N000000000" + "X" * (size - 10)))
    n = 0
    try:
        while True:
            batch = bytearray()
            for k in range(depth):
                n += 1
                template[0:2] = k.to_bytes(2, "big")
                template[8:17] = b"%09d" % n
                batch += template
            writer.write(batch)
            await writer.drain()
            tally.requests += depth
            for k in range(depth):
                reply = await replies.next()
                tally.replies += 1
                if reply.msg_id != k or reply.text != "":  # unknown: empty with success
                    tally.wrong += 1
    finally:
        writer.close()


async def costly_pipeline(host: str, port: int, tally: AbuseTally, *, pairs: int = 300) -> None:
    """Fill ``MYE6ARRAY``, then send ``pairs`` "write one element / read ``MYE6ARRAY[]``"
    pairs in one segment and read the replies, again and again."""
    reader, writer = await asyncio.open_connection(host, port)
    replies = _Replies(reader)
    tally.connections += 1
    try:
        writer.write(b"".join(encode_write(i, f"MYE6ARRAY[{i}]", _E6 % i) for i in range(1, 513)))
        for _ in range(512):
            await replies.next()
        n = 0
        while True:
            frames = []
            for i in range(pairs):
                n += 1
                frames.append(encode_write(2 * i, f"MYE6ARRAY[{n % 512 + 1}]", f"{{A1 {n}.5}}"))
                frames.append(encode_read(2 * i + 1, "MYE6ARRAY[]"))
            writer.write(b"".join(frames))
            await writer.drain()
            tally.requests += 2 * pairs
            for i in range(2 * pairs):
                reply = await replies.next()
                tally.replies += 1
                if reply.msg_id != i or (i % 2 == 0 and not reply.ok):
                    tally.wrong += 1
    finally:
        writer.close()


async def mode3_flood(host: str, port: int, tally: AbuseTally, *, name: str) -> None:
    """Write the largest mode-3 frames (32 000 words) to ``name``, one after the other."""
    reader, writer = await asyncio.open_connection(host, port)
    replies = _Replies(reader)
    tally.connections += 1
    frame = bytearray(encode_write_array(0, name, list(range(32_000))))
    try:
        n = 0
        while True:
            n = (n + 1) & 0xFFFF
            frame[0:2] = n.to_bytes(2, "big")
            writer.write(bytes(frame))
            await writer.drain()
            tally.requests += 1
            reply = await replies.next()
            tally.replies += 1
            if reply.msg_id != n:
                tally.wrong += 1
    finally:
        writer.close()


# --------------------------------------------------------------------------- command line


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m kukavarproxy_emu.abuse")
    sub = parser.add_subparsers(dest="command", required=True)
    probe = sub.add_parser("probe", help="be the bystander; print a JSON ProbeResult")
    probe.add_argument("host")
    probe.add_argument("port", type=int)
    probe.add_argument("seconds", type=float)
    probe.add_argument("var", help="an INT variable the probe may write")
    probe.add_argument(
        "--emulator-pid", type=int, help="measure this process's CPU time per round trip"
    )
    probe.add_argument(
        "--until-eof", action="store_true", help="run until stdin closes (SECONDS: a cap)"
    )
    probe.add_argument("--min-requests", type=int, default=0, help="time at least this many")
    args = parser.parse_args(argv)
    stop = threading.Event()

    def wait_for_eof() -> None:
        sys.stdin.read()
        stop.set()

    if args.until_eof:
        threading.Thread(target=wait_for_eof, daemon=True).start()
    result = run_probe(
        args.host,
        args.port,
        args.seconds,
        args.var,
        ready=lambda: print("ready", flush=True),
        emulator_pid=args.emulator_pid,
        stop=stop.is_set if args.until_eof else None,
        min_requests=args.min_requests,
    )
    print(json.dumps(asdict(result)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
