"""Arm files: the TOML schema (D-H tables or a URDF-like chain), read strictly.

A file is a table of top-level keys and one ``[[joint]]`` table per joint, base outwards
(schema in docs/arms.md). Every key is checked: an unknown key, a missing one or a value of
the wrong type is one :class:`~.errors.ArmFileError` naming the file, the joint and the key
(with a "did you mean" for typos), never a silently ignored line. Files in the older
six-axis schema of :meth:`~pyopenshowvar.kinematics.RobotModel.from_file` (``[[axis]]``
tables) load too.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..kinematics.frames import FloatArray
from ..kinematics.model import RobotModel
from .dh import DHRow, dh_chain
from .errors import ArmFileError
from .kuka import from_robot_model, with_closed_form
from .model import Arm, Inertial, Joint, Source
from .spatial import origin

__all__ = ["arm_from_dict", "load_toml"]

_TOP = {
    "name", "convention", "joint", "flange", "base", "home", "source", "family",
    "model_name", "length_unit", "angle_unit", "base_inertial", "builtin", "closed_form",
}  # fmt: skip
_JOINT_COMMON = {
    "name",
    "type",
    "lower",
    "upper",
    "max_speed",
    "max_accel",
    "max_effort",
    "inertial",
}
_JOINT_DH = {"a", "alpha", "d", "theta", "sign"}
_JOINT_CHAIN = {"xyz", "rpy", "axis"}
_FRAME = {"xyz", "rpy"}
_INERTIAL = {"mass", "com", "inertia", "rpy"}
_SOURCE = {"text", "url", "commit", "licence", "notes"}
_LENGTH = {"mm": 1.0, "m": 1000.0}
_ANGLE = {"deg": 1.0, "rad": math.degrees(1.0)}


class _Ctx:
    """Where we are in the file, for messages: ``arm.toml: joint 3 ('A3')``."""

    def __init__(self, file: str) -> None:
        self.file = file

    def fail(self, where: str, msg: str) -> ArmFileError:
        return ArmFileError(f"{self.file}: {where + ': ' if where else ''}{msg}")

    def keys(self, table: Mapping[str, Any], allowed: set[str], where: str) -> None:
        for k in table:
            if k not in allowed:
                near = difflib.get_close_matches(k, sorted(allowed), n=1)
                hint = f" (did you mean {near[0]!r}?)" if near else ""
                raise self.fail(where, f"unknown key {k!r}{hint}")

    def num(self, table: Mapping[str, Any], key: str, where: str, default: Any = ...) -> float:
        if key not in table:
            if default is ...:
                raise self.fail(where, f"missing {key!r}")
            return float(default)
        v = table[key]
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise self.fail(where, f"{key!r} must be a finite number, got {v!r}")
        return float(v)

    def vec(
        self, table: Mapping[str, Any], key: str, n: int, where: str, default: Any = ...
    ) -> FloatArray:
        if key not in table:
            if default is ...:
                raise self.fail(where, f"missing {key!r}")
            return np.array(default, dtype=np.float64)
        v = table[key]
        ok = isinstance(v, list) and len(v) == n
        ok = ok and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)
        if not ok or not all(math.isfinite(x) for x in v):
            raise self.fail(where, f"{key!r} must be a list of {n} numbers, got {v!r}")
        return np.array(v, dtype=np.float64)

    def text(self, table: Mapping[str, Any], key: str, where: str, default: str = "") -> str:
        v = table.get(key, default)
        if not isinstance(v, str):
            raise self.fail(where, f"{key!r} must be a string, got {v!r}")
        return v

    def table(self, parent: Mapping[str, Any], key: str, where: str) -> Mapping[str, Any] | None:
        v = parent.get(key)
        if v is None:
            return None
        if not isinstance(v, dict):
            raise self.fail(where, f"{key!r} must be a table, got {v!r}")
        return v


def _frame(ctx: _Ctx, data: Mapping[str, Any], key: str, lu: float, au: float) -> FloatArray:
    t = ctx.table(data, key, "")
    if t is None:
        return np.eye(4)
    ctx.keys(t, _FRAME, key)
    xyz = ctx.vec(t, "xyz", 3, key, [0.0, 0.0, 0.0]) * lu
    rpy = np.radians(ctx.vec(t, "rpy", 3, key, [0.0, 0.0, 0.0]) * au)
    return origin(xyz, rpy)


def _inertial(
    ctx: _Ctx, t: Mapping[str, Any] | None, where: str, lu: float, au: float
) -> Inertial | None:
    if t is None:
        return None
    ctx.keys(t, _INERTIAL, where)
    mass = ctx.num(t, "mass", where)
    com = ctx.vec(t, "com", 3, where, [0.0, 0.0, 0.0]) * lu
    inertia = None
    if "inertia" in t:
        ixx, ixy, ixz, iyy, iyz, izz = ctx.vec(t, "inertia", 6, where)
        inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        rot = origin([0, 0, 0], np.radians(ctx.vec(t, "rpy", 3, where, [0, 0, 0]) * au))[:3, :3]
        inertia = rot @ inertia @ rot.T  # principal-axes frame -> link axes
    try:
        return Inertial(mass, com, inertia)
    except ValueError as exc:
        raise ctx.fail(where, str(exc)) from exc


def arm_from_dict(data: Mapping[str, Any], file: str = "<arm>", key: str = "") -> Arm:
    """Build an arm from parsed TOML (see docs/arms.md); errors name ``file`` and the key."""
    ctx = _Ctx(file)
    if "axis" in data and "joint" not in data:
        try:
            model = RobotModel.from_dict(data)
        except (ValueError, TypeError, KeyError) as exc:
            raise ctx.fail("", str(exc)) from exc
        return from_robot_model(model, key=key)
    ctx.keys(data, _TOP, "")
    src_t = ctx.table(data, "source", "") or {}
    ctx.keys(src_t, _SOURCE, "source")
    source = Source(**{k: ctx.text(src_t, k, "source") for k in _SOURCE})
    meta: dict[str, Any] = {
        "key": key,
        "family": ctx.text(data, "family", ""),
        "model_name": ctx.text(data, "model_name", ""),
        "source": source,
    }
    if "builtin" in data:
        return _builtin(ctx, data, meta)
    name = ctx.text(data, "name", "")
    if not name:
        raise ctx.fail("", "missing 'name'")
    lu, au = _units(ctx, data)
    conv = ctx.text(data, "convention", "")
    if conv not in ("standard", "modified", "chain"):
        raise ctx.fail("", f"convention must be 'standard', 'modified' or 'chain', got {conv!r}")
    rows = data.get("joint")
    if not isinstance(rows, list) or not rows or not all(isinstance(r, dict) for r in rows):
        raise ctx.fail("", "needs [[joint]] tables, base outwards")
    specs, dh_rows, inertials, chain = _joint_rows(ctx, rows, conv, lu, au)
    if conv == "chain":
        tail = np.eye(4)
        links = inertials
    else:
        chain, tail, links = dh_chain(dh_rows, conv, inertials)  # type: ignore[arg-type]
    joints = []
    for spec, (org, axis), inertial in zip(specs, chain, links, strict=True):
        where = spec.pop("where")
        try:
            joints.append(Joint(origin=org, axis=axis, inertial=inertial, **spec))
        except ValueError as exc:
            raise ctx.fail(where, str(exc)) from exc
    home = None
    if "home" in data:
        scale = np.where([s["type"] == "revolute" for s in specs], au, lu)
        home = ctx.vec(data, "home", len(joints), "") * scale
    flange = tail @ _frame(ctx, data, "flange", lu, au)
    base_in = _inertial(ctx, ctx.table(data, "base_inertial", ""), "base_inertial", lu, au)
    try:
        arm = Arm(name, tuple(joints), _frame(ctx, data, "base", lu, au), flange, home,
                  base_in, **meta)  # fmt: skip
    except ValueError as exc:
        raise ctx.fail("", str(exc)) from exc
    return _closed_form(ctx, data, arm)


def _units(ctx: _Ctx, data: Mapping[str, Any]) -> tuple[float, float]:
    """The file's length and angle units as factors to mm and degrees."""
    lu_name = ctx.text(data, "length_unit", "", "mm")
    au_name = ctx.text(data, "angle_unit", "", "deg")
    if lu_name not in _LENGTH:
        raise ctx.fail("", f"length_unit must be 'mm' or 'm', got {lu_name!r}")
    if au_name not in _ANGLE:
        raise ctx.fail("", f"angle_unit must be 'deg' or 'rad', got {au_name!r}")
    lu, au = _LENGTH[lu_name], _ANGLE[au_name]
    return lu, au


def _joint_rows(
    ctx: _Ctx, rows: list[dict[str, Any]], conv: str, lu: float, au: float
) -> tuple[
    list[dict[str, Any]],
    list[DHRow],
    list[Inertial | None],
    list[tuple[FloatArray, FloatArray]],
]:
    """The ``[[joint]]`` tables checked: per moving joint its :class:`Joint` arguments
    (``where`` added), per row its D-H row or (``chain``) its origin and axis, its inertial."""
    allowed = _JOINT_COMMON | (_JOINT_CHAIN if conv == "chain" else _JOINT_DH)
    specs: list[dict[str, Any]] = []
    dh_rows: list[DHRow] = []
    inertials: list[Inertial | None] = []
    chain: list[tuple[FloatArray, FloatArray]] = []
    for i, row in enumerate(rows):
        where = f"joint {i + 1}" + (
            f" ({row['name']!r})" if isinstance(row.get("name"), str) else ""
        )
        ctx.keys(row, allowed, where)
        jtype = ctx.text(row, "type", where, "revolute")
        if jtype not in ("revolute", "prismatic", "fixed") or (
            jtype == "fixed" and conv == "chain"
        ):
            kinds = "revolute or prismatic" + ("" if conv == "chain" else " (or fixed)")
            raise ctx.fail(where, f"'type' must be {kinds}, got {jtype!r}")
        inertial = _inertial(ctx, ctx.table(row, "inertial", where), where + " inertial", lu, au)
        if conv == "chain":
            xyz = ctx.vec(row, "xyz", 3, where, [0.0, 0.0, 0.0]) * lu
            rpy = np.radians(ctx.vec(row, "rpy", 3, where, [0.0, 0.0, 0.0]) * au)
            chain.append((origin(xyz, rpy), ctx.vec(row, "axis", 3, where, [0.0, 0.0, 1.0])))
            inertials.append(inertial)
        else:
            sign = ctx.num(row, "sign", where, 1.0)
            if sign not in (1.0, -1.0):
                raise ctx.fail(where, f"'sign' must be 1 or -1, got {sign:g}")
            dh_rows.append(
                DHRow(jtype, ctx.num(row, "a", where, 0.0) * lu,
                      math.radians(ctx.num(row, "alpha", where, 0.0) * au),
                      ctx.num(row, "d", where, 0.0) * lu,
                      math.radians(ctx.num(row, "theta", where, 0.0) * au), sign)
            )  # fmt: skip
            inertials.append(inertial)
        if jtype == "fixed":
            for k in ("lower", "upper", "max_speed", "max_accel", "max_effort", "name"):
                if k in row:
                    raise ctx.fail(where, f"a fixed row has no {k!r}")
            continue
        unit = au if jtype == "revolute" else lu
        spec: dict[str, Any] = {
            "name": ctx.text(row, "name", where, f"J{len(specs) + 1}"),
            "type": jtype,
            "lower": ctx.num(row, "lower", where) * unit,
            "upper": ctx.num(row, "upper", where) * unit,
            "max_speed": ctx.num(row, "max_speed", where, math.nan) * unit,
            "max_accel": ctx.num(row, "max_accel", where, math.nan) * unit,
            "max_effort": ctx.num(row, "max_effort", where, math.nan),
            "where": where,
        }
        specs.append(spec)
    return specs, dh_rows, inertials, chain


def _closed_form(ctx: _Ctx, data: Mapping[str, Any], arm: Arm) -> Arm:
    """``arm`` with its closed-form model unless ``closed_form = false``; ``true`` demands one."""
    want = data.get("closed_form", None)
    if want is not None and not isinstance(want, bool):
        raise ctx.fail("", f"'closed_form' must be true or false, got {want!r}")
    if want is False:
        return arm
    arm = with_closed_form(arm)
    if want and arm.kuka is None:
        raise ctx.fail("", "closed_form = true, but the chain is not a KUKA-layout 6R arm")
    return arm


def _builtin(ctx: _Ctx, data: Mapping[str, Any], meta: dict[str, Any]) -> Arm:
    from .. import kinematics

    ctx.keys(data, {"builtin", "family", "model_name", "source"}, "")
    ref = ctx.text(data, "builtin", "")
    model = getattr(kinematics, ref, None)
    if not isinstance(model, RobotModel):
        raise ctx.fail(
            "", f"'builtin' must name a RobotModel of pyopenshowvar.kinematics, got {ref!r}"
        )
    return from_robot_model(model, **meta)


def load_toml(path: str | Path, key: str = "") -> Arm:
    """Load an arm from a TOML file."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ArmFileError(f"{p}: cannot read: {exc.strerror or exc}") from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ArmFileError(f"{p}: not valid TOML: {exc}") from exc
    return arm_from_dict(data, str(p), key)
