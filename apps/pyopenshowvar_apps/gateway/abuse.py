"""Hostile peers of ``kvp gateway`` and what measures their effect: the abuse suite's tools.

``tests/abuse/test_abuse_gateway.py`` asserts the gateway's promises under attack with them and
``bench/gateway_abuse.py`` prints the figures; both run the real ``kvp gateway`` command.

* :class:`CellProcess` — healthy robots: real emulators (``kukavarproxy-emu --robots N``, ideal
  plant) running :data:`SWING_KRL`, a program that never stops moving, so every poll of a
  healthy robot brings new values;
* ``python -m pyopenshowvar_apps.gateway.abuse hostile`` (:class:`HostileProcess`) — a fake
  robot, a TCP server that answers every KVP read with a different ~60 KB nested STRUC (the
  costliest text a KVP frame can carry) while ``on`` (a line on its stdin), and closes every
  connection while ``off`` (the gateway then sees a robot that is down);
* ``python -m pyopenshowvar_apps.gateway.abuse logins`` (:func:`login_flood`) — logins with a
  wrong password, one after the other, as fast as the gateway answers;
* :class:`GatewayProcess` — ``kvp gateway CELL`` in a subprocess: its URL, CPU time and peak
  resident memory (the high-water mark, reset when a scenario starts);
* :class:`Watch` — an OPC UA client that subscribes to the healthy robots' axes and records
  the gaps between their updates (by SourceTimestamp, the arrival of the KVP reply at the
  gateway: a stalled event loop shows as a long gap) and the round trips of its reads.

Nothing here asserts: the suite and the benchmark decide what is acceptable.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import functools
import itertools
import json
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from pyopenshowvar.protocol import Mode, Request
from pyopenshowvar.testing import FakeProxy, answer

__all__ = [
    "CLIENT_URI",
    "SWING_KRL",
    "CellProcess",
    "GatewayProcess",
    "HostileProcess",
    "LoginTally",
    "Watch",
    "cell_file",
    "client_certificate",
    "hostile_text",
    "login_flood",
    "login_once",
    "measure",
    "open_client",
    "percentile",
]

#: Moves all six axes between two poses for ever, approximated (C_PTP) so it never stands.
SWING_KRL = """\
DEF SWING()
  PTP $AXIS_ACT
  $APO.CPTP = 50
  LOOP
    PTP {A1 40, A2 -80, A3 100, A4 20, A5 30, A6 40} C_PTP
    PTP {A1 -40, A2 -100, A3 80, A4 -20, A5 -30, A6 -40} C_PTP
  ENDLOOP
END
"""

PYTHON = sys.executable
CLIENT_URI = "urn:pyopenshowvar:abuse-client"


def percentile(sorted_values: Sequence[float], q: float) -> float:
    """Nearest-rank percentile of sorted values (q in 0..100); NaN when there are none."""
    if not sorted_values:
        return float("nan")
    return float(sorted_values[min(len(sorted_values) - 1, int(len(sorted_values) * q / 100))])


def _status(pid: int, key: str) -> float:
    """A ``/proc/PID/status`` size in MB (VmRSS, VmHWM)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1]) * 1024 / 1e6
    raise RuntimeError(f"no {key} for {pid}")


def _read_line(proc: subprocess.Popen[str], prefix: str) -> str:
    assert proc.stdout is not None
    line = proc.stdout.readline().strip()
    if not line.startswith(prefix):
        proc.kill()
        raise RuntimeError(f"{proc.args!r} did not start: {line!r}")
    return line.removeprefix(prefix)


def _stop(proc: subprocess.Popen[str], timeout: float = 20.0) -> int:
    if proc.poll() is None:
        proc.terminate()
    try:
        return proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait(timeout)


# --------------------------------------------------------------------------- the robots


class CellProcess:
    """``robots`` emulated KRCs in one subprocess, all running :data:`SWING_KRL`."""

    def __init__(self, robots: int, folder: Path) -> None:
        program = folder / "swing.src"
        program.write_text(SWING_KRL)
        self.proc = subprocess.Popen(
            [PYTHON, "-m", "kukavarproxy_emu", "--port", "0", "--robots", str(robots),
             "--plant", "ideal", "--program", str(program), "--no-discovery",
             "--idle-timeout", "0", "--max-clients", "0"],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
        )  # fmt: skip
        self.ports = [int(_read_line(self.proc, "listening on ").rpartition(":")[2])]
        self.ports += [
            int(_read_line(self.proc, "listening on ").rpartition(":")[2])
            for _ in range(robots - 1)
        ]

    def stop(self) -> int:
        return _stop(self.proc)


def hostile_text(counter: int, size: int = 60_000) -> str:
    """A nested STRUC of about ``size`` characters, different for every ``counter``."""
    return f"{{HOSTILE_T: N {counter}{_hostile_body(size)}"


@functools.cache
def _hostile_body(size: int) -> str:
    # built once: the fake robot must send faster than the gateway can parse
    member = ", M{0} {{A {0}, B {{C 1.5, D TRUE, E #ON}}, F {0}.25}}"
    parts: list[str] = []
    length, i = 0, 0
    while length < size - 80:
        part = member.format(i)
        parts.append(part)
        length += len(part)
        i += 1
    return "".join(parts) + "}"


@dataclass
class HostileTally:
    replies: int = 0
    big_replies: int = 0
    bytes_sent: int = 0


async def serve_hostile(size: int) -> None:
    """The fake robot: ``listening on HOST:PORT``, then ``on``/``off`` lines on stdin switch
    it between 60 KB replies and closed connections; at the end of stdin it prints its tally
    (JSON) and stops. (A reply's kind never changes on one connection: our client drops a
    connection whose replies change kind, as from a confused proxy.)"""
    tally = HostileTally()
    big = asyncio.Event()

    async def handler(req: Request, writer: asyncio.StreamWriter, n: int) -> None:
        if not big.is_set():
            writer.transport.abort()
            return
        if req.mode == Mode.READ:
            frame = answer(req, hostile_text(n, size).encode())
            tally.big_replies += 1
        else:
            frame = answer(req)
        tally.replies += 1
        tally.bytes_sent += len(frame)
        writer.write(frame)
        await writer.drain()

    loop = asyncio.get_running_loop()
    async with FakeProxy(handler) as port:
        print(f"listening on 127.0.0.1:{port}", flush=True)
        while line := await loop.run_in_executor(None, sys.stdin.readline):
            if line.strip() == "on":
                big.set()
            elif line.strip() == "off":
                big.clear()
    print(json.dumps(asdict(tally)), flush=True)


class HostileProcess:
    """The fake robot of :func:`serve_hostile` in its own process (its CPU is not ours)."""

    def __init__(self, size: int = 60_000) -> None:
        self.proc = subprocess.Popen(
            [PYTHON, "-m", __name__, "hostile", "--size", str(size)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        )  # fmt: skip
        self.port = int(_read_line(self.proc, "listening on ").rpartition(":")[2])

    def big(self, on: bool) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write("on\n" if on else "off\n")
        self.proc.stdin.flush()

    def stop(self) -> dict[str, Any]:
        """Its tally (replies, big_replies, bytes_sent)."""
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.close()
        out = self.proc.stdout.read()
        self.proc.wait(20)
        return dict(json.loads(out.strip().splitlines()[-1]))


# --------------------------------------------------------------------------- the gateway


class GatewayProcess:
    """``kvp gateway CELL`` in a subprocess; stderr (the log) goes to ``log``."""

    def __init__(self, cell: Path, log: Path) -> None:
        self.log = log
        with log.open("w") as err:
            self.proc = subprocess.Popen(
                [PYTHON, "-c", "from pyopenshowvar_apps.cli import main; main()", "gateway",
                 str(cell), "--log-level", os.environ.get("GW_LOG", "warning")],
                stdout=subprocess.PIPE, stderr=err, text=True,
            )  # fmt: skip
        self.url = _read_line(self.proc, "serving ")
        self.fingerprint = ""
        if "[security]" in cell.read_text() and "enabled = false" not in cell.read_text():
            self.fingerprint = _read_line(self.proc, "certificate SHA-256 ")

    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def cpu_seconds(self) -> float:
        fields = Path(f"/proc/{self.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def reset_peak(self) -> None:
        """Start a new high-water mark of the resident memory (Linux ``clear_refs`` 5)."""
        Path(f"/proc/{self.pid}/clear_refs").write_text("5")

    def rss_mb(self) -> float:
        return _status(self.pid, "VmRSS")

    def peak_rss_mb(self) -> float:
        """The highest resident memory since :meth:`reset_peak` (or the start)."""
        return _status(self.pid, "VmHWM")

    def stop(self) -> int:
        return _stop(self.proc)


def cell_file(
    folder: Path,
    healthy: Sequence[int],
    hostile: Sequence[int] = (),
    *,
    security: str = "",
) -> Path:
    """A cell file ``abuse``: healthy robots r1.. at 10 Hz, hostile ones h1.. at 50 Hz, and
    ``security`` (the text of a ``[security]`` table, or nothing: loopback, anonymous)."""
    text = f'[cell]\nname = "abuse"\nendpoint = "opc.tcp://127.0.0.1:0"\n{security}'
    for i, port in enumerate(healthy, 1):
        text += f'[[robot]]\nname = "r{i}"\nhost = "127.0.0.1"\nport = {port}\n'
    for i, port in enumerate(hostile, 1):
        text += f'[[robot]]\nname = "h{i}"\nhost = "127.0.0.1"\nport = {port}\npoll_hz = 50\n'
    path = folder / "cell.toml"
    path.write_text(text)
    return path


async def open_client(gw: GatewayProcess, folder: Path, user: str = "", password: str = "") -> Any:
    """A connected asyncua client: anonymous, or (security on) Basic256Sha256 Sign&Encrypt
    with a certificate of its own and ``user``/``password``."""
    from asyncua import Client, ua
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

    client = Client(gw.url, timeout=30)
    if gw.fingerprint:
        cert, key = client_certificate(folder, CLIENT_URI, "watcher")
        client.application_uri = CLIENT_URI
        await client.set_security(
            SecurityPolicyBasic256Sha256, str(cert), str(key),
            mode=ua.MessageSecurityMode.SignAndEncrypt,
        )  # fmt: skip
        client.set_user(user)
        client.set_password(password)
    await client.connect()
    return client


# --------------------------------------------------------------------------- logins


@dataclass
class LoginTally:
    """What the login abuser saw: every attempt ends in exactly one of the counters."""

    attempts: int = 0
    #: the gateway answered BadUserAccessDenied (checked and refused)
    denied: int = 0
    #: refused at once, before a session (BadSecurityChecksFailed: the address is locked out)
    locked: int = 0
    #: logged in: must stay 0 with a wrong password
    accepted: int = 0
    #: anything else (a timeout, an unexpected status): the abuser's own errors
    errors: int = 0
    notes: list[str] = field(default_factory=list)
    #: seconds each attempt took, by kind ("denied", "locked", ...)
    times: dict[str, list[float]] = field(default_factory=dict)


def client_certificate(folder: Path, uri: str, name: str = "abuser") -> tuple[Path, Path]:
    """A client application certificate and key (self-signed) in ``folder``."""
    from asyncua.crypto import cert_gen
    from cryptography.hazmat.primitives import serialization
    from cryptography.x509.oid import ExtendedKeyUsageOID

    key = cert_gen.generate_private_key()
    cert = cert_gen.generate_self_signed_app_certificate(
        key, "abuse client", {}, [cert_gen.x509.UniformResourceIdentifier(uri)],
        extended=[ExtendedKeyUsageOID.CLIENT_AUTH],
    )  # fmt: skip
    cert_path, key_path = folder / f"{name}-cert.der", folder / f"{name}-key.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.DER))
    key_path.write_bytes(cert_gen.dump_private_key_as_pem(key))
    return cert_path, key_path


async def login_once(
    url: str, cert: Path, key: Path, user: str, password: str, tally: LoginTally
) -> None:
    """One login attempt with Basic256Sha256 Sign&Encrypt; counted in ``tally``."""
    from asyncua import Client, ua
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

    client = Client(url, timeout=10)
    client.application_uri = CLIENT_URI
    client.set_user(user)
    client.set_password(password)
    tally.attempts += 1
    started = time.perf_counter()
    kind = "errors"
    try:
        # set_security asks the server for its endpoints: a locked-out client fails here
        await client.set_security(
            SecurityPolicyBasic256Sha256, str(cert), str(key),
            mode=ua.MessageSecurityMode.SignAndEncrypt,
        )  # fmt: skip
        await client.connect()
        kind = "accepted"
        await client.disconnect()
    except ua.UaStatusCodeError as exc:
        kinds = {
            ua.StatusCodes.BadUserAccessDenied: "denied",
            ua.StatusCodes.BadSecurityChecksFailed: "locked",
        }
        kind = kinds.get(exc.code, "errors")
        if kind == "errors":
            tally.notes.append(f"{type(exc).__name__}: {exc}")
    except (TimeoutError, OSError, ua.UaError) as exc:
        tally.notes.append(f"{type(exc).__name__}: {exc}")
    finally:
        with contextlib.suppress(Exception):
            await client.close_secure_channel()
        with contextlib.suppress(Exception):
            client.disconnect_socket()
    setattr(tally, kind, getattr(tally, kind) + 1)
    tally.times.setdefault(kind, []).append(time.perf_counter() - started)


async def login_flood(
    url: str, users: Sequence[str], seconds: float, folder: Path, *, max_attempts: int = 10_000
) -> LoginTally:
    """Wrong-password logins for ``seconds``, cycling through ``users``, one at a time."""
    cert, key = client_certificate(folder, CLIENT_URI)
    tally = LoginTally()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and tally.attempts < max_attempts:
        user = users[tally.attempts % len(users)]
        await login_once(url, cert, key, user, "not the password", tally)
    return tally


# --------------------------------------------------------------------------- the watcher


class Watch:
    """Subscribes to the healthy robots' axis positions and reads one node in a loop.

    ``gaps_ms()``: the gaps between consecutive distinct SourceTimestamps of each robot (a
    robot's update is any of its six axes changing). ``reads_ms()``: the round trips of the
    reads. :meth:`mark` starts a new measuring window.
    """

    def __init__(self, client: Any, cell: str, robots: Sequence[str], read_period: float = 0.02):
        self.client, self.cell, self.robots = client, cell, list(robots)
        self.read_period = read_period
        self._stamps: dict[str, set[Any]] = {r: set() for r in self.robots}
        self._reads: list[float] = []
        self._task: asyncio.Task[None] | None = None
        self._sub: Any = None
        self.bad = 0
        self.read_errors = 0

    async def start(self) -> None:
        from asyncua import ua

        from .model import GATEWAY_URI

        ns = await self.client.get_namespace_index(GATEWAY_URI)
        self._node_robot: dict[Any, str] = {}
        nodes = []
        for robot in self.robots:
            for axis in range(1, 7):
                nid = ua.NodeId(
                    f"{self.cell}.MotionDevices.{robot}.Axes.A{axis}.ParameterSet.ActualPosition",
                    ns,
                )
                node = self.client.get_node(nid)
                nodes.append(node)
                self._node_robot[nid] = robot
        self._sub = await self.client.create_subscription(50, self)
        await self._sub.subscribe_data_change(nodes, queuesize=20, sampling_interval=0)
        self._read_node = nodes[0]
        self._task = asyncio.create_task(self._read_loop())

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        dv = data.monitored_item.Value
        if dv.StatusCode is not None and not dv.StatusCode.is_good():
            self.bad += 1
            return
        robot = self._node_robot.get(node.nodeid)
        if robot is not None and dv.SourceTimestamp is not None:
            self._stamps[robot].add(dv.SourceTimestamp)

    async def _read_loop(self) -> None:
        while True:
            started = time.perf_counter()
            try:
                await self._read_node.read_data_value(raise_on_bad_status=False)
                self._reads.append((time.perf_counter() - started) * 1e3)
            except Exception:  # a read that fails is counted, not raised: the figures tell
                self.read_errors += 1
            await asyncio.sleep(self.read_period)

    def mark(self) -> None:
        for stamps in self._stamps.values():
            stamps.clear()
        self._reads.clear()
        self.bad = 0
        self.read_errors = 0

    def gaps_ms(self) -> list[float]:
        gaps: list[float] = []
        for stamps in self._stamps.values():
            ordered = sorted(stamps)
            gaps += [(b - a).total_seconds() * 1e3 for a, b in itertools.pairwise(ordered)]
        return sorted(gaps)

    def updates(self) -> dict[str, int]:
        return {r: len(s) for r, s in self._stamps.items()}

    def reads_ms(self) -> list[float]:
        return sorted(self._reads)

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        if self._sub is not None:
            with contextlib.suppress(Exception):
                await self._sub.delete()

    def summary(self) -> dict[str, float]:
        gaps, reads = self.gaps_ms(), self.reads_ms()
        return {
            "gap_p50": percentile(gaps, 50),
            "gap_p99": percentile(gaps, 99),
            "gap_max": gaps[-1] if gaps else float("nan"),
            "gaps": len(gaps),
            "read_p50": percentile(reads, 50),
            "read_p99": percentile(reads, 99),
            "read_max": reads[-1] if reads else float("nan"),
            "reads": len(reads),
            "read_errors": self.read_errors,
            "bad": self.bad,
        }


async def measure(gw: GatewayProcess, watch: Watch, seconds: float) -> dict[str, Any]:
    """One phase: the :meth:`Watch.summary` of ``seconds``, the gateway's CPU (% of one core),
    its peak resident memory and how far that peak rose above the memory at the start."""
    gw.reset_peak()
    before = gw.rss_mb()
    watch.mark()
    c0, t0 = gw.cpu_seconds(), time.monotonic()
    await asyncio.sleep(seconds)
    result: dict[str, Any] = watch.summary()
    result["cpu_pct"] = 100 * (gw.cpu_seconds() - c0) / (time.monotonic() - t0)
    result["peak_rss_mb"] = gw.peak_rss_mb()
    result["growth_mb"] = result["peak_rss_mb"] - before
    return result


# --------------------------------------------------------------------------- command line


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pyopenshowvar_apps.gateway.abuse")
    sub = ap.add_subparsers(dest="what", required=True)
    hostile = sub.add_parser("hostile", help="a fake robot with ~60 KB replies (stdin: on/off)")
    hostile.add_argument("--size", type=int, default=60_000)
    logins = sub.add_parser("logins", help="wrong-password logins; prints the tally (JSON)")
    logins.add_argument("url")
    logins.add_argument("--user", action="append", required=True)
    logins.add_argument("--seconds", type=float, default=5.0)
    logins.add_argument("--folder", type=Path, required=True)
    args = ap.parse_args(argv)
    if args.what == "hostile":
        asyncio.run(serve_hostile(args.size))
        return 0
    tally = asyncio.run(login_flood(args.url, args.user, args.seconds, args.folder))
    print(json.dumps(asdict(tally)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
