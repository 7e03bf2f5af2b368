"""Operational profiles (thesis §5.2.1.3): how a crane's control system is used, as data.

A *profile* is a set of independent states with their probabilities of occurrence. Five
profiles narrow down how the crane is used — customer types, user types (operator classes),
system modes (position or velocity control), functions (a lift: a sequence of operations) —
and each function's operations are run in *run categories* (how fast) and *run types* (the
initial state: payload and joint configuration). One path through all levels is one run of
the benchmark; its probability is the product of the states' probabilities. A profile file
(TOML) lists every level as an array of tables; see ``profiles/container_lift.toml`` (the
thesis' experiment) and docs/maritime.md.

Every level's probabilities must sum to 1, every key must be known (a typo is an error naming
the key and the table), and a user type may cap the payload (``max_payload_kg``, e.g. a class 2
operator below half the crane's capacity): runs a user type may not make are left out and the
remaining runs' probabilities renormalised.
"""

from __future__ import annotations

import difflib
import itertools
import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

__all__ = [
    "LEVELS",
    "Operation",
    "Profile",
    "ProfileError",
    "Run",
    "State",
    "builtin_profile",
    "load_profile",
    "parse_profile",
]

#: the composed levels, in the thesis' order (Fig. 5.3), then run categories and run types
LEVELS = ("customer", "user", "mode", "function", "run_category", "run_type")
_STATE_KEYS: dict[str, dict[str, type | tuple[type, ...]]] = {
    "customer": {},
    "user": {"speed_scale": (int, float), "max_payload_kg": (int, float)},
    "mode": {"mode": str},
    "function": {"operations": list},
    "run_category": {"speed_deg_s": (int, float)},
    "run_type": {"payload_kg": (int, float), "initial_deg": list},
}
_REQUIRED = {"mode": ("mode",), "function": ("operations",), "run_category": ("speed_deg_s",),
             "run_type": ("payload_kg", "initial_deg")}  # fmt: skip
_TOP = {"name": str, "description": str, "crane": str, "control_period_s": (int, float),
        "log_period_s": (int, float), "hold_s": (int, float), "weights": dict, "sea": dict,
        "operation": list, **{lv: list for lv in LEVELS}}  # fmt: skip
_WEIGHTS = {"alpha": (int, float), "beta": (int, float)}
_SEA = {"hs": (int, float), "tp": (int, float), "heading": (int, float),
        "crane_on_deck_m": list, "seed": int}  # fmt: skip
_OPERATION = {"name": str, "joint": str, "move_deg": (int, float)}
MODES = ("position", "velocity")


class ProfileError(ValueError):
    """A profile file that cannot be used; the message names the file, table and key."""


@dataclass(frozen=True)
class State:
    """One state of a level: its name, probability and attributes."""

    name: str
    p: float
    attrs: dict[str, Any]


@dataclass(frozen=True)
class Operation:
    """One operation (Fig. 5.4): move ``joint`` by ``move_deg`` degrees."""

    name: str
    joint: str
    move_deg: float


@dataclass(frozen=True)
class Run:
    """One composed run: a path through every level, with its probability."""

    states: tuple[State, ...]
    probability: float
    operations: tuple[Operation, ...]
    mode: str
    speed_deg_s: float
    payload_kg: float
    initial_deg: tuple[float, ...]

    @property
    def name(self) -> str:
        return " / ".join(s.name for s in self.states)


@dataclass(frozen=True)
class Profile:
    """A parsed profile file: its levels, operations and the benchmark's settings."""

    name: str
    description: str
    crane: str
    levels: dict[str, tuple[State, ...]]
    operations: dict[str, Operation]
    control_period_s: float = 0.1
    log_period_s: float = 0.02
    hold_s: float = 2.0
    alpha: float = 0.5
    beta: float = 0.5
    sea: dict[str, Any] | None = None

    def runs(self) -> list[Run]:
        """Every permitted path through the levels, most probable first (eq.: the product
        of the states' probabilities, renormalised over the permitted paths)."""
        out: list[Run] = []
        for combo in itertools.product(*(self.levels[lv] for lv in LEVELS)):
            _, user, mode, function, category, rtype = combo
            payload = float(rtype.attrs["payload_kg"])
            if payload > float(user.attrs.get("max_payload_kg", math.inf)):
                continue
            ops = tuple(self.operations[o] for o in function.attrs["operations"])
            speed = float(category.attrs["speed_deg_s"]) * float(user.attrs.get("speed_scale", 1.0))
            out.append(Run(combo, math.prod(s.p for s in combo), ops, mode.attrs["mode"], speed,
                           payload, tuple(float(v) for v in rtype.attrs["initial_deg"])))  # fmt: skip
        total = sum(r.probability for r in out)
        if not out or total <= 0.0:
            raise ProfileError(f"{self.name}: no user type may make any of the run types")
        out = [Run(r.states, r.probability / total, r.operations, r.mode, r.speed_deg_s,
                   r.payload_kg, r.initial_deg) for r in out]  # fmt: skip
        return sorted(out, key=lambda r: -r.probability)


def _check_keys(where: str, table: dict[str, Any], allowed: dict[str, Any]) -> None:
    for key, value in table.items():
        if key not in allowed:
            near = difflib.get_close_matches(key, list(allowed), n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise ProfileError(f"{where}: unknown key {key!r}{hint}; allowed: {', '.join(allowed)}")
        kind = allowed[key]
        if not isinstance(value, kind) or isinstance(value, bool):
            raise ProfileError(f"{where}: {key!r} has the wrong type ({type(value).__name__})")


def _level(src: str, level: str, items: Any) -> tuple[State, ...]:
    if not isinstance(items, list) or not items:
        raise ProfileError(f"{src}: [[{level}]] needs at least one state")
    states = []
    for i, item in enumerate(items, 1):
        where = f"{src}: [[{level}]] #{i}"
        allowed = {"name": str, "p": (int, float), **_STATE_KEYS[level]}
        _check_keys(where, item, allowed)
        for key in ("name", "p", *_REQUIRED.get(level, ())):
            if key not in item:
                raise ProfileError(f"{where}: missing key {key!r}")
        p = float(item["p"])
        if not 0.0 <= p <= 1.0:
            raise ProfileError(f"{where}: probability 'p' must be in [0, 1], got {p}")
        attrs = {k: v for k, v in item.items() if k not in ("name", "p")}
        states.append(State(str(item["name"]), p, attrs))
    total = sum(s.p for s in states)
    if abs(total - 1.0) > 1e-6:
        raise ProfileError(f"{src}: the probabilities of [[{level}]] sum to {total:g}, not 1")
    return tuple(states)


def parse_profile(
    doc: dict[str, Any], src: str = "profile", joints: tuple[str, ...] = ()
) -> Profile:
    """A :class:`Profile` from a parsed TOML document (``joints``: the crane's joint names,
    to check the operations against)."""
    _check_keys(src, doc, _TOP)
    for key in ("name", "crane", "operation", *LEVELS):
        if key not in doc:
            raise ProfileError(f"{src}: missing key {key!r}")
    _check_keys(f"{src}: [weights]", doc.get("weights", {}), _WEIGHTS)
    _check_keys(f"{src}: [sea]", doc.get("sea", {}), _SEA)
    ops: dict[str, Operation] = {}
    for i, item in enumerate(doc["operation"], 1):
        where = f"{src}: [[operation]] #{i}"
        _check_keys(where, item, _OPERATION)
        if set(item) != set(_OPERATION):
            raise ProfileError(f"{where}: needs {', '.join(_OPERATION)}")
        if joints and item["joint"] not in joints:
            raise ProfileError(
                f"{where}: unknown joint {item['joint']!r}; one of {', '.join(joints)}"
            )
        ops[item["name"]] = Operation(item["name"], item["joint"], float(item["move_deg"]))
    levels = {lv: _level(src, lv, doc[lv]) for lv in LEVELS}
    for s in levels["mode"]:
        if s.attrs["mode"] not in MODES:
            raise ProfileError(f"{src}: [[mode]] {s.name!r}: mode must be one of {MODES}")
    for s in levels["function"]:
        for name in s.attrs["operations"]:
            if name not in ops:
                raise ProfileError(f"{src}: [[function]] {s.name!r}: no [[operation]] {name!r}")
    for s in levels["run_category"]:
        if not float(s.attrs["speed_deg_s"]) > 0.0:
            raise ProfileError(f"{src}: [[run_category]] {s.name!r}: speed_deg_s must be > 0")
    for s in levels["run_type"]:
        if joints and len(s.attrs["initial_deg"]) != len(joints):
            raise ProfileError(
                f"{src}: [[run_type]] {s.name!r}: initial_deg needs {len(joints)} angles"
            )
    weights = doc.get("weights", {})
    alpha, beta = float(weights.get("alpha", 0.5)), float(weights.get("beta", 0.5))
    if alpha < 0.0 or beta < 0.0 or abs(alpha + beta - 1.0) > 1e-9:
        raise ProfileError(f"{src}: [weights] alpha and beta must be >= 0 and sum to 1 (eq. 5.5)")
    periods = {
        k: float(doc.get(k, d)) for k, d in (("control_period_s", 0.1), ("log_period_s", 0.02))
    }
    ratio = periods["control_period_s"] / periods["log_period_s"]
    if not (periods["log_period_s"] > 0.0 and ratio >= 1.0 and abs(ratio - round(ratio)) < 1e-9):
        raise ProfileError(f"{src}: control_period_s must be a whole multiple of log_period_s")
    return Profile(str(doc["name"]), str(doc.get("description", "")), str(doc["crane"]), levels,
                   ops, periods["control_period_s"], periods["log_period_s"],
                   float(doc.get("hold_s", 2.0)), alpha, beta, doc.get("sea"))  # fmt: skip


def load_profile(path: str | Path, joints: tuple[str, ...] = ()) -> Profile:
    """Read and check a profile file (TOML)."""
    p = Path(path)
    try:
        doc = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ProfileError(f"{p}: cannot read: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{p}: not valid TOML: {exc}") from None
    return parse_profile(doc, p.name, joints)


def builtin_profile(name: str = "container_lift") -> Path:
    """The path of a profile shipped with the package (``profiles/<name>.toml``)."""
    path = Path(str(resources.files(__package__).joinpath("profiles").joinpath(f"{name}.toml")))
    if not path.is_file():
        raise ProfileError(f"no built-in profile {name!r}")
    return path
