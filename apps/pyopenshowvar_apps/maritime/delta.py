"""Kinematics of the three-axis compensator (TAC): a Delta parallel robot as crane head.

Henriksen et al. §2–6, in their frame {t}: x_t is the TAC's axis (from the base plate to
the top plate), the three arms sit at 120° about it (eq. 1: R_{t_i}^t = R_x(5π/6), R_x(3π/2),
R_x(π/6)). Arm i turns by α_i; the indented knee point (eq. 4)

    c_i = R_{t_i}^t [l_a sin α_i, a − l_a cos α_i, 0]ᵀ,   a = l_p − l_k,

lies at the rod length l_r from the tool centre point p_c (eq. 6, three spheres). α_i = 0 is
the arm stretched outwards in the base plate, α_i > 0 lifts the knee towards +x. (Eq. 3 of
the paper prints the knee with sin and cos swapped; eqs. 4, 9, 12 and 28 all use the form
above, which is the one a closed chain knee → rod → plate gives.)

* :func:`ipk` (§3): the tangent half-angle solution of eq. 11–15 per arm, the knee pointing
  outwards (|α_i| < π/2); NaN where the point is out of reach.
* :func:`fpk` (§4): eqs. 18–25 (Coope's sphere intersection), the solution above the
  plane of the knees (x_c larger, "over the TAC base plate").
* :func:`jacobian` (§5): eq. 32, ṗ_c = J α̇.
* :func:`workspace` (§6): the grid of eq. 33–34 tested by the IPK and the joint range.

Everything is batched over leading dimensions (points ``(..., 3)``, angles ``(..., 3)``, in
metres and radians).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
import numpy.typing as npt

__all__ = ["TAC", "Workspace", "fpk", "ipk", "jacobian", "workspace"]

FloatArray = npt.NDArray[np.float64]

#: eq. 1: the arm frames {t_i} are {t} turned about x_t
ARM_ANGLES = (5 * math.pi / 6, 3 * math.pi / 2, math.pi / 6)


def _rx(angle: float) -> FloatArray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


#: R_{t_i}^t, shape (3 arms, 3, 3)
R_ARMS = np.stack([_rx(a) for a in ARM_ANGLES])


@dataclass(frozen=True)
class TAC:
    """The geometry and joint range of the crane head (Table 4 of the paper by default)."""

    l_k: float = 2.00  # centre of the base plate to the arm's joint (m)
    l_a: float = 3.25  # arm (m)
    l_r: float = 7.00  # rod (m)
    l_p: float = 1.25  # centre of the top plate to the rod (m)
    alpha_min: float = math.radians(-40.0)
    alpha_max: float = math.radians(70.0)

    @property
    def a(self) -> float:
        return self.l_p - self.l_k

    def knees(self, alpha: npt.ArrayLike) -> FloatArray:
        """Indented knee points c_i (eq. 4) in {t}: ``(..., 3 arms, 3)``."""
        al = np.asarray(alpha, dtype=np.float64)
        local = np.stack(
            [self.l_a * np.sin(al), self.a - self.l_a * np.cos(al), np.zeros_like(al)], axis=-1
        )
        return np.asarray(np.einsum("ijk,...ik->...ij", R_ARMS, local))

    def in_range(self, alpha: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """True where every angle is a real number inside [α_min, α_max]."""
        al = np.asarray(alpha, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            ok = (al >= self.alpha_min - 1e-12) & (al <= self.alpha_max + 1e-12)
        return np.asarray(np.all(ok, axis=-1))

    def reachable(self, p: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """True where the TCP position has an IPK solution inside the joint range."""
        return self.in_range(ipk(self, p))


def ipk(tac: TAC, p: npt.ArrayLike) -> FloatArray:
    """Joint angles α (rad) for TCP positions ``p`` (m) in {t}; NaN rows where unreachable.

    Per arm, eq. 11: e_i cos α + f_i sin α + g_i = 0 with (eq. 12, written in {t_i})
    e_i = 2 l_a (y_ci − a), f_i = −2 l_a x_c, g_i = ‖p‖² + l_a² + a² − l_r² − 2 a y_ci.
    The two roots of the half-angle quadratic (eq. 15) are α = φ ± acos(−g/√(e²+f²)),
    φ = atan2(f, e) (the same pair, without the division by g − e that fails at α = π);
    the knee-outwards root is the one with the larger cos α.
    """
    pa = np.asarray(p, dtype=np.float64)
    y_local = np.einsum("ij,...j->...i", R_ARMS[:, :, 1], pa)  # y_ci = (R_iᵀ p)_y per arm
    x = pa[..., :1]
    la, a = tac.l_a, tac.a
    e = 2.0 * la * (y_local - a)
    f = -2.0 * la * x
    g = np.sum(pa * pa, axis=-1, keepdims=True) + la * la + a * a - tac.l_r**2 - 2.0 * a * y_local
    rho = np.hypot(e, f)
    with np.errstate(invalid="ignore", divide="ignore"):
        spread = np.arccos(np.where(np.abs(g) <= rho, -g / rho, np.nan))
    phi = np.arctan2(f, e)
    roots = np.stack([phi + spread, phi - spread])
    roots = (roots + np.pi) % (2.0 * np.pi) - np.pi  # wrap to (−π, π]
    pick = np.cos(roots[0]) >= np.cos(roots[1])
    return np.asarray(np.where(pick, roots[0], roots[1]))


def fpk(tac: TAC, alpha: npt.ArrayLike) -> FloatArray:
    """TCP position (m) in {t} for joint angles ``alpha`` (rad); NaN where the rods cannot close.

    Eqs. 18–25: with r = ‖p‖², b_i = ‖c_i‖² − l_r², u = C⁻ᵀ1, v = C⁻ᵀb, p = (r u + v)/2 and
    (uᵀu) r² + (2uᵀv − 4) r + vᵀv = 0. The paper's origin o_t lies in the plane of the three
    knees whenever α_1 = α_2 = α_3 = 0, where C is singular; the same equations are solved
    here about an origin moved l_r off that plane, which changes nothing else.
    """
    c = tac.knees(alpha)  # (..., 3, 3): rows are c_i
    n = np.cross(c[..., 1, :] - c[..., 0, :], c[..., 2, :] - c[..., 0, :])
    n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    n = np.where(n[..., :1] < 0.0, -n, n)  # the normal pointing up the TAC's axis
    shift = c.mean(axis=-2) - tac.l_r * n  # an origin well off the knees' plane
    cs = c - shift[..., None, :]
    b = np.sum(cs * cs, axis=-1) - tac.l_r**2
    u = np.linalg.solve(cs, np.ones_like(b)[..., None])[..., 0]  # C⁻ᵀ1: cs rows are c_iᵀ
    v = np.linalg.solve(cs, b[..., None])[..., 0]
    qa = np.sum(u * u, axis=-1)
    qb = 2.0 * np.sum(u * v, axis=-1) - 4.0
    qc = np.sum(v * v, axis=-1)
    disc = qb * qb - 4.0 * qa * qc
    with np.errstate(invalid="ignore"):
        root = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
    sols = np.stack([(-qb + root) / (2 * qa), (-qb - root) / (2 * qa)])  # r, two of them
    pts = (sols[..., None] * u + v) / 2.0 + shift  # (2, ..., 3)
    # "the valid solution is the one over the TAC base plate": the larger x_c
    upper = pts[0][..., 0] >= pts[1][..., 0]
    return np.asarray(np.where(upper[..., None], pts[0], pts[1]))


def jacobian(tac: TAC, p: npt.ArrayLike, alpha: npt.ArrayLike) -> FloatArray:
    """J(p_c, α) of eq. 32 (ṗ_c = J α̇): ``(..., 3, 3)``, metres per radian.

    s_i = p_c − c_i, d_i = R_{t_i}^t [l_a cos α_i, l_a sin α_i, 0]ᵀ = ∂c_i/∂α_i;
    J = [s_1 s_2 s_3]ᵀ⁻¹ diag(s_i · d_i).
    """
    al = np.asarray(alpha, dtype=np.float64)
    s = np.asarray(p, dtype=np.float64)[..., None, :] - tac.knees(al)
    local = np.stack([tac.l_a * np.cos(al), tac.l_a * np.sin(al), np.zeros_like(al)], axis=-1)
    d = np.einsum("ijk,...ik->...ij", R_ARMS, local)
    diag = np.sum(s * d, axis=-1)
    return np.asarray(np.linalg.solve(s, diag[..., :, None] * np.eye(3)))


@dataclass(frozen=True)
class Workspace:
    """The reachable TCP positions on a grid of step ``h`` (eq. 33–34) and their convex hull."""

    tac: TAC
    h: float
    points: FloatArray  # (N, 3) reachable grid points

    @cached_property
    def hull(self) -> object:
        """scipy's ConvexHull of the reachable points (the paper's workspace limits)."""
        from scipy.spatial import ConvexHull

        return ConvexHull(self.points)

    @property
    def volume(self) -> float:
        return float(self.hull.volume)  # type: ignore[attr-defined]

    def inside_hull(self, p: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """True where ``p`` lies in the convex hull (the paper's run-time limit check)."""
        eq = self.hull.equations  # type: ignore[attr-defined]
        pa = np.asarray(p, dtype=np.float64)
        return np.asarray(np.all(pa @ eq[:, :3].T + eq[:, 3] <= 1e-9, axis=-1))

    @cached_property
    def axis_centre(self) -> tuple[float, float]:
        """x_d of §8: the point (x, 0, 0) farthest from the boundary, and that distance.

        The paper places the TCP's set-point "in the middle of the workspace" on the TAC's
        axis; here that is the on-axis point whose nearest unreachable grid point is farthest.
        """
        from scipy.spatial import cKDTree

        grid, ok = _grid(self.tac, self.h)
        tree = cKDTree(grid[~ok])
        xs = np.unique(self.points[:, 0])
        axis = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], axis=-1)
        axis = axis[self.tac.reachable(axis)]
        dist, _ = tree.query(axis)
        k = int(np.argmax(dist))
        return float(axis[k, 0]), float(dist[k])


def _grid(tac: TAC, h: float) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    lat = tac.l_r + tac.l_p - tac.l_k  # eq. 33
    xs = np.arange(0.0, tac.l_a + tac.l_r + h / 2, h)
    ys = np.arange(-lat, lat + h / 2, h)
    grid = np.stack(np.meshgrid(xs, ys, ys, indexing="ij"), axis=-1).reshape(-1, 3)
    return grid, tac.reachable(grid)


@lru_cache(maxsize=8)
def workspace(tac: TAC, h: float = 0.2) -> Workspace:
    """The workspace of §6: grid points of eq. 33–34 with a real IPK inside the joint range
    (cached per geometry and step: it is computed once, "as an initializing process")."""
    if not h > 0:
        raise ValueError(f"grid step must be positive, got {h}")
    grid, ok = _grid(tac, h)
    return Workspace(tac, h, grid[ok])
