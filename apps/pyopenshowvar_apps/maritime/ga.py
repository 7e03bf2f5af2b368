"""A binary-coded genetic algorithm with the operators of Ishibashi et al.'s two planners.

Both of their GAs code the genes in binary ("to widen the search scope"), reproduce by the
roulette method (GA_p) or by tournaments (GA_m), cross by two-point crossover and mutate
bits. Fitness is minimised. Everything runs on whole populations as numpy arrays: a
generation is a handful of array operations, so 200 individuals × 400 generations of a 7-DOF
arm's forward kinematics take about a second (general GA libraries such as DEAP or PyGAD
apply operators individual by individual in Python, about a hundred times the cost here).

Choices the paper leaves open, made here and documented in docs/maritime.md: the mutation
rate is the probability that an individual has one random bit flipped; the best individual
survives unchanged (elitism of one); roulette weights are ``max(F) − F`` (a smaller F, a
larger slice); tournaments are between two individuals.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["BinaryGA", "decode", "encode"]

Bits = npt.NDArray[np.bool_]
FloatArray = npt.NDArray[np.float64]


def decode(bits: Bits, lower: npt.ArrayLike, upper: npt.ArrayLike, nbits: int) -> FloatArray:
    """Genes of ``nbits`` bits each (most significant first) to values on [lower, upper]."""
    n_genes = bits.shape[-1] // nbits
    weights = 2.0 ** np.arange(nbits - 1, -1, -1)
    ints = bits.reshape(*bits.shape[:-1], n_genes, nbits) @ weights
    lo, hi = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    return np.asarray(lo + (hi - lo) * ints / (2.0**nbits - 1.0))


def encode(values: npt.ArrayLike, lower: npt.ArrayLike, upper: npt.ArrayLike, nbits: int) -> Bits:
    """The inverse of :func:`decode` (values rounded to the nearest code)."""
    v = np.asarray(values, dtype=np.float64)
    lo, hi = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    top = 2**nbits - 1
    ints = np.clip(np.rint((v - lo) / (hi - lo) * top), 0, top).astype(np.int64)
    shifts = np.arange(nbits - 1, -1, -1)
    bits = (ints[..., None] >> shifts) & 1
    return np.asarray(bits.reshape(*v.shape[:-1], -1).astype(bool))


@dataclass
class BinaryGA:
    """One population and its operators; ``fitness(bits) -> (N,)`` values to minimise."""

    fitness: Callable[[Bits], FloatArray]
    n_bits: int
    size: int
    crossover: float
    mutation: float
    selection: str = "roulette"  # or "tournament"
    rng: np.random.Generator | None = None
    seeds: Bits | None = None  # individuals placed in the first population

    def _random(self) -> Bits:
        assert self.rng is not None
        pop = self.rng.random((self.size, self.n_bits)) < 0.5
        if self.seeds is not None and len(self.seeds):
            k = min(len(self.seeds), self.size)
            pop[:k] = self.seeds[:k]
        return pop

    def __post_init__(self) -> None:
        if self.size < 2 or self.n_bits < 2:
            raise ValueError("a GA needs at least 2 individuals of at least 2 bits")
        if self.selection not in ("roulette", "tournament"):
            raise ValueError(f"unknown selection {self.selection!r}")
        self.rng = self.rng or np.random.default_rng()
        self.population: Bits = self._random()
        self.scores: FloatArray = self.fitness(self.population)

    def restart(self) -> None:
        """A new first population (GA_m's regeneration): random, plus the seeds."""
        self.population = self._random()
        self.scores = self.fitness(self.population)

    def _select(self) -> npt.NDArray[np.intp]:
        rng = self.rng
        assert rng is not None
        n = self.size
        f = np.where(np.isfinite(self.scores), self.scores, np.inf)
        if self.selection == "tournament":
            a, b = rng.integers(0, n, n), rng.integers(0, n, n)
            return np.where(f[a] <= f[b], a, b)
        finite = np.isfinite(f)
        worst = f[finite].max() if finite.any() else 0.0
        w = np.where(finite, worst - f, 0.0) + 1e-12
        return rng.choice(n, size=n, p=w / w.sum())

    def step(self) -> None:
        """One generation: reproduction, two-point crossover, mutation, elitism of one."""
        rng = self.rng
        assert rng is not None
        n, m = self.size, self.n_bits
        best = self.population[int(np.argmin(self.scores))].copy()
        kids = self.population[self._select()].copy()
        # two-point crossover of consecutive pairs
        pairs = n // 2
        cross = rng.random(pairs) < self.crossover
        cuts = np.sort(rng.integers(0, m + 1, (pairs, 2)), axis=1)
        idx = np.arange(m)
        seg = (idx >= cuts[:, :1]) & (idx < cuts[:, 1:]) & cross[:, None]
        a, b = kids[0 : 2 * pairs : 2].copy(), kids[1 : 2 * pairs : 2].copy()
        kids[0 : 2 * pairs : 2] = np.where(seg, b, a)
        kids[1 : 2 * pairs : 2] = np.where(seg, a, b)
        # mutation: an individual, with probability `mutation`, gets one random bit flipped
        mut = np.flatnonzero(rng.random(n) < self.mutation)
        kids[mut, rng.integers(0, m, len(mut))] ^= True
        kids[0] = best
        self.population = kids
        self.scores = self.fitness(kids)

    @property
    def best(self) -> tuple[Bits, float]:
        k = int(np.argmin(self.scores))
        return self.population[k], float(self.scores[k])
