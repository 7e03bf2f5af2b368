"""The abuse suite's test bed around ``kvp gateway``: healthy robots, the gateway, a watcher.

``tests/abuse/test_abuse_gateway.py`` and ``bench/gateway_abuse.py`` build the same cell with it
(the attackers are in :mod:`.abuse`):

* :class:`CellProcess` — healthy robots: real emulators (``kukavarproxy-emu --robots N``, ideal
  plant) running :data:`SWING_KRL`, a program that never stops moving, so every poll of a
  healthy robot brings new values;
* :class:`GatewayProcess` — ``kvp gateway CELL`` in a subprocess (:func:`cell_file`): its URL,
  CPU time and peak resident memory (the high-water mark, reset when a phase starts);
* :class:`Watch` — an OPC UA client (:func:`open_client`) that subscribes to the healthy
  robots' axes and records the gaps between their updates (by SourceTimestamp, the arrival of
  the KVP reply at the gateway: a stalled event loop shows as a long gap) and the round trips
  of its reads; :func:`measure` runs one phase.

Nothing here asserts: the suite and the benchmark decide what is acceptable.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = [
    "CLIENT_URI",
    "SWING_KRL",
    "CellProcess",
    "GatewayProcess",
    "Watch",
    "cell_file",
    "client_certificate",
    "expect_line",
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


def expect_line(proc: subprocess.Popen[str], prefix: str) -> str:
    """The rest of a subprocess's first line, which must start with ``prefix`` (else it is
    killed and this raises)."""
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
        self.ports = [int(expect_line(self.proc, "listening on ").rpartition(":")[2])]
        self.ports += [
            int(expect_line(self.proc, "listening on ").rpartition(":")[2])
            for _ in range(robots - 1)
        ]

    def stop(self) -> int:
        return _stop(self.proc)


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
        self.url = expect_line(self.proc, "serving ")
        self.fingerprint = ""
        if "[security]" in cell.read_text() and "enabled = false" not in cell.read_text():
            self.fingerprint = expect_line(self.proc, "certificate SHA-256 ")

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
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

    from . import ua
    from .ua import Client

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


def client_certificate(folder: Path, uri: str, name: str = "abuser") -> tuple[Path, Path]:
    """A client application certificate and key (self-signed) in ``folder``."""
    from asyncua.crypto import cert_gen
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization
    from cryptography.x509.oid import ExtendedKeyUsageOID

    key = cert_gen.generate_private_key()
    cert = cert_gen.generate_self_signed_app_certificate(
        key, "abuse client", {}, [x509.UniformResourceIdentifier(uri)],
        extended=[ExtendedKeyUsageOID.CLIENT_AUTH],
    )  # fmt: skip
    cert_path, key_path = folder / f"{name}-cert.der", folder / f"{name}-key.pem"
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.DER))
    key_path.write_bytes(cert_gen.dump_private_key_as_pem(key))
    return cert_path, key_path


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
        from . import ua
        from .model import GATEWAY_URI

        ns = await self.client.get_namespace_index(GATEWAY_URI)
        self._node_robot: dict[Any, str] = {}
        nodes = []
        for robot in self.robots:
            for axis in range(1, 7):
                nid = ua.node_id(
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
