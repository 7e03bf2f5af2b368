"""Line detection for the line-following case study: segmentation, endpoints, A*, sampling.

Pure numpy + heapq, so the case study runs wherever pyopenshowvar runs (no OpenCV, no scipy):

* :func:`load_gray` reads a PNG or JPG (matplotlib; JPG through Pillow, which matplotlib
  depends on) as grey levels in [0, 1];
* :func:`segment` thresholds it (Otsu) and keeps the largest dark connected region: the line;
* :func:`distance_map` gives each line pixel its distance to the background (an octagonal
  distance by alternate 4/8-neighbour erosions: within ~8 % of Euclidean, plenty to find the
  ridge);
* :func:`find_endpoints` picks the two line ends by a geodesic double sweep (farthest pixel
  from anywhere, then farthest from that), on the line's core so the ends are cap centres;
* :func:`astar` finds the cheapest 8-connected path inside the region, with a step cost that
  grows away from the centre, so the path runs along the ridge rather than cutting corners;
* :func:`smooth_path` and :func:`resample` turn the pixel staircase into a smooth polyline and
  sample it at the requested resolution.
"""

from __future__ import annotations

import heapq
import math
from collections import deque

import numpy as np
import numpy.typing as npt

__all__ = [
    "NoPathError",
    "astar",
    "distance_map",
    "find_endpoints",
    "load_gray",
    "otsu_threshold",
    "polyline_distance",
    "resample",
    "segment",
    "smooth_path",
    "snap_to_region",
]

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
Pixel = tuple[int, int]  # (row, col)

_SQRT2 = math.sqrt(2.0)
_STEPS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


class NoPathError(ValueError):
    """No traversable path joins the two points inside the line region."""


def load_gray(path: str) -> FloatArray:
    """An image file as grey levels in [0, 1], shape (H, W)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.image as mpimg

    img = np.asarray(mpimg.imread(path), dtype=np.float64)
    if img.max() > 1.0:  # JPG through Pillow comes as uint8
        img = img / 255.0
    if img.ndim == 3:
        img = img[..., :3] @ np.array([0.299, 0.587, 0.114])  # luma; alpha ignored
    return img


def otsu_threshold(gray: FloatArray, bins: int = 256) -> float:
    """Otsu's threshold: the grey level that best separates two classes (line / table)."""
    hist, edges = np.histogram(gray, bins=bins, range=(0.0, 1.0))
    p = hist.astype(np.float64) / max(hist.sum(), 1)
    centres = (edges[:-1] + edges[1:]) / 2
    w0 = np.cumsum(p)
    mu = np.cumsum(p * centres)
    with np.errstate(divide="ignore", invalid="ignore"):
        between = (mu[-1] * w0 - mu) ** 2 / (w0 * (1 - w0))
    between[~np.isfinite(between)] = 0.0
    return float(edges[int(np.argmax(between)) + 1])


def _components(mask: BoolArray) -> list[list[Pixel]]:
    """8-connected components of ``mask`` (BFS over the set pixels only)."""
    seen = np.zeros_like(mask)
    h, w = mask.shape
    comps: list[list[Pixel]] = []
    for r0, c0 in zip(*np.nonzero(mask), strict=True):
        if seen[r0, c0]:
            continue
        seen[r0, c0] = True
        comp, queue = [], deque([(int(r0), int(c0))])
        while queue:
            r, c = queue.popleft()
            comp.append((r, c))
            for dr, dc in _STEPS:
                rr, cc = r + dr, c + dc
                if 0 <= rr < h and 0 <= cc < w and mask[rr, cc] and not seen[rr, cc]:
                    seen[rr, cc] = True
                    queue.append((rr, cc))
        comps.append(comp)
    return comps


def segment(gray: FloatArray, threshold: float | None = None, dark: bool = True) -> BoolArray:
    """The line region: pixels darker (``dark``) than the threshold (Otsu when ``None``),
    reduced to the largest connected component so specks and shadows are ignored."""
    t = otsu_threshold(gray) if threshold is None else threshold
    raw = gray < t if dark else gray > t
    comps = _components(raw)
    if not comps:
        raise NoPathError("no line found in the image (nothing below the threshold)")
    mask = np.zeros_like(raw)
    rows, cols = zip(*max(comps, key=len), strict=True)
    mask[list(rows), list(cols)] = True
    return mask


def distance_map(mask: BoolArray) -> FloatArray:
    """Distance (pixels) of every region pixel to the background, 0 outside.

    Onion peeling: each erosion removes one layer; alternating the 4- and 8-neighbourhood
    approximates a Euclidean distance (octagonal metric) with a handful of numpy shifts.
    """
    dist = np.zeros(mask.shape, dtype=np.float64)
    cur = mask.copy()
    layer = 0
    while cur.any():
        layer += 1
        dist[cur] = layer
        p = np.pad(cur, 1)
        nxt = p[1:-1, 1:-1] & p[:-2, 1:-1] & p[2:, 1:-1] & p[1:-1, :-2] & p[1:-1, 2:]
        if layer % 2 == 0:
            nxt &= p[:-2, :-2] & p[:-2, 2:] & p[2:, :-2] & p[2:, 2:]
        cur = nxt
    return dist


def _geodesic_farthest(region: BoolArray, seed: Pixel) -> Pixel:
    """The region pixel farthest from ``seed`` along 8-connected paths inside the region."""
    h, w = region.shape
    seen = np.zeros_like(region)
    seen[seed] = True
    queue, last = deque([seed]), seed
    while queue:
        last = r, c = queue.popleft()
        for dr, dc in _STEPS:
            rr, cc = r + dr, c + dc
            if 0 <= rr < h and 0 <= cc < w and region[rr, cc] and not seen[rr, cc]:
                seen[rr, cc] = True
                queue.append((rr, cc))
    return last


def find_endpoints(mask: BoolArray, dist: FloatArray | None = None) -> tuple[Pixel, Pixel]:
    """The two ends of the line: geodesic double sweep on the line's core.

    The core (distance ≥ half the maximum) is a thinner copy of the line whose tips lie near
    the centres of the round end caps rather than on their rims, which is where a person would
    click as start and end. Falls back to the whole region if the core is fragmented.
    """
    d = distance_map(mask) if dist is None else dist
    core = d >= max(1.0, 0.5 * float(d.max()))
    comps = _components(core)
    region = core
    if not comps or len(max(comps, key=len)) < 0.5 * core.sum():
        region = mask
    else:
        region = np.zeros_like(core)
        rows, cols = zip(*max(comps, key=len), strict=True)
        region[list(rows), list(cols)] = True
    r0, c0 = (int(v[0]) for v in np.nonzero(region))
    a = _geodesic_farthest(region, (r0, c0))
    b = _geodesic_farthest(region, a)
    return a, b


def snap_to_region(mask: BoolArray, point: Pixel) -> Pixel:
    """``point`` if it is on the line, else the nearest line pixel (a click just beside it)."""
    r, c = point
    h, w = mask.shape
    if 0 <= r < h and 0 <= c < w and mask[r, c]:
        return (r, c)
    rows, cols = np.nonzero(mask)
    i = int(np.argmin((rows - r) ** 2 + (cols - c) ** 2))
    return (int(rows[i]), int(cols[i]))


def astar(
    mask: BoolArray,
    start: Pixel,
    goal: Pixel,
    *,
    dist: FloatArray | None = None,
    centre_weight: float = 4.0,
) -> list[Pixel]:
    """Cheapest 8-connected path from ``start`` to ``goal`` through ``mask`` pixels (A*).

    Step cost = step length x (1 + ``centre_weight`` x (1 - d/d_max)), d the distance to the
    background: a step on the ridge costs its length, a step on the rim up to
    1 + centre_weight times more, so the path stays central and only shortcuts where the
    line itself does. The heuristic (octile distance) never overestimates since every step
    costs at least its length, so A* returns an optimal path. Raises :class:`NoPathError`.
    """
    h, w = mask.shape
    for name, (r, c) in (("start", start), ("goal", goal)):
        if not (0 <= r < h and 0 <= c < w) or not mask[r, c]:
            raise NoPathError(f"{name} {(r, c)} is not inside the line region")
    d = distance_map(mask) if dist is None else dist
    dmax = max(float(d.max()), 1.0)
    penalty = 1.0 + centre_weight * (1.0 - np.minimum(d, dmax) / dmax)
    gr, gc = goal

    def heuristic(r: int, c: int) -> float:
        dr, dc = abs(r - gr), abs(c - gc)
        return (dr + dc) + (_SQRT2 - 2.0) * min(dr, dc)

    g = np.full(mask.shape, np.inf)
    parent: dict[Pixel, Pixel] = {}
    g[start] = 0.0
    heap: list[tuple[float, float, Pixel]] = [(heuristic(*start), 0.0, start)]
    closed = np.zeros_like(mask)
    while heap:
        _, cost, node = heapq.heappop(heap)
        if closed[node]:
            continue
        if node == goal:
            path = [node]
            while node in parent:
                node = parent[node]
                path.append(node)
            return path[::-1]
        closed[node] = True
        r, c = node
        for dr, dc in _STEPS:
            rr, cc = r + dr, c + dc
            if not (0 <= rr < h and 0 <= cc < w) or not mask[rr, cc] or closed[rr, cc]:
                continue
            step = _SQRT2 if dr and dc else 1.0
            # mean penalty of the two pixels: the cost of the step between them
            new = cost + step * 0.5 * (penalty[r, c] + penalty[rr, cc])
            if new < g[rr, cc]:
                g[rr, cc] = new
                parent[(rr, cc)] = node
                heapq.heappush(heap, (new + heuristic(rr, cc), new, (rr, cc)))
    raise NoPathError(f"no traversable path from {start} to {goal} inside the line region")


def smooth_path(pixels: list[Pixel], window: int = 9) -> FloatArray:
    """(x, y) = (col, row) floats: a centred moving average over ``window`` pixels.

    Removes the 8-connected staircase (up to 0.5 px) without moving the ends: near the ends
    the window shrinks symmetrically, so the first and last points stay where A* put them.
    """
    xy = np.array([(c, r) for r, c in pixels], dtype=np.float64)
    n, half = len(xy), max(window // 2, 0)
    out = np.empty_like(xy)
    for i in range(n):
        k = min(half, i, n - 1 - i)
        out[i] = xy[i - k : i + k + 1].mean(axis=0)
    return out


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
