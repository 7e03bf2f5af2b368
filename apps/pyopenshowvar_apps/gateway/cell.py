"""The cell file of ``kvp gateway``: which controllers to poll and how to serve them.

A TOML file (docs/gateway.md has a full example)::

    [cell]
    name = "weld-cell"                          # BrowseName of the MotionDeviceSystem
    endpoint = "opc.tcp://127.0.0.1:4840"       # the default; port 0 picks a free port

    [security]                                  # required when bound beyond loopback
    users = [{ name = "scada", password_hash = "pbkdf2-sha256$..." }]

    [[robot]]
    name = "r1"
    host = "192.168.1.10"                       # port 7000, poll_hz 10 by default
    variables = ["$OV_JOG", "MYAXIS"]           # extra variables, read-only
    writable = ["$OV_PRO"]                      # may be written through the WriteVariable method
    allow_motion_writes = true                  # $OV_PRO is a motion variable: say so

Everything is validated here, before a socket is opened: a typo is an error that names the key,
never a silently ignored option. Relative paths are relative to the cell file.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from pyopenshowvar_apps.hosts import is_loopback
from pyopenshowvar_apps.names import is_motion_variable

from .budget import MAX_VALUE_CHARS
from .passwords import UserEntry, check_hash_format

__all__ = [
    "CellConfig",
    "CellError",
    "RobotConfig",
    "SecurityConfig",
    "SnapshotGroup",
    "UserEntry",
    "load_cell",
    "parse_cell",
]

DEFAULT_ENDPOINT = "opc.tcp://127.0.0.1:4840"
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,31}")
# A KRL variable as KUKAVARPROXY reads it: a global or system name, optional index and members.
_KRL_NAME = re.compile(
    r"\$?[A-Za-z_][A-Za-z0-9_]*(\[[0-9, ]*\])?(\.[A-Za-z_][A-Za-z0-9_]*(\[[0-9, ]*\])?)*"
)
_INDEX = re.compile(r"\[[0-9, ]*\]")
MAX_POLL_HZ = 50.0
MAX_ROBOTS = 200


class CellError(ValueError):
    """The cell file is not valid; the message names the file and the offending key."""


@dataclass(frozen=True)
class SecurityConfig:
    """``enabled``: Basic256Sha256 Sign&Encrypt and user/password only; no anonymous, no None."""

    enabled: bool
    users: tuple[UserEntry, ...] = ()
    #: Where the server's generated certificate and key are kept.
    pki_dir: Path = Path("pki")
    #: Client certificates to trust (a folder of DER/PEM files); None accepts any client
    #: certificate and relies on the user/password check.
    trusted_clients: Path | None = None
    #: A client address with this many failed logins within ``lockout_seconds`` is refused
    #: (its logins unchecked, its new connections closed) until the oldest failure ages out.
    max_failed_logins: int = 5
    lockout_seconds: float = 60.0


@dataclass(frozen=True)
class SnapshotGroup:
    """Variables a controller copies into one global STRUC each SPS cycle (see docs/gateway.md).

    ``members`` maps each original variable name to its member of ``variable``; the gateway
    reads ``variable`` in one KVP request instead of one request per member.
    """

    variable: str
    members: Mapping[str, str]


@dataclass(frozen=True)
class RobotConfig:
    name: str
    host: str
    port: int = 7000
    poll_hz: float = 10.0
    #: Seconds for each KVP request (and for connecting).
    timeout: float = 1.0
    variables: tuple[str, ...] = ()
    writable: tuple[str, ...] = ()
    #: Writing a motion variable (pyopenshowvar_apps.names.MOTION_VARIABLES, e.g. $OV_PRO) can
    #: move the robot or change how it moves: listing one in ``writable`` needs this set too.
    allow_motion_writes: bool = False
    #: Maximum axis speeds A1..A6 in deg/s, which $VEL_AXIS_ACT's percent refers to; None takes
    #: them from the robot's arm (``arm``, else the catalogue arm its $MODEL_NAME[] names).
    max_axis_speed: tuple[float, ...] | None = None
    snapshots: tuple[SnapshotGroup, ...] = ()
    #: A reply longer than this is not parsed: the robot is misbehaving (gateway/budget.py).
    max_value_chars: int = MAX_VALUE_CHARS
    #: The arm (catalogue name or arm file) when $MODEL_NAME[] does not name a catalogue arm;
    #: "" = the one $MODEL_NAME[] names (pyopenshowvar_apps.armpick).
    arm: str = ""

    @property
    def exposed(self) -> tuple[str, ...]:
        """Extra variables shown on the controller: ``variables``, then writables not listed."""
        seen = {canonical(v) for v in self.variables}
        return self.variables + tuple(w for w in self.writable if canonical(w) not in seen)

    def writable_name(self, name: str) -> str | None:
        """The cell file's spelling of ``name`` when it is listed in ``writable``, else None.

        ``name`` must be a KRL variable name as a whole (no blank outside an index, nothing
        before or after it); it matches a listed name case-insensitively, blanks inside an
        index aside: ``$ov_pro`` and ``$OUT[ 1]`` match ``$OV_PRO`` and ``$OUT[1]``, while
        ``$OV _PRO``, ``$OV_PRO[]`` or ``$OV_PRO `` match nothing.
        """
        if not _KRL_NAME.fullmatch(name):
            return None
        key = canonical(name)
        return next((w for w in self.writable if canonical(w) == key), None)


@dataclass(frozen=True)
class CellConfig:
    name: str
    endpoint: str
    security: SecurityConfig
    robots: tuple[RobotConfig, ...] = field(default_factory=tuple)
    source: Path | None = None

    @property
    def host(self) -> str:
        return urlsplit(self.endpoint).hostname or ""

    @property
    def port(self) -> int:
        return urlsplit(self.endpoint).port or 0


def canonical(name: str) -> str:
    """The form two valid KRL names are compared in: upper case (KRL is case-insensitive),
    without the blanks inside an index (``$OUT[ 1]`` is ``$OUT[1]``)."""
    return _INDEX.sub(lambda m: m.group(0).replace(" ", ""), name).upper()


def load_cell(path: str | Path) -> CellConfig:
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CellError(f"{path}: cannot read the cell file: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise CellError(f"{path}: not valid TOML: {exc}") from None
    return parse_cell(data, source=path)


def parse_cell(data: Mapping[str, Any], *, source: Path | None = None) -> CellConfig:
    """Validate the parsed TOML; raises :class:`CellError` naming the first problem."""
    where = str(source) if source else "cell"
    base = source.parent if source else Path.cwd()
    _no_extra(data, {"cell", "security", "robot"}, where)
    cell = _table(data.get("cell", {}), f"{where}: [cell]")
    _no_extra(cell, {"name", "endpoint"}, f"{where}: [cell]")
    name = _str(cell.get("name", "cell"), f"{where}: cell.name")
    if not _NAME.fullmatch(name):
        raise CellError(f"{where}: cell.name {name!r}: letters, digits, _ and -, 1-32 characters")
    endpoint = _endpoint(
        _str(cell.get("endpoint", DEFAULT_ENDPOINT), f"{where}: cell.endpoint"), where
    )
    host = urlsplit(endpoint).hostname or ""
    security = _security(data.get("security"), host, base, where)
    robots_raw = data.get("robot", [])
    if not isinstance(robots_raw, list) or not robots_raw:
        raise CellError(f"{where}: at least one [[robot]] table is needed")
    if len(robots_raw) > MAX_ROBOTS:
        raise CellError(f"{where}: {len(robots_raw)} robots; at most {MAX_ROBOTS} per gateway")
    robots = tuple(_robot(r, i, where) for i, r in enumerate(robots_raw, 1))
    names = [r.name.lower() for r in robots]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise CellError(f"{where}: robot names must be unique (case-insensitive): {dupes}")
    return CellConfig(name, endpoint, security, robots, source)


def _endpoint(url: str, where: str) -> str:
    parts = urlsplit(url)
    try:
        port = parts.port
    except ValueError:
        port = -1
    if parts.scheme != "opc.tcp" or not parts.hostname or port is None or not 0 <= port <= 0xFFFF:
        raise CellError(f"{where}: cell.endpoint {url!r}: expected opc.tcp://HOST:PORT")
    return url


def _security(raw: Any, host: str, base: Path, where: str) -> SecurityConfig:
    loopback = is_loopback(host)
    if raw is None:
        if not loopback:
            raise CellError(
                f"{where}: the endpoint host {host!r} is beyond loopback: a [security] table"
                " with at least one user is required (Basic256Sha256 Sign&Encrypt, user/password)"
            )
        return SecurityConfig(enabled=False, pki_dir=base / "pki")
    sec = _table(raw, f"{where}: [security]")
    allowed = {
        "enabled",
        "users",
        "pki_dir",
        "trusted_clients",
        "max_failed_logins",
        "lockout_seconds",
    }
    _no_extra(sec, allowed, f"{where}: [security]")
    enabled = sec.get("enabled", True)
    if not isinstance(enabled, bool):
        raise CellError(f"{where}: security.enabled must be true or false")
    if not enabled and not loopback:
        raise CellError(
            f"{where}: security.enabled = false is only allowed on a loopback endpoint,"
            f" not on {host!r}"
        )
    users: list[UserEntry] = []
    for i, u in enumerate(sec.get("users", []), 1):
        what = f"{where}: security.users[{i}]"
        u = _table(u, what)
        _no_extra(u, {"name", "password_hash"}, what)
        uname = _str(u.get("name"), f"{what}.name")
        phash = _str(u.get("password_hash"), f"{what}.password_hash")
        problem = check_hash_format(phash)
        if problem:
            raise CellError(
                f"{what}.password_hash: {problem} (make one with kvp gateway --hash-password)"
            )
        users.append(UserEntry(uname, phash))
    if enabled and not users:
        raise CellError(f"{where}: security is on but security.users is empty")
    pki = base / _str(sec.get("pki_dir", "pki"), f"{where}: security.pki_dir")
    trusted = sec.get("trusted_clients")
    trusted_path = base / _str(trusted, f"{where}: security.trusted_clients") if trusted else None
    failures = sec.get("max_failed_logins", 5)
    if not isinstance(failures, int) or isinstance(failures, bool) or not 1 <= failures <= 10**6:
        raise CellError(f"{where}: security.max_failed_logins must be an integer in 1..1000000")
    lockout = _number(sec.get("lockout_seconds", 60.0), f"{where}: security.lockout_seconds")
    if not 1 <= lockout <= 86400:
        raise CellError(f"{where}: security.lockout_seconds must be within 1..86400")
    return SecurityConfig(enabled, tuple(users), pki, trusted_path, failures, lockout)


def _robot(raw: Any, index: int, where: str) -> RobotConfig:
    what = f"{where}: robot #{index}"
    r = _table(raw, what)
    allowed = {
        "name",
        "host",
        "port",
        "poll_hz",
        "timeout",
        "variables",
        "writable",
        "allow_motion_writes",
        "max_axis_speed",
        "snapshot",
        "max_value_chars",
        "arm",
    }
    _no_extra(r, allowed, what)
    name = _str(r.get("name"), f"{what}.name")
    if not _NAME.fullmatch(name):
        raise CellError(f"{what}.name {name!r}: letters, digits, _ and -, 1-32 characters")
    what = f"{where}: robot {name!r}"
    host = _str(r.get("host"), f"{what}.host")
    port = r.get("port", 7000)
    if not isinstance(port, int) or isinstance(port, bool) or not 1 <= port <= 0xFFFF:
        raise CellError(f"{what}.port must be an integer in 1..65535")
    poll_hz = _number(r.get("poll_hz", 10.0), f"{what}.poll_hz")
    if not 0 < poll_hz <= MAX_POLL_HZ:
        raise CellError(f"{what}.poll_hz must be > 0 and <= {MAX_POLL_HZ:g}")
    timeout = _number(r.get("timeout", 1.0), f"{what}.timeout")
    if not 0.05 <= timeout <= 60:
        raise CellError(f"{what}.timeout must be within 0.05..60 s")
    variables = _names(r.get("variables", []), f"{what}.variables")
    writable = _names(r.get("writable", []), f"{what}.writable")
    motion = r.get("allow_motion_writes", False)
    if not isinstance(motion, bool):
        raise CellError(f"{what}.allow_motion_writes must be true or false")
    moving = [w for w in writable if is_motion_variable(w)]
    if moving and not motion:
        raise CellError(
            f"{what}.writable lists motion variables {moving}: writing them can move the robot"
            " or change how it moves; set allow_motion_writes = true to allow it"
        )
    speeds_raw = r.get("max_axis_speed")
    speeds: tuple[float, ...] | None = None
    if speeds_raw is not None:
        if not isinstance(speeds_raw, list) or len(speeds_raw) != 6:
            raise CellError(f"{what}.max_axis_speed needs 6 numbers (deg/s, A1..A6)")
        speeds = tuple(_number(s, f"{what}.max_axis_speed") for s in speeds_raw)
        if any(s <= 0 for s in speeds):
            raise CellError(f"{what}.max_axis_speed: every speed must be > 0")
    snaps = tuple(
        _snapshot(s, f"{what}.snapshot[{i}]") for i, s in enumerate(r.get("snapshot", []), 1)
    )
    chars = r.get("max_value_chars", MAX_VALUE_CHARS)
    if not isinstance(chars, int) or isinstance(chars, bool) or not 256 <= chars <= 65535:
        raise CellError(f"{what}.max_value_chars must be an integer in 256..65535")
    arm = _str(r.get("arm", ""), f"{what}.arm") if "arm" in r else ""
    if arm:
        from ..armpick import given_arm

        try:
            given_arm(arm)
        except (LookupError, ValueError, OSError) as exc:
            raise CellError(f"{what}.arm: {exc}") from None
    return RobotConfig(
        name, host, port, poll_hz, timeout, variables, writable, motion, speeds, snaps, chars, arm
    )


def _snapshot(raw: Any, what: str) -> SnapshotGroup:
    s = _table(raw, what)
    _no_extra(s, {"variable", "members"}, what)
    variable = _str(s.get("variable"), f"{what}.variable")
    if not _KRL_NAME.fullmatch(variable):
        raise CellError(f"{what}.variable {variable!r} is not a KRL variable name")
    members_raw = _table(s.get("members"), f"{what}.members")
    if not members_raw:
        raise CellError(f"{what}.members is empty")
    members: dict[str, str] = {}
    for original, member in members_raw.items():
        member = _str(member, f"{what}.members[{original!r}]")
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", member):
            raise CellError(f"{what}.members[{original!r}]: {member!r} is not a member name")
        members[original] = member
    return SnapshotGroup(variable, members)


def _names(raw: Any, what: str) -> tuple[str, ...]:
    if not isinstance(raw, list):
        raise CellError(f"{what} must be a list of variable names")
    out: list[str] = []
    for item in raw:
        name = _str(item, what).strip()
        if not _KRL_NAME.fullmatch(name):
            raise CellError(f"{what}: {name!r} is not a KRL variable name")
        out.append(name)
    return tuple(out)


def _table(raw: Any, what: str) -> Mapping[str, Any]:
    if not isinstance(raw, Mapping):
        raise CellError(f"{what} must be a table")
    return raw


def _str(raw: Any, what: str) -> str:
    if not isinstance(raw, str) or not raw:
        raise CellError(f"{what} must be a non-empty string")
    return raw


def _number(raw: Any, what: str) -> float:
    if isinstance(raw, bool) or not isinstance(raw, int | float):
        raise CellError(f"{what} must be a number")
    return float(raw)


def _no_extra(table: Mapping[str, Any], allowed: set[str], what: str) -> None:
    extra = sorted(set(table) - allowed)
    if extra:
        raise CellError(f"{what}: unknown key(s) {extra} (allowed: {sorted(allowed)})")
