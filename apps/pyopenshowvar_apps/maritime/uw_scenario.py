"""The underwater planner's world: the workspace image of cubes, obstacle domains, the arm's
links as cylinders, their distance to the domains (Fig. 7) and their projected area (eq. 7).

Ishibashi et al. divide the workspace into 10 mm cubes (Fig. 1); an obstacle domain is the
cubes holding an obstacle plus the cubes around it (Fig. 2). A scenario here is a TOML file
(or :data:`PAPER`, Table 1's): positions in cube units, the arm from the arms catalogue
(any name or file ``load_arm`` takes), where its base stands (mm), the links' radius, the
flow direction and the GA settings. Domains are boxes of cubes (inclusive index ranges).

Geometry (millimetres): a link is the segment between consecutive joint origins (and the
flange), a cylinder of the link radius about it. Its distance to a domain is the exact
segment-to-box distance minus the radius, so clearance > 0 means no contact (Fig. 7's
pattern (iii) is clearance ≤ 0); the segment-to-box distance is convex along the segment
and found exactly from its piecewise-quadratic form.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from pyopenshowvar.arms import Arm, load_arm

__all__ = [
    "PAPER",
    "Box",
    "Scenario",
    "clearances",
    "link_points",
    "load_scenario",
    "point_box_distance",
    "projected_area",
    "segment_box_distance",
]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Box:
    """An obstacle domain: cubes ``lo..hi`` (inclusive cube indices) of the workspace image."""

    lo: tuple[int, int, int]
    hi: tuple[int, int, int]

    @property
    def cubes(self) -> int:
        return int(np.prod(np.subtract(self.hi, self.lo) + 1))

    def bounds_mm(self, cube: float) -> tuple[FloatArray, FloatArray]:
        """The domain's faces in mm: cube i is centred on i·cube, so it spans (i ± ½)·cube."""
        return (np.asarray(self.lo, float) - 0.5) * cube, (np.asarray(self.hi, float) + 0.5) * cube


@dataclass(frozen=True)
class Scenario:
    """One planning problem; the defaults are the paper's Tables 1 and 2 and our choices."""

    cube: float = 10.0  # mm
    start: tuple[int, int, int] = (40, -30, 65)
    goal: tuple[int, int, int] = (25, -80, 15)
    x_range: tuple[int, int] = (0, 63)  # cube indices GA_p may choose on an X-Z plane
    z_range: tuple[int, int] = (-20, 107)
    obstacles: tuple[Box, ...] = (
        Box((34, -46, 48), (35, -44, 51)),
        Box((29, -66, 28), (30, -64, 31)),
    )
    arm: str = "lbr_iiwa14_r820"
    base: tuple[float, float, float] = (0.0, -550.0, 0.0)  # mm, the arm's base in the image
    link_radius: float = 60.0  # mm
    flow: tuple[float, float, float] = (0.0, 0.0, 1.0)  # "parallel to the Z-axis"
    # GA_p (Table 1) and eq. 1's weights
    path_individuals: int = 60
    path_generations: int = 60
    path_crossover: float = 0.5
    path_mutation: float = 0.05
    alpha: tuple[float, float, float] = (40.0, 1.0, 1.0)
    max_step: int = 2  # cubes GA_p may move the tip in X and in Z from one plane to the next
    # GA_m (Table 2), its candidates and eq. 3's weights
    posture_individuals: int = 200
    posture_generations: int = 400
    posture_crossover: float = 0.75
    posture_mutation: float = 0.15
    bits_per_joint: int = 12
    seed_spread: float = 10.0  # deg: half of GA_m's first population is the present posture ± this
    tolerance: float = 5.0  # mm: a candidate's tip within half a cube of the objective
    max_candidates: int = 20
    regenerate_after: int = 40  # generations without a candidate before a new population
    beta: tuple[float, float, float] = (1.0, 1.0, 20.0)
    step_deg: float = 1.0  # joint-space sampling of a posture change (collisions, eq. 8)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.cube <= 0 or self.link_radius < 0:
            raise ValueError("cube size must be > 0 and the link radius >= 0")
        if self.start[1] == self.goal[1]:
            raise ValueError("start and goal must lie on different X-Z planes (Y differs)")
        if not (self.x_range[0] < self.x_range[1] and self.z_range[0] < self.z_range[1]):
            raise ValueError("x_range and z_range must be increasing")
        if np.linalg.norm(self.flow) == 0:
            raise ValueError("flow direction must not be zero")
        for name in ("path_individuals", "posture_individuals"):
            if getattr(self, name) < 2:
                raise ValueError(f"{name} must be at least 2")
        for name in ("path_generations", "posture_generations", "max_candidates", "max_step"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least 1")

    def load_arm(self) -> Arm:
        return load_arm(self.arm)

    def mm(self, cube_xyz: Any) -> FloatArray:
        """Cube indices to the cube centre in mm."""
        return np.asarray(cube_xyz, dtype=np.float64) * self.cube

    def boxes_mm(self) -> tuple[FloatArray, FloatArray]:
        """Domains as arrays of faces in mm: lo ``(B, 3)``, hi ``(B, 3)``."""
        if not self.obstacles:
            return np.zeros((0, 3)), np.zeros((0, 3))
        lo, hi = zip(*(b.bounds_mm(self.cube) for b in self.obstacles), strict=True)
        return np.stack(lo), np.stack(hi)


PAPER = Scenario()

_INT3 = ("start", "goal")
_FLOAT3 = ("base", "flow")


def load_scenario(path: str | Path) -> Scenario:
    """A scenario TOML: the keys of :class:`Scenario` at the top level, obstacles as
    ``[[obstacle]]`` tables with ``lo`` and ``hi``; anything else is an error naming it."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ValueError(f"{p}: {exc}") from None
    known = {f.name for f in fields(Scenario)} - {"obstacles"}
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if key == "obstacle":
            try:
                kwargs["obstacles"] = tuple(
                    Box(_ints(o["lo"], 3), _ints(o["hi"], 3)) for o in value
                )
            except (KeyError, TypeError, ValueError) as exc:
                raise ValueError(
                    f"{p}: [[obstacle]] needs lo = [x, y, z], hi = [x, y, z] ({exc})"
                ) from None
            continue
        if key not in known:
            raise ValueError(f"{p}: unknown key {key!r}")
        default = getattr(PAPER, key)
        try:
            if key in _INT3:
                kwargs[key] = _ints(value, 3)
            elif key in _FLOAT3 or isinstance(default, tuple):
                kind = int if key.endswith("_range") else float
                kwargs[key] = tuple(kind(v) for v in value)
                if len(kwargs[key]) != len(default):
                    raise ValueError(f"needs {len(default)} numbers")
            elif isinstance(default, bool | str):
                kwargs[key] = type(default)(value)
            else:
                kwargs[key] = type(default)(value)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{p}: bad value for {key!r}: {exc}") from None
    try:
        return Scenario(**{**{f.name: getattr(PAPER, f.name) for f in fields(Scenario)}, **kwargs})
    except ValueError as exc:
        raise ValueError(f"{p}: {exc}") from None


def _ints(value: Any, n: int) -> Any:
    out = tuple(int(v) for v in value)
    if len(out) != n:
        raise ValueError(f"expected {n} integers, got {value!r}")
    return out


def link_points(arm: Arm, q: npt.ArrayLike, base: npt.ArrayLike) -> FloatArray:
    """The polyline of the arm in the image (mm): base, every joint origin, the flange:
    ``(..., dof + 2, 3)``; consecutive points are the links."""
    qa = np.asarray(q, dtype=np.float64)
    frames = arm.link_frames(qa)
    flange = frames[..., -1, :, :] @ arm.flange
    b = np.asarray(base, dtype=np.float64)
    pts = np.concatenate(
        [np.broadcast_to(arm.base[:3, 3], (*qa.shape[:-1], 1, 3)), frames[..., :3, 3],
         flange[..., None, :3, 3]], axis=-2,
    )  # fmt: skip
    return np.asarray(pts + b)


def point_box_distance(p: FloatArray, lo: FloatArray, hi: FloatArray) -> FloatArray:
    """Euclidean distance from points to axis-aligned boxes (0 inside), broadcasting."""
    d = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    return np.asarray(np.sqrt(np.sum(d * d, axis=-1)))


def segment_box_distance(
    a: FloatArray, b: FloatArray, lo: FloatArray, hi: FloatArray
) -> FloatArray:
    """Exact distance from segments a→b to boxes (broadcasting over leading dimensions).

    Along the segment the squared distance is a convex piecewise quadratic whose pieces
    change where the point crosses a face plane; the minimum is at an end, a crossing, or the
    vertex of one piece (clipped to it), so those ≤ 15 points are evaluated.
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    a, b, lo, hi = np.broadcast_arrays(a, b, lo, hi)
    d = b - a
    # a zero or tiny component of d: no crossing, or one far beyond the segment (inf/overflow),
    # both dropped below
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        cross = np.concatenate([(lo - a) / d, (hi - a) / d], axis=-1)
    cross = np.where(np.isfinite(cross), np.clip(cross, 0.0, 1.0), 0.0)
    ends = np.broadcast_to(np.array([0.0, 1.0]), (*cross.shape[:-1], 2))
    ts = np.sort(np.concatenate([ends, cross], axis=-1), axis=-1)  # (..., 8)
    t0, t1 = ts[..., :-1], ts[..., 1:]
    mid = a[..., None, :] + ((t0 + t1) / 2.0)[..., None] * d[..., None, :]
    lo_, hi_ = lo[..., None, :], hi[..., None, :]
    below, above = mid < lo_, mid > hi_
    bound = np.where(below, lo_, np.where(above, hi_, 0.0))
    active = below | above
    dd = d[..., None, :]
    num = np.sum(np.where(active, dd * (a[..., None, :] - bound), 0.0), axis=-1)
    den = np.sum(np.where(active, dd * dd, 0.0), axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        vertex = np.where(den > 0.0, -num / den, t0)
    vertex = np.clip(vertex, t0, t1)
    cands = np.concatenate([ts, vertex], axis=-1)  # (..., 15)
    pts = a[..., None, :] + cands[..., None] * d[..., None, :]
    return np.asarray(point_box_distance(pts, lo_, hi_).min(axis=-1))


def projected_area(points: FloatArray, radius: float, flow: npt.ArrayLike) -> FloatArray:
    """Eq. 7: Σ_k 2 r h_k sin φ_k + π r² |cos φ_k| over the links (mm²), φ the angle of link k
    to the flow; zero-length links (coincident joint origins) add nothing."""
    u = np.asarray(flow, dtype=np.float64)
    u = u / np.linalg.norm(u)
    seg = np.diff(points, axis=-2)
    h = np.linalg.norm(seg, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.where(h > 1e-9, np.abs(seg @ u) / np.where(h > 1e-9, h, 1.0), 0.0)
    sin = np.sqrt(np.clip(1.0 - cos * cos, 0.0, 1.0))
    area = 2.0 * radius * h * sin + np.where(h > 1e-9, math.pi * radius**2 * cos, 0.0)
    return np.asarray(area.sum(axis=-1))


def clearances(
    points: FloatArray, radius: float, lo: FloatArray, hi: FloatArray, near: float = 100.0
) -> FloatArray:
    """Per link and domain, surface distance (mm): ``(..., links, domains)``; ≤ 0 is contact.

    Exact where a link's bounding box comes within ``radius + near`` of a domain; farther
    links get the (smaller, still positive) distance between the two boxes, which is all a
    collision test or a closeness sum needs and saves the exact search for most pairs.
    """
    if len(lo) == 0:
        return np.full((*points.shape[:-2], points.shape[-2] - 1, 0), np.inf)
    a, b = points[..., :-1, None, :], points[..., 1:, None, :]
    gap_v = np.maximum(np.maximum(lo - np.maximum(a, b), np.minimum(a, b) - hi), 0.0)
    gap = np.sqrt(np.sum(gap_v * gap_v, axis=-1))
    a, b = np.broadcast_arrays(a, b)
    a = np.broadcast_to(a, (*gap.shape, 3))
    b = np.broadcast_to(b, (*gap.shape, 3))
    close = gap < radius + near
    out = gap.copy()
    if close.any():
        box_lo = np.broadcast_to(lo, (*gap.shape, 3))[close]
        box_hi = np.broadcast_to(hi, (*gap.shape, 3))[close]
        out[close] = segment_box_distance(a[close], b[close], box_lo, box_hi)
    return np.asarray(out - radius)
