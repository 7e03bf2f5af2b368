"""GA motion planning for an underwater manipulator (Ishibashi, Shimizu & Ito, §3–4, Fig. 8).

* **GA_p** (§3, eq. 1): on each X–Z plane between start and goal one cube is chosen by a
  binary GA (genes: the cube's X and Z, within ``max_step`` cubes of the current tip) minimising
  F_p = α₁ f₁/Σf₁ + α₂ f₂/Σf₂ + α₃ f₃/Σf₃, f₁ the distance to the goal, f₃ the distance from
  the current tip, f₂ the obstacle term. As printed f₂ is the distance to the domains, which
  a minimisation would seek out; it is used here as Σ 1/distance (closeness), which keeps the
  intent. A cube nearer a domain than the link radius cannot hold the tip and is excluded.
  The window matters: F_p is a weighted sum of two distances (to the goal, from the tip),
  whose minimum over a whole plane is always one of the two points, so unbounded GA_p
  either stays put or jumps to the goal's X, Z at once; a step of at most ``max_step`` cubes
  per plane (the arm's "movable range") gives the paper's route along the shortest way.
* **GA_m** (§4.1, eq. 2): a binary GA over the joint angles minimising the tip's distance
  to the cube; every individual within ``tolerance`` in any generation is a candidate; no
  candidate for 40 generations regenerates the population.
* **Secure posture** (§4.2, eqs. 3–8): a candidate whose links touch a domain at the posture
  or anywhere on the way there from the present posture (joint-space line, sampled every
  ``step_deg``) is excluded (Fig. 7, pattern iii); the rest are ranked by
  E = β₁ e₁/Σe₁ + β₂ e₂/Σe₂ + β₃ e₃/Σe₃ with e₁ the weighted posture change (eq. 4, w_k the
  number of links joint k moves), e₂ the obstacle closeness (Σ 1/clearance, as f₂) and e₃
  the projected area of the cylindrical links integrated over the change (eqs. 6–8).
  No safe candidate: GA_m runs again; still none: the plane's next-best GA_p cube.

:func:`plan` returns a :class:`Plan`; the drag term's effect is ``plan(..., drag=False)`` on
the same scenario, seed and GA_p path.
"""

from __future__ import annotations

import logging
import math
import time
import zlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from pyopenshowvar.arms import Arm

from .ga import BinaryGA, decode, encode
from .uw_scenario import Scenario, clearances, link_points, point_box_distance, projected_area

__all__ = ["Plan", "PlannedPoint", "PlanningError", "plan", "plan_path"]

log = logging.getLogger(__name__)
FloatArray = npt.NDArray[np.float64]
Cube = tuple[int, int, int]
EPS = 1e-3  # mm: closeness of a touching link stays finite


class PlanningError(RuntimeError):
    """No collision-free posture for any of a plane's cubes."""


@dataclass
class PlannedPoint:
    cube: Cube
    q: FloatArray  # deg
    tip: FloatArray  # mm, reached
    transition: FloatArray  # (S, dof) joint samples from the previous posture to q
    e1: float
    e2: float
    e3: float  # mm²: projected area integrated over the change (T normalised to 1)
    clearance: float  # mm, over the transition
    area: float  # mm², at the posture
    candidates: int
    rank: int  # 0: GA_p's best cube of the plane, 1: the second best, ...
    regenerations: int


@dataclass
class Plan:
    scenario: Scenario
    drag: bool
    points: list[PlannedPoint]
    seconds: float
    info: dict[str, Any] = field(default_factory=dict)

    def metrics(self) -> dict[str, float]:
        pts = self.points
        tips = np.array([p.tip for p in pts])
        path = pts[1:]  # the start posture's way from home is no part of the path
        return {
            "path_length_mm": float(np.sum(np.linalg.norm(np.diff(tips, axis=0), axis=1))),
            "straight_line_mm": float(np.linalg.norm(tips[-1] - tips[0])),
            "min_clearance_mm": float(min(p.clearance for p in pts)),
            "posture_change_deg": float(sum(p.e1 for p in path)),
            "drag_area_integral_m2": float(sum(p.e3 for p in path)) / 1e6,
            "mean_area_m2": float(np.mean([p.area for p in pts])) / 1e6,
            "max_tip_error_mm": float(max(np.linalg.norm(p.tip - self.scenario.mm(p.cube)) for p in pts)),
            "fallbacks": float(sum(p.rank > 0 for p in pts)),
            "regenerations": float(sum(p.regenerations for p in pts)),
            "planning_time_s": self.seconds,
        }  # fmt: skip


def _bits(n: int) -> int:
    return max(2, math.ceil(math.log2(n)))


def _domain_distance(sc: Scenario, cubes_mm: FloatArray) -> FloatArray:
    lo, hi = sc.boxes_mm()
    if len(lo) == 0:
        return np.full((*cubes_mm.shape[:-1], 0), np.inf)
    return point_box_distance(cubes_mm[..., None, :], lo, hi)


def _normalised(terms: list[FloatArray], weights: tuple[float, ...]) -> FloatArray:
    """Σ_i w_i t_i / Σ_k t_ik (a term summing to zero adds nothing)."""
    out = np.zeros_like(terms[0])
    for w, t in zip(weights, terms, strict=True):
        total = float(np.sum(t[np.isfinite(t)]))
        if w != 0.0 and total > 0.0:
            out = out + w * t / total
    return out


def plan_path(sc: Scenario, rng: np.random.Generator) -> list[list[Cube]]:
    """GA_p on every X–Z plane strictly between start and goal, each plane's feasible cubes
    best first; the current tip of a plane is the previous plane's best cube."""
    k = sc.max_step
    bx = bz = _bits(2 * k + 1)
    goal = sc.mm(sc.goal)
    step = -1 if sc.goal[1] < sc.start[1] else 1
    current = sc.mm(sc.start)
    cur = sc.start
    planes: list[list[Cube]] = []
    for y in range(sc.start[1] + step, sc.goal[1], step):
        # the plane's window: at most max_step cubes from the current tip in X and in Z
        x0, x1 = max(sc.x_range[0], cur[0] - k), min(sc.x_range[1], cur[0] + k)
        z0, z1 = max(sc.z_range[0], cur[2] - k), min(sc.z_range[1], cur[2] + k)

        # f1, f2, f3 and feasibility of every cube of the window, looked up per individual
        gx, gz = np.meshgrid(np.arange(x0, x1 + 1), np.arange(z0, z1 + 1), indexing="ij")
        window = np.stack([gx, np.full_like(gx, y), gz], axis=-1)
        c_mm = sc.mm(window)
        dist = _domain_distance(sc, c_mm)
        terms = (np.linalg.norm(c_mm - goal, axis=-1),
                 np.sum(1.0 / np.maximum(dist, EPS), axis=-1),
                 np.linalg.norm(c_mm - current, axis=-1))  # fmt: skip
        feasible = np.all(dist > sc.link_radius, axis=-1)

        def index(
            bits: npt.NDArray[np.bool_], w: tuple[int, int, int, int] = (x0, x1, z0, z1)
        ) -> Any:
            ix = np.rint(decode(bits[:, :bx], 0, w[1] - w[0], bx)[:, 0]).astype(np.int64)
            iz = np.rint(decode(bits[:, bx:], 0, w[3] - w[2], bz)[:, 0]).astype(np.int64)
            return ix, iz

        def fitness(
            bits: npt.NDArray[np.bool_],
            index: Any = index,
            terms: Any = terms,
            feasible: Any = feasible,
        ) -> FloatArray:  # eq. 1 over the population
            ix, iz = index(bits)
            ok = feasible[ix, iz]
            out = np.full(len(bits), np.inf)
            if ok.any():
                out[ok] = _normalised([t[ix, iz][ok] for t in terms], sc.alpha)
            return out

        ga = BinaryGA(fitness, bx + bz, sc.path_individuals, sc.path_crossover,
                      sc.path_mutation, "roulette", rng)  # fmt: skip
        for _ in range(sc.path_generations):
            ga.step()
        # every feasible cube of the window, ranked by eq. 1 with the final population's sums
        # (the population's best first: the "second smallest fitness" of the paper's fallback
        # exists even when the population has converged on one cube)
        ix, iz = index(ga.population)
        ok = feasible[ix, iz]
        sums = [float(np.sum(t[ix, iz][ok])) for t in terms]
        score = sum(
            (w * t / s_ if s_ > 0 else 0.0 * t)
            for w, t, s_ in zip(sc.alpha, terms, sums, strict=True)
        )
        score = np.where(feasible, score, np.inf)
        bi, bj = ix[int(np.argmin(ga.scores))], iz[int(np.argmin(ga.scores))]
        score[bi, bj] = -np.inf
        ranked = [(int(x0 + i), y, int(z0 + j))
                  for i, j in zip(*np.unravel_index(np.argsort(score, axis=None), score.shape), strict=True)
                  if np.isfinite(score[i, j]) or score[i, j] < 0]  # fmt: skip
        if not ranked:
            raise PlanningError(f"GA_p found no cube clear of the obstacles on plane Y = {y}")
        planes.append(ranked)
        cur = ranked[0]
        current = sc.mm(cur)
    return planes


def _candidates(
    sc: Scenario, arm: Arm, cube: Cube, attempt: int, present: FloatArray
) -> tuple[FloatArray, int]:
    """GA_m (eq. 2) for the cube: the candidate postures (deg) and the regenerations.

    Half the first population is random, as in the paper; the other half is the present
    posture with every joint moved by a normal draw of σ = ``seed_spread`` (the paper does
    not say how its population starts;
    seeded, the GA finds candidates near the present posture, which e₁ then prefers). The
    second attempt, the paper's regeneration, starts fully random: other arm configurations.
    """
    seed = zlib.crc32(repr((sc.seed, cube, attempt)).encode())
    rng = np.random.default_rng(seed)
    target = sc.mm(cube) - np.asarray(sc.base)
    nb = sc.bits_per_joint
    seeds = None
    if attempt == 0:  # the regeneration (attempt 1) starts from a fully random population
        near = present + rng.normal(0.0, sc.seed_spread, (sc.posture_individuals // 2, arm.dof))
        seeds = encode(np.clip(near, arm.lower, arm.upper), arm.lower, arm.upper, nb)

    def fitness(bits: npt.NDArray[np.bool_]) -> FloatArray:  # eq. 2
        q = decode(bits, arm.lower, arm.upper, nb)
        return np.asarray(np.linalg.norm(arm.fk(q)[:, :3, 3] - target, axis=-1))

    ga = BinaryGA(fitness, nb * arm.dof, sc.posture_individuals, sc.posture_crossover,
                  sc.posture_mutation, "tournament", rng, seeds)  # fmt: skip
    found: dict[bytes, FloatArray] = {}
    since, regenerations = 0, 0
    for _ in range(sc.posture_generations):
        hit = ga.scores <= sc.tolerance
        if hit.any():
            since = 0
            for q in decode(ga.population[hit], arm.lower, arm.upper, nb):
                found.setdefault(np.round(q, 2).tobytes(), q)
            if len(found) >= sc.max_candidates:
                break
        else:
            since += 1
            if since >= sc.regenerate_after:
                ga.restart()
                since, regenerations = 0, regenerations + 1
                continue
        ga.step()
    q_all = np.array(list(found.values())) if found else np.zeros((0, arm.dof))
    return q_all, regenerations


def _evaluate(
    sc: Scenario, arm: Arm, present: FloatArray, cands: FloatArray, drag: bool
) -> tuple[int, dict[str, Any]] | None:
    """The secure posture among ``cands`` (eq. 3) and its figures, or None if none is safe."""
    lo, hi = sc.boxes_mm()
    dq = cands - present
    n_s = int(min(90, max(2, math.ceil(float(np.abs(dq).max(initial=0.0)) / sc.step_deg) + 1)))
    s = np.linspace(0.0, 1.0, n_s)
    path = present + s[None, :, None] * dq[:, None, :]  # (n, S, dof)
    pts = link_points(arm, path, sc.base)
    clear = clearances(pts, sc.link_radius, lo, hi)  # (n, S, links, domains)
    worst = clear.reshape(len(cands), -1).min(axis=-1, initial=np.inf)
    safe = worst > 0.0
    if not safe.any():
        return None
    dof = arm.dof
    w = np.arange(dof, 0, -1, dtype=np.float64)  # joint k moves dof - k + 1 links
    e1 = np.sqrt(np.sum(w * dq**2, axis=-1))  # eq. 4 (deg)
    e2 = np.sum(1.0 / np.maximum(clear[:, -1], EPS), axis=(-2, -1))  # eq. 5, as closeness
    area = projected_area(pts, sc.link_radius, sc.flow)  # (n, S), eq. 7
    e3 = np.asarray(np.trapezoid(area, s, axis=-1))  # eq. 8 over the change, T normalised
    beta = sc.beta if drag else (sc.beta[0], sc.beta[1], 0.0)
    e = _normalised([e1[safe], e2[safe], e3[safe]], beta)
    k = int(np.flatnonzero(safe)[int(np.argmin(e))])
    return k, {"e1": float(e1[k]), "e2": float(e2[k]), "e3": float(e3[k]),
               "clearance": float(worst[k]), "area": float(area[k, -1]),
               "transition": path[k], "candidates": int(safe.sum())}  # fmt: skip


def _secure(
    sc: Scenario, arm: Arm, present: FloatArray, ranked: list[Cube], drag: bool,
    max_rank: int = 5,
) -> PlannedPoint:  # fmt: skip
    for rank, cube in enumerate(ranked[:max_rank]):
        regenerations = 0
        for attempt in range(2):  # GA_m, then GA_m again with new candidates
            cands, regen = _candidates(sc, arm, cube, attempt, present)
            regenerations += regen + attempt
            if len(cands) == 0:
                continue
            chosen = _evaluate(sc, arm, present, cands, drag)
            if chosen is None:
                continue
            k, fig = chosen
            tip = arm.fk(cands[k])[:3, 3] + np.asarray(sc.base)
            return PlannedPoint(cube, cands[k], tip, fig["transition"], fig["e1"], fig["e2"],
                                fig["e3"], fig["clearance"], fig["area"], fig["candidates"],
                                rank, regenerations)  # fmt: skip
        log.info("no secure posture at cube %s, trying the plane's next cube", cube)
    raise PlanningError(
        f"no collision-free posture reaches any of the best {min(max_rank, len(ranked))} cubes "
        f"of the plane Y = {ranked[0][1]}"
    )


def plan(sc: Scenario, *, drag: bool = True, planes: list[list[Cube]] | None = None) -> Plan:
    """Path (GA_p, unless ``planes`` are given) and secure postures (GA_m, eq. 3) from start
    to goal. Raises :class:`PlanningError` when a plane has no reachable safe cube."""
    started = time.perf_counter()
    arm = sc.load_arm()
    if planes is None:
        planes = plan_path(sc, np.random.default_rng(sc.seed))
    route = [[sc.start], *planes, [sc.goal]]
    present = arm.home_q.astype(np.float64)
    points: list[PlannedPoint] = []
    for ranked in route:
        point = _secure(sc, arm, present, ranked, drag)
        points.append(point)
        present = point.q
    return Plan(sc, drag, points, time.perf_counter() - started, {"arm": arm.name})
