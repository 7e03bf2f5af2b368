"""URDF files both ways: an arm from a URDF (yourdfpy), and a clean mesh-free URDF of an arm.

Reading uses **yourdfpy** (the ``urdf`` extra), a small, maintained pure-Python URDF parser:
it reads the joint tree, limits and inertials without loading meshes, with no C++ build
(pinocchio) and without MuJoCo's importer, which merges fixed links, drops velocity limits and
wants every mesh file on disk. It is imported only here, when a ``.urdf`` file is loaded.

The serial chain runs from the root link to ``tip`` (default: ``tool0``, else ``flange``,
else the end of the longest chain of moving joints). Fixed joints before the first moving
joint become the arm's ``base``, fixed joints after the last one its ``flange``, and masses
of links bolted on by fixed joints (motors, flanges, tools) are lumped into the link they
ride on. A continuous
joint becomes a revolute joint with limits ±180°. Units change from metres and radians to
the toolkit's millimetres and degrees.

:func:`to_urdf` writes any arm back as URDF (metres, radians; inertials where known), the
form pinocchio, ikpy and MuJoCo load: the IK benchmark and the emulator's MuJoCo plant use it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from ..kinematics.frames import FloatArray
from .errors import ArmFileError
from .kuka import with_closed_form
from .model import Arm, Inertial, Joint, Source
from .spatial import rpy_from_matrix

__all__ = ["load_urdf", "to_urdf"]


def _combine(a: Inertial | None, b: Inertial | None) -> Inertial | None:
    """Mass properties of two bodies in one frame (parallel-axis theorem; mm and kg·m²)."""
    if a is None or b is None:
        return a or b
    m = a.mass + b.mass
    if m <= 0.0:
        return Inertial(0.0)
    com = (a.mass * a.com + b.mass * b.com) / m
    inertia = None
    if a.inertia is not None and b.inertia is not None:
        inertia = np.zeros((3, 3))
        for part in (a, b):
            d = (part.com - com) / 1000.0
            inertia += part.inertia + part.mass * (float(d @ d) * np.eye(3) - np.outer(d, d))  # type: ignore[operator]
    return Inertial(m, com, inertia)


def _moved(inertial: Inertial | None, t: FloatArray) -> Inertial | None:
    """An inertial of frame B expressed in frame A, ``t`` = A→B (mm)."""
    if inertial is None:
        return None
    r = t[:3, :3]
    inertia = None if inertial.inertia is None else r @ inertial.inertia @ r.T
    return Inertial(inertial.mass, r @ inertial.com + t[:3, 3], inertia)


def _link_inertial(link: Any) -> Inertial | None:
    inertial = getattr(link, "inertial", None)
    if inertial is None or inertial.mass is None:
        return None
    org = np.eye(4) if inertial.origin is None else np.array(inertial.origin, dtype=np.float64)
    inertia = None if inertial.inertia is None else np.array(inertial.inertia, dtype=np.float64)
    local = Inertial(float(inertial.mass), np.zeros(3), inertia)
    scaled = org.copy()
    scaled[:3, 3] *= 1000.0
    return _moved(local, scaled)


def _read(p: Path) -> Any:
    """The ``robot`` of the URDF file ``p`` (yourdfpy, no meshes, no scene graph)."""
    try:
        import yourdfpy
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ArmFileError(
            f"{p}: reading URDF needs yourdfpy (pip install 'pyopenshowvar[urdf]')"
        ) from exc
    try:
        urdf = yourdfpy.URDF.load(
            str(p),
            build_scene_graph=False,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
        )
    except Exception as exc:  # yourdfpy raises assorted errors (lxml, KeyError, ...)
        raise ArmFileError(f"{p}: not a usable URDF: {exc}") from exc
    return urdf.robot


def _chain_to_tip(
    p: Path, links: set[str], children: dict[str, list[Any]], root: str, tip: str | None
) -> list[Any]:
    """The joints from ``root`` to ``tip`` (default: ``tool0``, else ``flange``, else the
    chain with the most moving joints)."""

    def paths(link: str) -> list[list[Any]]:
        out: list[list[Any]] = [[]]
        for j in children.get(link, []):
            out += [[j, *rest] for rest in paths(j.child)]
        return out

    chains = paths(root)
    want = tip or next((t for t in ("tool0", "flange") if t in links), None)
    if tip is not None and tip not in links:
        raise ArmFileError(f"{p}: no link {tip!r}")
    if want is not None:
        chains = [c for c in chains if c and c[-1].child == want]
    else:
        chains.sort(key=lambda c: sum(j.type != "fixed" for j in c), reverse=True)
    if not chains:
        raise ArmFileError(f"{p}: no joint chain to {want!r}")
    return chains[0]


def _limits(p: Path, j: Any, revolute: bool) -> tuple[float, float, float, float]:
    """Joint ``j``'s lower, upper, speed (deg, mm) and effort; a revolute joint without
    limits (``continuous``) turns ±180°, a prismatic one must have them."""
    unit = math.degrees(1.0) if revolute else 1000.0
    lim = j.limit
    if j.type == "continuous" or lim is None or lim.lower is None or lim.upper is None:
        if not revolute:
            raise ArmFileError(f"{p}: prismatic joint {j.name!r} needs lower and upper limits")
        lower, upper = -180.0, 180.0
    else:
        lower, upper = float(lim.lower) * unit, float(lim.upper) * unit
    speed = float(lim.velocity) * unit if lim is not None and lim.velocity else math.nan
    effort = float(lim.effort) if lim is not None and lim.effort else math.nan
    return lower, upper, speed, effort


def load_urdf(path: str | Path, *, tip: str | None = None, name: str | None = None) -> Arm:
    """An arm from a URDF file (needs the ``urdf`` extra: ``pip install pyopenshowvar[urdf]``)."""
    p = Path(path)
    robot = _read(p)
    links = {link.name: link for link in robot.links}
    children: dict[str, list[Any]] = {}
    parents: set[str] = set()
    for j in robot.joints:
        children.setdefault(j.parent, []).append(j)
        parents.add(j.child)
    roots = [n for n in links if n not in parents]
    if len(roots) != 1:
        raise ArmFileError(f"{p}: a URDF arm needs one root link, found {roots}")
    chain = _chain_to_tip(p, set(links), children, roots[0], tip)

    def body(link: str) -> Inertial | None:
        """Mass of ``link`` and of everything bolted to it by fixed joints, in its frame."""
        total = _link_inertial(links[link])
        for j in children.get(link, []):
            if j.type == "fixed":
                org = np.eye(4) if j.origin is None else np.array(j.origin, dtype=np.float64)
                org[:3, 3] *= 1000.0
                total = _combine(total, _moved(body(j.child), org))
        return total

    joints: list[Joint] = []
    pending = np.eye(4)
    base = None
    for j in chain:
        org = np.eye(4) if j.origin is None else np.array(j.origin, dtype=np.float64)
        org[:3, 3] *= 1000.0
        if j.type == "fixed":
            pending = pending @ org
            continue
        if j.type not in ("revolute", "continuous", "prismatic"):
            raise ArmFileError(f"{p}: joint {j.name!r}: type {j.type!r} is not a serial-arm joint")
        if base is None:
            base, pending = pending, np.eye(4)
        revolute = j.type != "prismatic"
        lower, upper, speed, effort = _limits(p, j, revolute)
        axis = np.array([1.0, 0.0, 0.0] if j.axis is None else j.axis, dtype=np.float64)
        try:
            joints.append(
                Joint(j.name, "revolute" if revolute else "prismatic", pending @ org, axis,
                      lower, upper, speed, math.nan, effort, body(j.child))
            )  # fmt: skip
        except ValueError as exc:
            raise ArmFileError(f"{p}: {exc}") from exc
        pending = np.eye(4)
    if not joints:
        raise ArmFileError(f"{p}: no moving joints on the chain to {chain[-1].child!r}")
    arm = Arm(
        name or robot.name or p.stem,
        tuple(joints),
        base=base if base is not None else np.eye(4),
        flange=pending,
        base_inertial=body(roots[0]),
        source=Source(text=f"URDF file {p.name}"),
    )
    return with_closed_form(arm)


def _fmt(v: float) -> str:
    return repr(float(v))


def _origin(t: FloatArray) -> str:
    xyz = " ".join(_fmt(v / 1000.0) for v in t[:3, 3])
    rpy = " ".join(_fmt(v) for v in rpy_from_matrix(t))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def _inertial_xml(inertial: Inertial | None) -> str:
    if inertial is None:
        return ""
    i = inertial.inertia if inertial.inertia is not None else np.zeros((3, 3))
    xyz = " ".join(_fmt(v / 1000.0) for v in inertial.com)
    return (
        f'<inertial><origin xyz="{xyz}" rpy="0 0 0"/><mass value="{_fmt(inertial.mass)}"/>'
        f'<inertia ixx="{_fmt(i[0, 0])}" ixy="{_fmt(i[0, 1])}" ixz="{_fmt(i[0, 2])}" '
        f'iyy="{_fmt(i[1, 1])}" iyz="{_fmt(i[1, 2])}" izz="{_fmt(i[2, 2])}"/></inertial>'
    )


def to_urdf(arm: Arm, *, robot_name: str | None = None) -> str:
    """A mesh-free URDF of the arm: links ``base_link``, ``link_1`` … ``link_n``, ``flange``.

    Unknown speeds and efforts are written as 0 (URDF has no "unknown"); links without an
    inertial get none.
    """
    name = robot_name or (arm.key or "arm")
    out = [
        f"<robot name={quoteattr(name)}>",
        f'<link name="base_link">{_inertial_xml(arm.base_inertial)}</link>',
    ]
    parent = "base_link"
    for i, j in enumerate(arm.joints):
        org = j.origin if i else arm.base @ j.origin
        child = f"link_{i + 1}"
        unit = math.degrees(1.0) if j.revolute else 1000.0
        speed = 0.0 if math.isnan(j.max_speed) else j.max_speed / unit
        effort = 0.0 if math.isnan(j.max_effort) else j.max_effort
        out.append(f'<link name="{child}">{_inertial_xml(j.inertial)}</link>')
        out.append(
            f'<joint name={quoteattr(j.name)} type="{j.type}"><parent link="{parent}"/>'
            f'<child link="{child}"/>{_origin(org)}'
            f'<axis xyz="{" ".join(_fmt(v) for v in j.axis)}"/>'
            f'<limit lower="{_fmt(j.lower / unit)}" upper="{_fmt(j.upper / unit)}" '
            f'velocity="{_fmt(speed)}" effort="{_fmt(effort)}"/></joint>'
        )
        parent = child
    out.append('<link name="flange"/>')
    out.append(
        f'<joint name="flange_fixed" type="fixed"><parent link="{parent}"/>'
        f'<child link="flange"/>{_origin(arm.flange)}</joint>'
    )
    out.append("</robot>")
    return "\n".join(out) + "\n"
