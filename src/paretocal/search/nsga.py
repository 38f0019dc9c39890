"""NSGA-II with the paper's operators, run generation by generation.

One engine: :class:`~paretocal.search.engine.ArrayNSGA2` (pymoo's operators, sorting and crowding on
plain arrays). pymoo's own algorithm object runs the same NSGA-II about three times slower per
generation; it is kept in ``benchmarks/pymoo_nsga.py``, where the speed benchmark and a test
compare the two.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting

from ..config import SearchSettings
from ..objective.objective import PopulationObjective
from ..errors import STOP
from .checkpoint import Checkpoint, SearchInterrupted
from .engine import ArrayNSGA2
from .problem import bounds, place_seeds, round_n

log = logging.getLogger(__name__)


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


class TimedObjective:
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
    """Indices of the non-dominated rows of F (k, 2), both objectives minimised.

    Parameters
    ----------
    F : ndarray, shape (k, 2)
        Objectives ``[f1, f2]``.

    Returns
    -------
    ndarray of int64, shape (m,)
    """
    return np.asarray(NonDominatedSorting().do(F, only_non_dominated_front=True), dtype=np.int64)


def front_of(X: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Non-dominated, de-duplicated rows of (X, F), sorted by cost then f1.

    Parameters
    ----------
    X : ndarray, shape (k, 7)
        Solutions ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
    F : ndarray, shape (k, 2)
        Their objectives ``[f1, f2]``.

    Returns
    -------
    X, F : ndarray, shapes (m, 7) and (m, 2)
    """
    nd = front_indices(F)
    Xf, Ff = X[nd], F[nd]
    _, uniq = np.unique(np.round(Ff, 12), axis=0, return_index=True)
    Xf, Ff = Xf[uniq], Ff[uniq]
    order = np.lexsort((Ff[:, 0], Ff[:, 1]))
    return Xf[order], Ff[order]


def run_nsga2(objective: PopulationObjective, settings: SearchSettings, n_min: int, n_max: int,
              progress=None, seeds: np.ndarray | None = None,
              checkpoint: Checkpoint | None = None) -> SearchResult:
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
    checkpoint : Checkpoint, optional
        Save the state every ``checkpoint.every`` generations and resume from it when it
        exists. On KeyboardInterrupt (SIGINT, or SIGTERM turned
        into one) the state of the last completed generation is saved and
        :class:`SearchInterrupted` is raised with its non-dominated set.
    """
    timed = TimedObjective(objective)
    xl, xu = bounds(settings, n_min, n_max)
    history = []

    def record(gen, F):
        best = float(F[:, 0].min())
        history.append({"gen": gen, "best_f1": best, "evaluations": timed.evaluations})
        if progress is not None:
            progress(gen, settings.gens, best)

    t0 = time.perf_counter()
    engine = ArrayNSGA2(timed.evaluate, xl, xu, settings.pop, lambda X: round_n(X, xl, xu),
                       settings.sbx_prob, settings.sbx_eta, settings.pm_eta)
    saved = (checkpoint.load(settings.pop, settings.gens, xl, xu) if checkpoint is not None
             else None)
    if saved is not None:
        state, history[:] = saved
        timed.evaluations = state.evaluations
        log.info("resuming the search at generation %d", state.generation)
    else:
        state = engine.start(initial_population(settings, xl, xu, seeds), settings.seed)
        record(1, state.F)
    try:
        while state.generation < settings.gens:
            # step() leaves its argument untouched, so an interrupt inside it leaves the last
            # whole generation in `state` to save.
            STOP.check()
            state = engine.step(state)
            record(state.generation, state.F)
            if checkpoint is not None and state.generation % checkpoint.every == 0:
                checkpoint.save(state, history)
    except KeyboardInterrupt:
        STOP.clear()                              # taken
        if checkpoint is not None:
            checkpoint.save(state, history)
        Xf, Ff = front_of(state.X, state.F)
        raise SearchInterrupted(Xf, Ff, state.generation,
                                checkpoint.path if checkpoint is not None else None) from None
    if checkpoint is not None:
        checkpoint.save(state, history)     # a resume after this point skips the search
    popX, popF, gen = state.X, state.F, state.generation
    wall = time.perf_counter() - t0
    Xf, Ff = front_of(popX, popF)
    return SearchResult(X=Xf, F=Ff, pop_X=popX, pop_F=popF, evaluations=timed.evaluations,
                        generations=gen, wall_s=wall,
                        objective_s=timed.seconds, history=history)


def initial_population(settings: SearchSettings, xl: np.ndarray, xu: np.ndarray,
                       seeds: np.ndarray | None = None) -> np.ndarray:
    """The first generation (pop, 7): uniform in the box from ``settings.seed`` (the paper's
    sampling), plus the zero correction and ``seeds`` (k, 6) when ``settings.include_init``.

    Parameters
    ----------
    settings : SearchSettings
        ``pop``, ``seed`` and ``include_init``.
    xl, xu : ndarray, shape (7,)
        The box's lower and upper bounds (m, deg, points per frame; :func:`bounds`).
    seeds : ndarray, shape (k, 6), optional
        Corrections (m, deg) placed in the population.

    Returns
    -------
    ndarray, shape (pop, 7)
    """
    rng = np.random.default_rng(settings.seed)
    X0 = rng.uniform(xl, xu, (settings.pop, len(xl)))
    if settings.include_init:
        X0 = place_seeds(X0, xl, xu, np.vstack([np.zeros((1, 6))] + (
            [seeds] if seeds is not None and len(seeds) else [])))
    return X0
