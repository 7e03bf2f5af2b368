"""Synthetic "photo of a line on a table" for the line-following case study.

The thesis drew a random curvy line on a table and photographed it from the robot (Figure
4.12b). :func:`generate_line_image` makes the same kind of picture, deterministically from a
seed: a smooth curve (Catmull-Rom spline through random control points that advance across the
image, so the curve never crosses itself) drawn with a round marker of a given thickness on a
slightly textured table, anti-aliased so that the centreline is defined to sub-pixel accuracy.
The true centreline is returned (and saved as CSV next to the PNG) so tests and the demo can
measure how well the line was *detected*, separately from how well it was *followed*.

Only numpy and matplotlib (for the PNG) are needed.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

__all__ = ["LineImage", "catmull_rom", "generate_line_image", "load_centreline"]

FloatArray = npt.NDArray[np.float64]


@dataclass
class LineImage:
    """A generated image: grey levels in [0, 1] (H, W), the true centreline in pixels (N, 2)
    as (x = column, y = row), and the files written (``None`` when not saved)."""

    image: FloatArray
    centreline: FloatArray
    thickness: float
    path: Path | None = None
    centreline_path: Path | None = None


def catmull_rom(points: npt.ArrayLike, samples_per_segment: int = 50) -> FloatArray:
    """A uniform Catmull-Rom spline through ``points`` (M, 2) → (K, 2).

    Uniform Catmull-Rom passes through every control point with a continuous tangent, which
    is all a hand-drawn-looking line needs; the end points are duplicated so the curve starts
    and ends on the first and last control points.
    """
    p = np.asarray(points, dtype=np.float64)
    if len(p) < 2:
        raise ValueError("a spline needs at least two points")
    ext = np.vstack([p[0], p, p[-1]])
    t = np.linspace(0.0, 1.0, samples_per_segment, endpoint=False)[:, None]
    t2, t3 = t * t, t * t * t
    out = []
    for i in range(1, len(ext) - 2):
        p0, p1, p2, p3 = ext[i - 1], ext[i], ext[i + 1], ext[i + 2]
        out.append(
            0.5
            * (
                2 * p1
                + (-p0 + p2) * t
                + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t2
                + (-p0 + 3 * p1 - 3 * p2 + p3) * t3
            )
        )
    out.append(p[-1:])
    return np.vstack(out)


def _resample(poly: FloatArray, step: float) -> FloatArray:
    """Points every ``step`` along a polyline (arc length), both ends included."""
    seg = np.hypot(*np.diff(poly, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(2, int(np.ceil(s[-1] / step)) + 1)
    si = np.linspace(0.0, s[-1], n)
    return np.column_stack([np.interp(si, s, poly[:, 0]), np.interp(si, s, poly[:, 1])])


def generate_line_image(
    path: str | Path | None = None,
    *,
    width: int = 640,
    height: int = 480,
    thickness: float = 12.0,
    n_points: int = 6,
    margin: int = 50,
    wiggle: float = 0.35,
    seed: int = 0,
) -> LineImage:
    """Draw a random smooth line and optionally save it as PNG (+ ``<stem>_centreline.csv``
    and ``<stem>.json`` with the parameters).

    ``n_points`` control points advance left to right with random heights (``wiggle`` is the
    fraction of the usable height the curve may swing) and a random horizontal jitter; half of
    the lines are stored right to left. The same arguments always give the same image.
    """
    rng = np.random.default_rng(seed)
    w, h = width, height
    xs = np.linspace(margin, w - margin, n_points)
    xs[1:-1] += rng.uniform(-0.25, 0.25, n_points - 2) * (w - 2 * margin) / (n_points - 1)
    mid = h / 2
    ys = mid + rng.uniform(-1.0, 1.0, n_points) * wiggle * (h - 2 * margin)
    ys = np.clip(ys, margin, h - margin)
    centre = catmull_rom(np.column_stack([xs, ys]), samples_per_segment=80)
    centre = np.clip(centre, [margin / 2, margin / 2], [w - margin / 2, h - margin / 2])
    if rng.integers(2):  # draw it right-to-left half of the time: direction must not matter
        centre = centre[::-1]

    # Table: light grey with a soft gradient and a little noise, like a photo.
    yy, xx = np.mgrid[0:h, 0:w]
    table = 0.82 + 0.06 * (xx / w) - 0.04 * (yy / h) + rng.normal(0.0, 0.015, (h, w))

    # Exact distance to the centreline near it: min over dense samples, window by window
    # (each sample only touches the pixels its marker tip can reach).
    radius = thickness / 2
    dist = np.full((h, w), np.inf)
    reach = int(np.ceil(radius + 2))
    for cx, cy in _resample(centre, 0.25):
        x0, x1 = max(int(cx) - reach, 0), min(int(cx) + reach + 1, w)
        y0, y1 = max(int(cy) - reach, 0), min(int(cy) + reach + 1, h)
        d = np.hypot(xx[y0:y1, x0:x1] - cx, yy[y0:y1, x0:x1] - cy)
        np.minimum(dist[y0:y1, x0:x1], d, out=dist[y0:y1, x0:x1])
    # Anti-aliased coverage: 1 inside, 0 outside, linear over one pixel at the edge.
    ink = np.clip(radius + 0.5 - dist, 0.0, 1.0)
    image = np.clip(table * (1 - ink) + 0.12 * ink, 0.0, 1.0)

    result = LineImage(image=image, centreline=centre, thickness=thickness)
    if path is not None:
        result.path, result.centreline_path = _save(
            Path(path), image, centre, thickness, seed, width, height
        )
    return result


def _save(
    path: Path,
    image: FloatArray,
    centre: FloatArray,
    thickness: float,
    seed: int,
    width: int,
    height: int,
) -> tuple[Path, Path]:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.image as mpimg

    path.parent.mkdir(parents=True, exist_ok=True)
    mpimg.imsave(path, image, cmap="gray", vmin=0.0, vmax=1.0)
    gt = path.with_name(path.stem + "_centreline.csv")
    with gt.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(["x_px", "y_px"])
        writer.writerows((f"{x:.4f}", f"{y:.4f}") for x, y in centre)
    meta = {"seed": seed, "width": width, "height": height, "thickness_px": thickness}
    path.with_suffix(".json").write_text(json.dumps(meta, indent=2), encoding="utf-8")
    return path, gt


def load_centreline(path: str | Path) -> FloatArray:
    """Read a ``*_centreline.csv`` written by :func:`generate_line_image` → (N, 2) pixels."""
    with Path(path).open(encoding="utf-8") as fh:
        rows = list(csv.reader(fh))[1:]
    return np.array([[float(x), float(y)] for x, y in rows], dtype=np.float64)
