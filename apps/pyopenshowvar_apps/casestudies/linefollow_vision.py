"""Line detection for the line-following case study, on scikit-image and scipy.ndimage.

The thesis photographs a line drawn on a table, lets the operator pick its two ends and finds a
traversable path between them inside the line with A* (§4.2.2.2, case study 2). Each step is
the field's library routine:

* :func:`load_gray` — ``skimage.io`` (PNG, JPG, …) to grey levels in [0, 1];
* :func:`segment` — Otsu's threshold (``skimage.filters.threshold_otsu``) and the largest
  8-connected dark region (``skimage.measure.label``): the line;
* :func:`distance_map` — the exact Euclidean distance of each line pixel to the background
  (``scipy.ndimage.distance_transform_edt``);
* :func:`find_tips` — the two ends of the region by a geodesic double sweep
  (``skimage.graph.MCP_Geometric``: the region pixel farthest from anywhere, then the one
  farthest from that);
* :func:`trace` — the minimum-cost 8-connected path between two pixels through a cost that
  grows away from the ridge (``skimage.graph.route_through_array``, Dijkstra's algorithm: the
  same optimum as the thesis' A*, whose heuristic only changes the search order);
* :func:`centreline` — the ridge path smoothed to sub-pixel (``scipy.ndimage.uniform_filter1d``)
  and trimmed at both ends by the line's half width: a marker of radius r leaves a round cap
  that reaches r beyond the end of the stroke's centre, so the tips are not the ends.

:class:`Detection` holds what the steps found for one image; :func:`resample` and
:func:`polyline_distance` are the geometry the case study measures with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage

__all__ = [
    "Detection",
    "NoPathError",
    "centreline",
    "distance_map",
    "find_tips",
    "load_gray",
    "polyline_distance",
    "resample",
    "segment",
    "snap_to_region",
    "trace",
]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
Pixel = tuple[int, int]  # (row, col)


@dataclass
class Detection:
    """The detected line: region, ridge pixels, centreline (px, sub-pixel) and its ends."""

    gray: np.ndarray
    mask: np.ndarray
    pixels: list[tuple[int, int]]
    path_px: np.ndarray
    start: tuple[int, int]
    end: tuple[int, int]


class NoPathError(ValueError):
    """No traversable path joins the two points inside the line region."""


def load_gray(path: str) -> FloatArray:
    """An image file as grey levels in [0, 1], shape (H, W) (alpha ignored)."""
    from skimage import io
    from skimage.color import rgb2gray
    from skimage.util import img_as_float

    img = io.imread(path)
    if img.ndim == 3:
        img = rgb2gray(img[..., :3])
    return np.asarray(img_as_float(img), dtype=np.float64)


def _largest(mask: BoolArray) -> BoolArray:
    from skimage.measure import label

    labels = label(mask, connectivity=2)
    if labels.max() == 0:
        return np.zeros_like(mask)
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    return np.asarray(labels == int(np.argmax(sizes)))


def segment(gray: FloatArray, threshold: float | None = None, dark: bool = True) -> BoolArray:
    """The line region: pixels darker (``dark``) than the threshold (Otsu when ``None``),
    reduced to the largest 8-connected component so specks and shadows are ignored."""
    from skimage.filters import threshold_otsu

    t = float(threshold_otsu(gray)) if threshold is None else threshold
    mask = _largest(gray < t if dark else gray > t)
    if not mask.any():
        raise NoPathError("no line found in the image (nothing below the threshold)")
    return mask


def distance_map(mask: BoolArray) -> FloatArray:
    """Euclidean distance (pixels) of every region pixel to the nearest background pixel."""
    return np.asarray(ndimage.distance_transform_edt(mask), dtype=np.float64)


def _farthest(region: BoolArray, seed: Pixel) -> Pixel:
    """The region pixel farthest from ``seed`` along paths inside the region."""
    from skimage.graph import MCP_Geometric

    costs = np.where(region, 1.0, np.inf)
    cum, _ = MCP_Geometric(costs, fully_connected=True).find_costs([seed])
    cum = np.where(np.isfinite(cum), cum, -1.0)
    r, c = np.unravel_index(int(np.argmax(cum)), cum.shape)
    return int(r), int(c)


def find_tips(mask: BoolArray) -> tuple[Pixel, Pixel]:
    """The two tips of the line (geodesically farthest apart): a double sweep."""
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        raise NoPathError("the line region is empty")
    a = _farthest(mask, (int(rows[0]), int(cols[0])))
    return a, _farthest(mask, a)


def snap_to_region(mask: BoolArray, point: Pixel) -> Pixel:
    """``point`` if it is on the line, else the nearest line pixel (a click just beside it)."""
    r, c = point
    h, w = mask.shape
    if 0 <= r < h and 0 <= c < w and mask[r, c]:
        return (r, c)
    rows, cols = np.nonzero(mask)
    i = int(np.argmin((rows - r) ** 2 + (cols - c) ** 2))
    return (int(rows[i]), int(cols[i]))


def trace(
    mask: BoolArray,
    start: Pixel,
    goal: Pixel,
    *,
    dist: FloatArray | None = None,
    centre_weight: float = 4.0,
) -> list[Pixel]:
    """The cheapest 8-connected path from ``start`` to ``goal`` inside ``mask``.

    Step cost = length × (1 + ``centre_weight`` × (1 − d/d_max)), d the distance to the
    background: a step on the ridge costs its length, one on the rim up to 1 + centre_weight
    times more, so the path runs along the middle of the line and only shortcuts where the
    line itself does. Raises :class:`NoPathError`.
    """
    from skimage.graph import route_through_array

    h, w = mask.shape
    for name, (r, c) in (("start", start), ("goal", goal)):
        if not (0 <= r < h and 0 <= c < w) or not mask[r, c]:
            raise NoPathError(f"{name} {(r, c)} is not inside the line region")
    d = distance_map(mask) if dist is None else dist
    dmax = max(float(d.max()), 1.0)
    costs = np.where(mask, 1.0 + centre_weight * (1.0 - np.minimum(d, dmax) / dmax), np.inf)
    try:
        path, cost = route_through_array(costs, start, goal, fully_connected=True, geometric=True)
    except ValueError:  # skimage: "no minimum-cost path was found"
        cost = math.inf
    if not math.isfinite(cost):
        raise NoPathError(f"no traversable path from {start} to {goal} inside the line region")
    return [(int(r), int(c)) for r, c in path]


def centreline(pixels: list[Pixel], dist: FloatArray, *, trim: bool = True) -> FloatArray:
    """The path as (x, y) = (col, row) floats: smoothed over about one line width (removes the
    8-connected staircase) and, with ``trim``, shortened at each end by the line's half width
    (the median distance-to-background along the path: the marker radius), so it ends where the
    stroke's centre ended rather than at the tip of its round cap."""
    xy = np.array([(c, r) for r, c in pixels], dtype=np.float64)
    # the EDT counts to the centre of the first background pixel: the edge is half a pixel in
    radius = float(np.median([dist[p] for p in pixels])) - 0.5
    window = max(3, round(2 * radius + 1) | 1)
    if len(xy) > window:
        # odd (point) reflection about each end keeps the ends and straight runs in place
        pad = window // 2
        ext = np.pad(xy, ((pad, pad), (0, 0)), mode="reflect", reflect_type="odd")
        xy = ndimage.uniform_filter1d(ext, size=window, axis=0)[pad:-pad]
    if not trim or len(xy) < 3:
        return xy
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    cut = min(radius, 0.25 * s[-1])
    keep = (s >= cut) & (s <= s[-1] - cut)
    ends = [np.interp(v, s, xy[:, k]) for v in (cut, s[-1] - cut) for k in range(2)]
    return np.vstack([ends[:2], xy[keep], ends[2:]])


def resample(poly: FloatArray, step: float) -> FloatArray:
    """Points evenly spaced by at most ``step`` along a polyline (arc length), ends included."""
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(2, math.ceil(s[-1] / step - 1e-9) + 1)
    si = np.linspace(0.0, s[-1], n)
    return np.column_stack([np.interp(si, s, poly[:, k]) for k in range(poly.shape[1])])


def polyline_distance(points: FloatArray, poly: FloatArray, chunk: int = 512) -> FloatArray:
    """Distance of each point (P, D) to the polyline (N, D): min over its segments."""
    a, b = poly[:-1], poly[1:]
    ab = b - a
    ab2 = np.maximum((ab * ab).sum(axis=1), 1e-18)
    out = np.empty(len(points))
    for i in range(0, len(points), chunk):
        p = points[i : i + chunk, None, :]
        t = np.clip(((p - a) * ab).sum(axis=2) / ab2, 0.0, 1.0)
        nearest = a + t[..., None] * ab
        out[i : i + chunk] = np.sqrt(((p - nearest) ** 2).sum(axis=2)).min(axis=1)
    return out
