"""NSGA-II with the paper's operators, run generation by generation."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from pymoo.algorithms.moo.nsga2 import NSGA2
from pymoo.operators.crossover.sbx import SBX
from pymoo.operators.mutation.pm import PM
from pymoo.operators.sampling.rnd import FloatRandomSampling
from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting

from ..config import SearchSettings
from .problem import CalibrationProblem, RoundN, SamplingWithInit, bounds


@dataclass
class SearchResult:
    """The final population and its non-dominated front.

    Attributes
    ----------
    X : ndarray, shape (P, 7)
        Non-dominated solutions ``[x, y, z, yaw, pitch, roll, n]``, sorted by ``n``.
    F : ndarray, shape (P, 2)
        Their objectives ``[f1, f2]``.
    pop_X, pop_F : ndarray
        The whole final population.
    evaluations : int
    generations : int
    wall_s : float
    objective_s : float
        Time spent inside the objective (the rest is optimiser overhead).
    history : list of dict
        Per generation: best f1, front size.
    """

    X: np.ndarray
    F: np.ndarray
    pop_X: np.ndarray
    pop_F: np.ndarray
    evaluations: int
    generations: int
    wall_s: float
    objective_s: float
    history: list = field(default_factory=list)


def make_algorithm(settings: SearchSettings, seeds: np.ndarray | None = None) -> NSGA2:
    """NSGA-II with SBX (p, eta), polynomial mutation (eta) and uniform sampling (plus the
    zero correction and ``seeds`` (k, 6) when ``settings.include_init``)."""
    sampling = SamplingWithInit(seeds) if settings.include_init else FloatRandomSampling()
    return NSGA2(pop_size=settings.pop, sampling=sampling,
                 crossover=SBX(prob=settings.sbx_prob, eta=settings.sbx_eta),
                 mutation=PM(eta=settings.pm_eta, at_least_once=True),
                 repair=RoundN(), eliminate_duplicates=settings.eliminate_duplicates)


class _TimedObjective:
    """Wraps an objective to measure the time spent evaluating."""

    def __init__(self, objective):
        self.objective = objective
        self.seconds = 0.0
        self.evaluations = 0

    def evaluate(self, X):
        t0 = time.perf_counter()
        F = self.objective.evaluate(X)
        self.seconds += time.perf_counter() - t0
        self.evaluations += len(X)
        return F


def front_indices(F: np.ndarray) -> np.ndarray:
    """Indices of the non-dominated rows of F (k, 2), both objectives minimised."""
    return np.asarray(NonDominatedSorting().do(F, only_non_dominated_front=True), dtype=np.int64)


def front_of(X: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Non-dominated, de-duplicated rows of (X, F), sorted by cost then f1."""
    nd = front_indices(F)
    Xf, Ff = X[nd], F[nd]
    _, uniq = np.unique(np.round(Ff, 12), axis=0, return_index=True)
    Xf, Ff = Xf[uniq], Ff[uniq]
    order = np.lexsort((Ff[:, 0], Ff[:, 1]))
    return Xf[order], Ff[order]


def run_nsga2(objective, settings: SearchSettings, n_min: int, n_max: int,
              progress=None, seeds: np.ndarray | None = None) -> SearchResult:
    """Run NSGA-II for ``settings.gens`` generations.

    Parameters
    ----------
    objective
        Has ``evaluate(X) -> F`` for X of shape (C, 7).
    settings : SearchSettings
    n_min, n_max : int
        Range of points per frame.
    progress : callable, optional
        Called as ``progress(generation, total, best_f1)`` after every generation.
    seeds : ndarray, shape (k, 6), optional
        Poses placed in the initial population.
    """
    timed = _TimedObjective(objective)
    xl, xu = bounds(settings, n_min, n_max)
    problem = CalibrationProblem(timed, xl, xu)
    algorithm = make_algorithm(settings, seeds)
    algorithm.setup(problem, termination=("n_gen", settings.gens), seed=settings.seed,
                    verbose=False, save_history=False)
    t0 = time.perf_counter()
    history = []
    gen = 0
    while algorithm.has_next():
        algorithm.next()
        gen += 1
        F = algorithm.pop.get("F")
        best = float(F[:, 0].min())
        history.append({"gen": gen, "best_f1": best, "evaluations": timed.evaluations})
        if progress is not None:
            progress(gen, settings.gens, best)
    wall = time.perf_counter() - t0
    popX, popF = algorithm.pop.get("X"), algorithm.pop.get("F")
    Xf, Ff = front_of(popX, popF)
    return SearchResult(X=Xf, F=Ff, pop_X=popX, pop_F=popF, evaluations=timed.evaluations,
                        generations=gen, wall_s=wall,
                        objective_s=timed.seconds, history=history)
