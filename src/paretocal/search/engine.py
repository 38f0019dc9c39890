"""NSGA-II generations on plain arrays, with pymoo's operators and sorting.

pymoo's ``NSGA2`` keeps every individual as a Python object; at population 1000 moving values in
and out of those objects costs 38-51 ms per generation, more than evaluating the whole population
on one frame (benchmarks/speed.py). This driver runs the same generation on arrays and calls
pymoo for everything that is NSGA-II: the binary tournament rule (domination, then crowding
distance), ``SBX`` and ``PM`` (their array kernels, with the same mating probability), the
Pareto ranking (moocore's, as pymoo's ``NonDominatedSorting``; its fronts are taken here in one
stable sort instead of one scan of the ranks per front) and the randomised split of the last
front. The crowding distance is pymoo's, computed for every front in one compiled call
(:func:`crowding_distances`): pymoo's per-front call cost 50 us, and a population spread over
n has some 200 fronts (3 of the 5 s of a paper-scale search on one frame).

The whole state is a few arrays and a numpy Generator, so a run can be checkpointed and resumed
exactly (:mod:`paretocal.search.checkpoint` stores it as arrays and JSON).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from moocore import pareto_rank
from numba import njit
from pymoo.operators.crossover.sbx import SBX
from pymoo.operators.mutation.pm import PM
from pymoo.util.randomized_argsort import randomized_argsort


@njit(cache=True)
def _front_crowding(G: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """pymoo's ``calc_crowding_distance`` of the points G (n, M), operation for operation."""
    n, M = G.shape
    total = np.zeros(n)
    for m in range(M):
        col = G[:, m].copy()
        order = np.argsort(col, kind="mergesort")
        Fs = col[order]
        norm = Fs.max() - Fs.min()
        for p in range(n):
            last = Fs[p] - (Fs[p - 1] if p > 0 else -np.inf)
            nxt = (Fs[p + 1] if p < n - 1 else np.inf) - Fs[p]
            if norm == 0.0:                  # pymoo divides by NaN, then sets NaN to 0
                last = 0.0
                nxt = 0.0
            else:
                last = last / norm
                nxt = nxt / norm
            total[order[p]] += last + nxt
    return total / M


@njit(cache=True)
def crowding_distances(F: np.ndarray, idx: np.ndarray,
                       starts: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """pymoo's crowding distance (``get_crowding_function("cd")``: duplicates not filtered)
    of each front at once.

    Front k is ``F[idx[starts[k]:starts[k + 1]]]``; returns the distances (len(idx),) in the
    order of ``idx``; as pymoo, a front of at most two points gets inf.
    """
    out = np.empty(len(idx))
    M = F.shape[1]
    for k in range(len(starts) - 1):
        a, b = starts[k], starts[k + 1]
        if b - a <= 2:
            out[a:b] = np.inf
            continue
        G = np.empty((b - a, M))
        for i in range(b - a):
            G[i] = F[idx[a + i]]
        out[a:b] = _front_crowding(G)
    return out


def tournament_winners(F: np.ndarray, crowding: np.ndarray, a: np.ndarray, b: np.ndarray,
                       coin: np.ndarray) -> np.ndarray:
    """NSGA-II's binary tournament between individuals ``a`` and ``b`` (index arrays, (n,)).

    pymoo's ``comp_by_dom_and_crowding`` rule for unconstrained problems, vectorised: the
    dominating individual wins; otherwise the larger crowding distance; otherwise ``coin``
    ((n,) bool, True: ``a``). ``F`` (P, 2) objectives, ``crowding`` (P,). Returns (n,) indices.
    """
    Fa, Fb = F[a], F[b]
    a_dom = np.all(Fa <= Fb, axis=1) & np.any(Fa < Fb, axis=1)
    b_dom = np.all(Fb <= Fa, axis=1) & np.any(Fb < Fa, axis=1)
    ca, cb = crowding[a], crowding[b]
    by_cd = np.where(ca > cb, a, np.where(cb > ca, b, np.where(coin, a, b)))
    return np.where(a_dom, a, np.where(b_dom, b, by_cd))


@dataclass
class EngineState:
    """Everything a run needs to continue: population, objectives, ranks, crowding, RNG."""

    X: np.ndarray
    F: np.ndarray
    rank: np.ndarray
    crowding: np.ndarray
    rng: np.random.Generator
    generation: int
    evaluations: int


class ArrayNSGA2:
    """NSGA-II over a box, one generation per :meth:`step`.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(X) -> F`` for X of shape (C, n_var), F of shape (C, 2).
    xl, xu : ndarray, shape (n_var,)
        Bounds.
    pop_size : int
    repair : callable
        ``repair(X) -> X`` applied to every new population (rounds ``n``).
    sbx_prob, sbx_eta, pm_eta : float
        The paper's operator settings.
    """

    def __init__(self, evaluate, xl, xu, pop_size: int, repair, sbx_prob: float = 0.9,
                 sbx_eta: float = 15.0, pm_eta: float = 20.0):
        self.evaluate = evaluate
        self.problem = SimpleNamespace(xl=np.asarray(xl, float), xu=np.asarray(xu, float),
                                       n_var=len(xl))
        self.pop_size = int(pop_size)
        self.repair = repair
        self.sbx = SBX(prob=sbx_prob, eta=sbx_eta)
        self.sbx_prob = float(sbx_prob)
        self.pm = PM(eta=pm_eta, at_least_once=True)

    def start(self, X0: np.ndarray, seed: int) -> EngineState:
        """Evaluate the initial population (pop_size, n_var) and rank it."""
        rng = np.random.default_rng(seed)
        X = self.repair(np.array(X0, dtype=np.float64))
        F = np.asarray(self.evaluate(X), dtype=np.float64)
        rank, cd, keep = self._survive(F, len(F), rng)
        return EngineState(X[keep], F[keep], rank, cd, rng, 1, len(X))

    def step(self, s: EngineState) -> EngineState:
        """One generation: tournament, SBX, PM, repair, evaluation, rank-and-crowding survival.

        ``s`` is left untouched (its Generator included), so an interrupt inside a step
        leaves the last whole generation intact for a checkpoint.
        """
        rng = copy.deepcopy(s.rng)
        n_mat = math.ceil(self.pop_size / 2)
        parents = self._tournament(s, n_mat * 2, rng).reshape(n_mat, 2)
        Xpar = np.swapaxes(s.X[parents], 0, 1)                 # (2, n_matings, n_var)
        cross = rng.random(n_mat) < self.sbx_prob
        Q = Xpar.copy()
        if cross.any():
            Qc = self.sbx._do(self.problem, Xpar, random_state=rng)
            Q[:, cross] = Qc[:, cross]
        off = Q.reshape(-1, self.problem.n_var)[: self.pop_size]
        off = self.pm._do(self.problem, off, random_state=rng)
        off = self.repair(np.clip(off, self.problem.xl, self.problem.xu))
        Foff = np.asarray(self.evaluate(off), dtype=np.float64)
        X = np.vstack([s.X, off])
        F = np.vstack([s.F, Foff])
        rank, cd, keep = self._survive(F, self.pop_size, rng)
        return EngineState(X[keep], F[keep], rank, cd, rng, s.generation + 1,
                         s.evaluations + len(off))

    def _tournament(self, s: EngineState, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` winners of binary tournaments between random permutations of the population."""
        m = len(s.X)
        perms = np.concatenate([rng.permutation(m) for _ in range(math.ceil(2 * n / m))])
        a, b = perms[: 2 * n].reshape(n, 2).T
        return tournament_winners(s.F, s.crowding, a, b, rng.random(n) < 0.5)

    def _survive(self, F: np.ndarray, n_survive: int, rng: np.random.Generator):
        """pymoo's rank-and-crowding survival on arrays: returns (rank, crowding, kept idx)."""
        ranks = pareto_rank(np.asarray(F, dtype=np.float64))
        # pymoo's fronts: each front's indices in increasing order, fronts by rank.
        order = np.argsort(ranks, kind="stable")
        sizes = np.bincount(ranks)
        # The fronts that fill the population: all before the first that reaches n_survive.
        last = int(np.searchsorted(np.cumsum(sizes), n_survive))
        sizes = sizes[:last + 1]
        starts = np.concatenate([[0], np.cumsum(sizes)])
        idx = order[:starts[-1]].astype(np.int64)
        cd = crowding_distances(F, idx, starts)
        rank = np.repeat(np.arange(len(sizes)), sizes)
        n_remove = int(starts[-1]) - n_survive
        if n_remove > 0:
            a = int(starts[-2])
            order = randomized_argsort(cd[a:], order="descending", method="numpy",
                                       random_state=rng)[:-n_remove]
            idx = np.concatenate([idx[:a], idx[a:][order]])
            cd = np.concatenate([cd[:a], cd[a:][order]])
            rank = rank[:n_survive]
        return rank, cd, idx
