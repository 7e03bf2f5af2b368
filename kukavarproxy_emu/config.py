"""Configuration of one emulator instance: every command-line option as a dataclass field.

:class:`EmulatorConfig` is what both the CLI (``kukavarproxy_emu.__main__``) and the
in-process API (:class:`~kukavarproxy_emu.server.Emulator`) consume; the defaults are the
behaviour of a KUKAVARPROXY 9.0 on TCP 7000, except that it listens on 127.0.0.1 only.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pyopenshowvar.protocol import MAX_FRAME

from .faults import Fault
from .latency import LatencyProfile, resolve_profile
from .plant import PLANTS, Obstacle

__all__ = [
    "DEFAULT_PORT",
    "KNOWN_QUIRKS",
    "PROXIES",
    "PROXY_LIMITS",
    "ROBOT_PROGRAMS",
    "WIRES",
    "EmulatorConfig",
]

DEFAULT_PORT = 7000
DEFAULT_UDP_PORT = 6999
#: ``legacy-ids``: pre-9.0 bug, every reply to one TCP read carries the first request's id.
#: ``no-ping``: pre-9.0 proxies pass ``PING`` to CrossComm, so it reads as an unknown variable.
KNOWN_QUIRKS = frozenset({"legacy-ids", "no-ping"})
#: ``robust``: requests are reassembled across TCP reads and garbage closes the connection.
#: ``kvp9``: every read of at most 2048 bytes is parsed on its own, exactly as KUKAVARPROXY 9.0's
#: source does, malformed input included (docs/emulator.md, "Wire-faithful mode").
WIRES = ("robust", "kvp9")
#: ``kvp``: KUKAVARPROXY 9.0. ``c3bridge``: the C3 Bridge Interface server 1.4 (KVP's modes 0/1
#: with C3's failure tail, plus the extended messages: docs/c3bridge.md).
PROXIES = ("kvp", "c3bridge")
#: (max_clients, idle_timeout) when not given: KVP's 10 clients and 30 s; C3 Bridge has no
#: limits, the emulator keeps 64 clients to bound its memory and drops no idle client.
PROXY_LIMITS = {"kvp": (10, 30.0), "c3bridge": (64, 0.0)}
#: ``--program`` names of the shipped KRL programs (kept here so the config does not import
#: numpy-heavy motion code; ``kukavarproxy_emu.program_factory.PROGRAMS`` has the same keys, a test
#: checks it). Any other ``--program`` is the path of a ``.src`` file.
ROBOT_PROGRAMS = ("follow", "actuator", "ext_move_axis", "joint_path", "cart_path", "none")
_KRL_SUFFIXES = (".src", ".sub")
#: ``idle_reset`` values: any received bytes (KVP) or whole requests only.
IDLE_RESETS = ("bytes", "requests")


def _is_program(value: str) -> bool:
    return value in ROBOT_PROGRAMS or value.lower().endswith(_KRL_SUFFIXES)


@dataclass(frozen=True)
class EmulatorConfig:
    """All options of one emulator; see docs/emulator.md for the behaviour behind each."""

    host: str = "127.0.0.1"
    #: TCP port; 0 picks a free ephemeral port (read it back from ``Emulator.port``).
    port: int = DEFAULT_PORT
    #: $CONFIG.DAT-style files whose globals are added to the default ones.
    config_files: tuple[Path, ...] = ()
    #: The same, as text (for tests).
    dat_text: str | None = None
    #: "none", "kvp", "thesis", "fixed:SECONDS" or a LatencyProfile.
    latency: str | LatencyProfile = "none"
    #: Clients beyond this are accepted and closed at once (KVP: 10); 0 = unlimited;
    #: -1 = the proxy's default (PROXY_LIMITS).
    max_clients: int = -1
    #: Seconds without received data before a client is dropped (KVP 9.0: 30); 0 = never;
    #: -1 = the proxy's default.
    idle_timeout: float = -1.0
    #: What resets the idle timer: ``"bytes"`` (any received data, as KVP's read event does)
    #: or ``"requests"`` (only a whole request, so a client trickling bytes is dropped).
    idle_reset: str = "bytes"
    #: Seed of the latency sampler (None: a fresh seed each run).
    seed: int | None = None
    #: C3 Bridge style failures (tail 00 00 00, empty value) for unknown reads and refused writes.
    strict: bool = False
    quirks: frozenset[str] = frozenset()
    #: How the byte stream is framed and parsed: "robust" or "kvp9" (see WIRES).
    wire: str = "robust"
    #: Which server to be: "kvp" or "c3bridge" (see PROXIES).
    proxy: str = "kvp"
    #: UDP discovery: listen port, the port answers go to (0: the sender's port) and the switch
    #: (None: on unless the TCP port is ephemeral).
    udp_port: int = DEFAULT_UDP_PORT
    udp_reply_port: int = DEFAULT_PORT
    discovery: bool | None = None
    faults: tuple[Fault, ...] = ()
    #: Largest request frame accepted; a longer length field closes the connection.
    max_frame: int = MAX_FRAME
    #: Requests queued but not yet answered per connection before the socket stops being read.
    max_pending: int = 128
    #: Simulate the robot (motion kernel + program + SPS); False = static variables only.
    robot: bool = True
    #: Which KUKA arm (``--robot``): a catalogue name or an arm file; "" = the KR 6 R900
    #: sixx. Its identity, limits and start-up pose are in the variables even without
    #: ``robot`` (see kukavarproxy_emu.robots).
    arm: str = ""
    #: Robot program: a shipped name (see docs/emulator-robot.md) or a ``.src`` path (docs/krl.md);
    #: "" = the proxy's default: ``follow`` for KVP, ``none`` for C3 Bridge (whose clients
    #: select and start their own programs).
    program: str = ""
    #: Submit (SPS) program: ``"sps"`` (the shipped Algorithm 4.11), a ``.sub``/``.src`` path,
    #: or ``"none"``.
    sps: str = "sps"
    #: Simulated time runs this many times faster than wall time.
    speed: float = 1.0
    #: Interpolation cycle, simulated seconds (KRC4: 12 ms).
    ipo: float = 0.012
    #: Wall seconds the robot's IPO deadlines are shifted by: the robots of a cell
    #: (:mod:`kukavarproxy_emu.cell`) spread their ticks over the period instead of all at once.
    ipo_phase: float = 0.0
    #: The physical robot: "dynamic" (MuJoCo rigid bodies, servos, friction, sensor noise) or
    #: "ideal" (measured = set-point, statics torques: exact values); see kukavarproxy_emu.plant.
    plant: str = "dynamic"
    #: Encoder noise (deg, standard deviation) on the measured axes; None = the plant's default
    #: (ideal 0; dynamic 2e-5, the model file's). Seeded by ``seed``.
    noise: float | None = None
    #: Noise on $TORQUE_AXIS_ACT (Nm, standard deviation, every axis); None = the dynamic
    #: plant's default (0.1 % of each axis' max torque). Dynamic plant only.
    torque_noise: float | None = None
    #: Seed of a random calibration error (the physical robot's geometry and masses differ
    #: from the nominal model); None = none. Dynamic plant only.
    calibration_error: int | None = None
    #: Objects in the cell the TCP can push against (dynamic plant only).
    obstacles: tuple[Obstacle, ...] = ()

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 0xFFFF or not 0 <= self.udp_port <= 0xFFFF:
            raise ValueError("ports must be in 0..65535")
        if not 0 <= self.udp_reply_port <= 0xFFFF:
            raise ValueError("udp_reply_port must be in 0..65535")
        if self.proxy not in PROXIES:
            raise ValueError(f"unknown proxy {self.proxy!r} (choose from {', '.join(PROXIES)})")
        if self.client_limit < 0 or self.idle_limit < 0:
            raise ValueError("max_clients and idle_timeout must be >= 0")
        if self.idle_reset not in IDLE_RESETS:
            raise ValueError(f"idle_reset must be one of {', '.join(IDLE_RESETS)}")
        if self.max_pending < 1 or self.max_frame < 8:
            raise ValueError("max_pending must be >= 1 and max_frame >= 8")
        object.__setattr__(self, "program", str(self.program))
        object.__setattr__(self, "sps", str(self.sps))
        if not _is_program(self.robot_program):
            raise ValueError(
                f"unknown program {self.program!r} (known: {', '.join(ROBOT_PROGRAMS)},"
                " or a .src file)"
            )
        if self.sps not in ("sps", "none") and not self.sps.lower().endswith(_KRL_SUFFIXES):
            raise ValueError(f"--sps needs 'sps', 'none' or a .sub/.src file, not {self.sps!r}")
        if not (self.speed > 0 and self.ipo > 0):
            raise ValueError("speed and ipo must be > 0")
        if not 0 <= self.ipo_phase < self.ipo / self.speed:
            raise ValueError("ipo_phase must be in [0, ipo / speed)")
        if any(n is not None and not n >= 0 for n in (self.noise, self.torque_noise)):
            raise ValueError("noise levels must be >= 0")
        if self.plant not in PLANTS:
            raise ValueError(f"unknown plant {self.plant!r} (known: {', '.join(PLANTS)})")
        object.__setattr__(self, "obstacles", tuple(self.obstacles))
        if self.plant == "ideal" and (
            self.calibration_error is not None or self.obstacles or self.torque_noise
        ):
            raise ValueError("calibration error, obstacles and torque noise need plant 'dynamic'")
        unknown = set(self.quirks) - KNOWN_QUIRKS
        if unknown:
            raise ValueError(f"unknown quirks {sorted(unknown)} (known: {sorted(KNOWN_QUIRKS)})")
        object.__setattr__(self, "quirks", frozenset(self.quirks))
        if self.wire not in WIRES:
            raise ValueError(f"unknown wire {self.wire!r} (choose from {', '.join(WIRES)})")
        if self.wire == "kvp9" and (self.strict or self.proxy == "c3bridge"):
            # strict is C3 Bridge's failure tail; C3 Bridge frames like the robust mode
            raise ValueError(
                "--strict / --proxy c3bridge cannot be combined with --wire kvp9 (C3 Bridge"
                " collects whole messages, like the robust wire)"
            )
        if self.proxy == "c3bridge":
            if self.quirks:
                raise ValueError("--quirks reproduce KUKAVARPROXY bugs; C3 Bridge has none")
            object.__setattr__(self, "strict", True)  # C3's failure tail on types 0/1
        object.__setattr__(self, "config_files", tuple(Path(p) for p in self.config_files))
        object.__setattr__(self, "arm", str(self.arm).strip())
        if self.arm:
            from .robots import resolve_robot  # numpy: only for another arm than the KR 6

            resolve_robot(self.arm)  # fail early, with one line, on an arm it cannot be
        resolve_profile(self.latency)  # fail early on a bad profile name

    # The proxy-dependent defaults are resolved on use, not stored, so that
    # ``dataclasses.replace(config, proxy="c3bridge")`` gets C3 Bridge's defaults.
    @property
    def client_limit(self) -> int:
        """``max_clients`` with -1 resolved to the proxy's default."""
        return PROXY_LIMITS[self.proxy][0] if self.max_clients == -1 else self.max_clients

    @property
    def idle_limit(self) -> float:
        """``idle_timeout`` with -1 resolved to the proxy's default."""
        return PROXY_LIMITS[self.proxy][1] if self.idle_timeout == -1 else self.idle_timeout

    @property
    def robot_program(self) -> str:
        """``program`` with "" resolved: ``follow`` for KVP, ``none`` for C3 Bridge."""
        return self.program or ("none" if self.proxy == "c3bridge" else "follow")

    @property
    def latency_profile(self) -> LatencyProfile | None:
        return resolve_profile(self.latency)

    @property
    def discovery_enabled(self) -> bool:
        if self.discovery is None:
            return self.port != 0
        return self.discovery
