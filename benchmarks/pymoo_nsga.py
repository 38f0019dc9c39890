"""pymoo's own NSGA-II algorithm object on the calibration problem, for comparison.

The package runs one NSGA-II engine, :class:`paretocal.search.engine.ArrayNSGA2`: pymoo's operators,
sorting and crowding on plain arrays. This module keeps the algorithm-object version it was
checked against (``benchmarks/speed.py`` times both; ``tests/test_search.py`` checks that they
reach the same front): pymoo's ``NSGA2`` with the paper's operators, the binary tournament
vectorised with the package's rule, and the optimum not recomputed after every generation.
"""

from __future__ import annotations

import time

import numpy as np
from pymoo.algorithms.moo.nsga2 import NSGA2
from pymoo.core.problem import Problem
from pymoo.operators.crossover.sbx import SBX
from pymoo.operators.mutation.pm import PM
from pymoo.operators.sampling.rnd import FloatRandomSampling
from pymoo.operators.selection.tournament import TournamentSelection

from paretocal.search.engine import tournament_winners
from paretocal.search.nsga import SearchResult, TimedObjective, front_of
from paretocal.search.problem import RoundN, SamplingWithInit, bounds


class CalibrationProblem(Problem):
    """Two objectives, both minimised, evaluated for the whole population in one call."""

    def __init__(self, objective, xl: np.ndarray, xu: np.ndarray):
        super().__init__(n_var=7, n_obj=2, xl=xl, xu=xu)
        self.objective = objective

    def _evaluate(self, X, out, *args, **kwargs):
        out["F"] = self.objective.evaluate(X)


def binary_tournament(pop, P, algorithm, **kwargs):
    """pymoo's tournament interface over the package's vectorised rule."""
    coin = algorithm.random_state.random(len(P)) < 0.5
    S = tournament_winners(pop.get("F"), pop.get("crowding"), P[:, 0], P[:, 1], coin)
    return S[:, None].astype(int, copy=False)


class FastPymooNSGA2(NSGA2):
    """pymoo's NSGA-II without the optimum recomputed after every generation."""

    def _set_optimum(self, **kwargs):
        self.opt = self.pop


def make_algorithm(settings, seeds: np.ndarray | None = None,
                   eliminate_duplicates: bool = False) -> NSGA2:
    """NSGA-II with SBX (p, eta), polynomial mutation (eta) and uniform sampling (plus the
    zero correction and ``seeds`` (k, 6) when ``settings.include_init``)."""
    sampling = SamplingWithInit(seeds) if settings.include_init else FloatRandomSampling()
    return FastPymooNSGA2(pop_size=settings.pop, sampling=sampling,
                          selection=TournamentSelection(func_comp=binary_tournament),
                          crossover=SBX(prob=settings.sbx_prob, eta=settings.sbx_eta),
                          mutation=PM(eta=settings.pm_eta, at_least_once=True),
                          repair=RoundN(), eliminate_duplicates=eliminate_duplicates)


def run_pymoo_nsga2(objective, settings, n_min: int, n_max: int, algorithm=None,
                    seeds: np.ndarray | None = None) -> SearchResult:
    """Like :func:`paretocal.search.run_nsga2`, with pymoo's algorithm object (``algorithm``,
    default :func:`make_algorithm`); no checkpoints."""
    xl, xu = bounds(settings, n_min, n_max)
    timed = TimedObjective(objective)
    algo = algorithm if algorithm is not None else make_algorithm(settings, seeds)
    t0 = time.perf_counter()
    algo.setup(CalibrationProblem(timed, xl, xu), termination=("n_gen", settings.gens),
               seed=settings.seed, verbose=False, save_history=False)
    gen, history = 0, []
    while algo.has_next():
        algo.next()
        gen += 1
        history.append({"gen": gen, "best_f1": float(algo.pop.get("F")[:, 0].min()),
                        "evaluations": timed.evaluations})
    popX, popF = algo.pop.get("X"), algo.pop.get("F")
    Xf, Ff = front_of(popX, popF)
    return SearchResult(X=Xf, F=Ff, pop_X=popX, pop_F=popF, evaluations=timed.evaluations,
                        generations=gen, wall_s=time.perf_counter() - t0,
                        objective_s=timed.seconds, history=history)
