"""Single-objective verification: minimise the Chamfer alone, globally (pymoo DE) then locally.

The NSGA-II front claims that its most expensive solutions are the best alignments the
objective offers. A single-objective search of f1 at the largest ``n`` checks that claim: if
it finds a markedly lower f1 than the front's best, the multi-objective search did not
converge. Both runs record their convergence so that the speeds can be compared as well.
"""

from __future__ import annotations

import time

import numpy as np
from pymoo.algorithms.soo.nonconvex.de import DE
from pymoo.core.callback import Callback
from pymoo.core.problem import Problem
from pymoo.core.sampling import Sampling
from pymoo.operators.sampling.rnd import FloatRandomSampling
from pymoo.optimize import minimize as pymoo_minimize
from scipy.optimize import minimize as scipy_minimize


class FixedNProblem(Problem):
    """f1 over the six pose variables at a fixed number of points ``n`` per frame.

    ``chamfer(X) -> f1`` takes candidates of shape (C, 7); one call per population.
    """

    def __init__(self, chamfer, n: int, xl: np.ndarray, xu: np.ndarray):
        super().__init__(n_var=6, n_obj=1, xl=xl[:6], xu=xu[:6])
        self.chamfer, self.n = chamfer, int(n)

    def full(self, X6: np.ndarray) -> np.ndarray:
        return np.column_stack([np.atleast_2d(X6), np.full(len(np.atleast_2d(X6)), self.n)])

    def _evaluate(self, X, out, *args, **kwargs):
        out["F"] = np.asarray(self.chamfer(self.full(X)), dtype=np.float64)[:, None]


class _SeededSampling(Sampling):
    """Uniform sampling with given poses (k, 6) in the first rows."""

    def __init__(self, seeds: np.ndarray):
        super().__init__()
        self.seeds = seeds

    def _do(self, problem, n_samples, **kwargs):
        X = FloatRandomSampling()._do(problem, n_samples, **kwargs)
        k = min(len(self.seeds), n_samples // 2)
        X[:k] = np.clip(self.seeds[:k], problem.xl, problem.xu)
        return X


class _Trace(Callback):
    """Best and median f1 of the population after every generation."""

    def __init__(self):
        super().__init__()
        self.rows: list[dict] = []
        self.t0 = time.perf_counter()

    def notify(self, algorithm):
        F = algorithm.pop.get("F")[:, 0]
        self.rows.append({"generation": int(algorithm.n_gen),
                          "evaluations": int(algorithm.evaluator.n_eval),
                          "best_f1": float(algorithm.opt.get("F")[0, 0]),
                          "median_f1": float(np.median(F)), "wall_s": time.perf_counter() - self.t0})


def single_objective(chamfer, n: int, xl: np.ndarray, xu: np.ndarray, pop: int, gens: int,
                     seed: int = 0, seeds: np.ndarray | None = None,
                     local_maxfev: int = 3000) -> dict:
    """Minimise f1 at fixed ``n``: differential evolution, then Powell from its best pose.

    Parameters
    ----------
    chamfer : callable
        ``chamfer(X) -> f1`` for X of shape (C, 7), vectorised.
    n : int
        Points per frame (the seventh variable, held fixed).
    xl, xu : ndarray, shape (7,)
        Search bounds (m, deg; the last entry is ignored).
    pop, gens : int
        Population size and generations of the DE (pymoo ``DE/rand/1/bin``).
    seed : int
        Seed of the DE.
    seeds : ndarray, shape (k, 6), optional
        Poses placed in the initial population (the zero correction is always one).
    local_maxfev : int
        Evaluation budget of the local (Powell) refinement.

    Returns
    -------
    dict
        ``de_history`` (per generation: generation, evaluations, best_f1, median_f1, wall_s),
        ``local_history`` (per Powell iteration: iteration, evaluations, f1), ``x_de`` and
        ``x`` (the pose after the local step, kept only if it is lower), shape (7,), ``f1_de``,
        ``f1``, ``evaluations``, ``wall_s``.
    """
    t0 = time.perf_counter()
    problem = FixedNProblem(chamfer, n, np.asarray(xl, float), np.asarray(xu, float))
    start = np.zeros((1, 6)) if seeds is None else np.vstack([np.zeros((1, 6)), seeds])
    trace = _Trace()
    algo = DE(pop_size=pop, variant="DE/rand/1/bin", CR=0.9, F=0.5,
              sampling=_SeededSampling(start))
    res = pymoo_minimize(problem, algo, ("n_gen", gens), seed=seed, callback=trace,
                         verbose=False)
    x_de = np.asarray(res.X, dtype=np.float64).ravel()
    f_de = float(np.asarray(res.F).ravel()[0])
    evals = int(res.algorithm.evaluator.n_eval)

    # Powell works on one candidate at a time; scale the variables so that one unit is about
    # 1 deg or 10 cm, the sizes the objective resolves.
    scale = np.array([0.1, 0.1, 0.1, 1.0, 1.0, 1.0])
    count = {"n": 0}
    local: list[dict[str, float]] = []

    def fun(z):
        count["n"] += 1
        return float(problem.chamfer(problem.full(np.clip(z * scale, problem.xl, problem.xu)))[0])

    def record(zk):
        local.append({"iteration": len(local) + 1, "evaluations": count["n"], "f1": fun_nocount(zk)})

    def fun_nocount(z):
        v = fun(z)
        count["n"] -= 1
        return v

    out = scipy_minimize(fun, x_de / scale, method="Powell", callback=record,
                         options={"maxfev": local_maxfev, "xtol": 1e-3, "ftol": 1e-7})
    x_loc = np.clip(out.x * scale, problem.xl, problem.xu)
    f_loc = float(out.fun)
    evals += count["n"]
    keep = f_loc < f_de
    x = x_loc if keep else x_de
    return {"de_history": trace.rows, "local_history": local,
            "x_de": np.r_[x_de, n], "f1_de": f_de,
            "x": np.r_[x, n], "f1": f_loc if keep else f_de, "local_improved": bool(keep),
            "evaluations": evals, "wall_s": time.perf_counter() - t0}
