"""The bystander: a well-behaved client in its own process, timing every round trip.

:func:`run_probe` writes a counter, reads it back and reads ``$OV_PRO``, one request at a
time, and reports every round trip's latency and every wrong value (:class:`ProbeResult`);
given the emulator's process id (Linux) it also reports each round trip less the time the
emulator and the probe waited for a core, which a busy machine does not inflate, and the
emulator's CPU time per round trip. :func:`start_probe` runs it in a process of its own
(``python -m kukavarproxy_emu.abuse probe``), so it shares no GIL with the abusers.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from pyopenshowvar.protocol import Reply, ReplyDecoder, encode_read, encode_write

__all__ = ["Probe", "ProbeResult", "cpu_clock", "run_probe", "start_probe"]


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


class _TimedLink:
    """The probe's blocking connection: sends one request, waits for its reply and records the
    round trip (ms); with the emulator's process id also the round trip less the time spent
    waiting for a core (``net``) and the emulator's CPU time (``cpu``)."""

    def __init__(self, sock: socket.socket, emulator_pid: int | None) -> None:
        self.sock = sock
        self.samples: list[float] = []
        self.net: list[float] = []
        self.cpu: list[float] = []
        self.clock = cpu_clock(emulator_pid) if emulator_pid is not None else None
        self.waits: list[_RunQueueWait | _OtherThreadsWait] = []
        if emulator_pid is not None:  # the emulator's event loop runs in its main thread
            self.waits = [_RunQueueWait(f"/proc/{emulator_pid}/schedstat"),
                          _OtherThreadsWait(emulator_pid),
                          _RunQueueWait("/proc/thread-self/schedstat")]  # fmt: skip
        self.decoder = ReplyDecoder()
        self.pending: list[Reply] = []

    def request(self, frame: bytes) -> Reply:
        clock, waits, pending = self.clock, self.waits, self.pending
        if clock is not None:
            waited = sum(wait() for wait in waits)
            cpu = time.clock_gettime(clock)
        start = time.perf_counter()
        self.sock.sendall(frame)
        while not pending:
            data = self.sock.recv(65536)
            if not data:
                raise ConnectionError("closed by the emulator")
            pending.extend(self.decoder.feed_replies(data))
        wall = (time.perf_counter() - start) * 1e3
        self.samples.append(wall)
        if clock is not None:
            self.cpu.append((time.clock_gettime(clock) - cpu) * 1e3)
            self.net.append(wall - (sum(wait() for wait in waits) - waited) / 1e6)
        return pending.pop(0)

    def close(self) -> None:
        self.sock.close()
        for wait in self.waits:
            wait.close()

    def summarise(self, result: ProbeResult) -> ProbeResult:
        """``result`` with the percentiles of what was recorded."""
        result.requests = len(self.samples)
        result.p50_ms, result.p99_ms, result.max_ms = _spread(self.samples)
        result.net_p50_ms, result.net_p99_ms, result.net_max_ms = _spread(self.net)
        result.cpu_p50_ms, result.cpu_p99_ms, result.cpu_max_ms = _spread(self.cpu)
        return result


def _spread(samples: list[float]) -> tuple[float, float, float]:
    """p50, p99 and maximum of ``samples`` (sorted in place), 0 for none."""
    samples.sort()
    top = samples[-1] if samples else 0.0
    return _percentile(samples, 0.50), _percentile(samples, 0.99), top


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
    sock = socket.create_connection((host, port), timeout=2.0)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    link = _TimedLink(sock, emulator_pid)
    if ready is not None:
        ready()
    request = link.request

    def check(reply: Reply, msg_id: int, expect: str, what: str) -> None:
        if reply.msg_id != msg_id or not reply.ok or reply.text != expect:
            result.wrong += 1
            if len(result.notes) < 10:
                result.notes.append(f"{what}: id {reply.msg_id} {reply.text[:40]!r}")

    end = time.monotonic() + seconds

    def more() -> bool:
        if len(link.samples) < min_requests:
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
        link.close()
    return link.summarise(result)


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
