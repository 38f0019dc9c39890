"""Epsilon-constraint verification of the Pareto front.

For each cost limit ``eps``: minimise f1 subject to ``f2 <= eps`` (a pymoo inequality
constraint ``G = f2 - eps``) with a single-objective GA over all seven variables. Every point
so found is a Pareto-optimal candidate in its own right; if NSGA-II's front is right, none of
them lies clearly below it, and they should lie on it.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from pymoo.algorithms.soo.nonconvex.ga import GA
from pymoo.core.problem import Problem
from pymoo.optimize import minimize as pymoo_minimize

from ...search.polish import newton_polish
from ...search.problem import RoundN, SamplingWithInit


class EpsilonProblem(Problem):
    """min f1 s.t. f2 <= eps, over ``[x, y, z, yaw, pitch, roll, n]``."""

    def __init__(self, objective, eps: float, xl: np.ndarray, xu: np.ndarray):
        super().__init__(n_var=7, n_obj=1, n_ieq_constr=1, xl=xl, xu=xu)
        self.objective, self.eps = objective, float(eps)

    def _evaluate(self, X, out, *args, **kwargs):
        F = self.objective.evaluate(X)
        out["F"] = F[:, :1]
        out["G"] = F[:, 1:2] - self.eps


def front_f1_at(F_front: np.ndarray, eps: float) -> float:
    """The lowest f1 of a front (k, 2) among solutions with ``f2 <= eps`` (inf if none)."""
    ok = F_front[:, 1] <= eps + 1e-12
    return float(F_front[ok, 0].min()) if ok.any() else float("inf")


def epsilon_constraint(objective, eps_values, xl: np.ndarray, xu: np.ndarray, pop: int,
                       gens: int, seed: int = 0, seeds: np.ndarray | None = None,
                       F_front: np.ndarray | None = None, polish_iters: int = 12) -> list[dict]:
    """Solve the epsilon-constraint problem for each cost limit.

    Parameters
    ----------
    objective : CalibrationObjective
        ``evaluate(X) -> [f1, f2]`` and ``chamfer(X)["f1"]``.
    eps_values : sequence of float
        Limits on the normalised cost f2.
    xl, xu : ndarray, shape (7,)
        Bounds of the seven variables.
    pop, gens : int
        GA population and generations per limit.
    seed : int
    seeds : ndarray, shape (k, 6), optional
        Poses placed in every initial population (as in the NSGA-II run).
    F_front : ndarray, shape (m, 2), optional
        The NSGA-II front to compare with.
    polish_iters : int
        Newton iterations of the same local polish the front gets (0: none), after a line
        search in ``n`` up to the limit at the GA's pose.

    Returns
    -------
    list of dict
        Per limit: ``eps``, ``x`` (7,), ``f1``, ``f2``, ``f1_ga`` (the GA's own result, before the
        line search in n and the polish),
        ``feasible``, ``front_f1`` (the front's best f1 within the limit), ``gap``
        (``f1 - front_f1``: negative means the constraint run beat the front),
        ``evaluations``, ``wall_s``.
    """
    xl, xu = np.asarray(xl, float), np.asarray(xu, float)
    rows: list[dict[str, Any]] = []
    for k, eps in enumerate(eps_values):
        t0 = time.perf_counter()
        problem = EpsilonProblem(objective, eps, xl, xu)
        algo = GA(pop_size=pop, sampling=SamplingWithInit(seeds), repair=RoundN(),
                  eliminate_duplicates=False)
        res = pymoo_minimize(problem, algo, ("n_gen", gens), seed=seed + k, verbose=False)
        evals = int(res.algorithm.evaluator.n_eval)
        if res.X is None:              # no feasible solution found
            rows.append({"eps": float(eps), "feasible": False, "evaluations": evals,
                         "wall_s": time.perf_counter() - t0})
            continue
        x = np.asarray(res.X, dtype=np.float64).ravel()
        f_ga = float(objective.chamfer(x[None])["f1"][0])
        # The GA rarely lands exactly on the constraint: try the same pose with more points,
        # up to the limit (a line search in n; f2 is checked, not assumed monotone in n).
        ns = np.unique(np.rint(np.linspace(x[6], xu[6], min(int(xu[6] - x[6]) + 1, 2048))))
        line = np.repeat(x[None], len(ns), axis=0)
        line[:, 6] = ns
        FL = objective.evaluate(line)
        evals += len(line)
        ok = np.flatnonzero(FL[:, 1] <= eps)
        f_x = f_ga
        if len(ok) and FL[ok, 0].min() < f_ga:
            j = ok[np.argmin(FL[ok, 0])]
            x, f_x = line[j], float(FL[j, 0])
        if polish_iters:
            # n stays fixed, so the cost and the constraint do not change.
            P, fP, ev = newton_polish(lambda Z: objective.chamfer(Z)["f1"], x[None],
                                      iters=polish_iters, lower=xl, upper=xu)
            evals += ev
            if fP[0] < f_x:
                x = P[0]
        F = objective.evaluate(x[None])[0]
        row: dict[str, Any] = {
            "eps": float(eps), "feasible": bool(F[1] <= eps + 1e-12), "x": x,
            "f1": float(F[0]), "f2": float(F[1]), "f1_ga": f_ga, "evaluations": evals,
            "wall_s": time.perf_counter() - t0}
        if F_front is not None:
            row["front_f1"] = front_f1_at(F_front, eps)
            row["gap"] = row["f1"] - row["front_f1"]
        rows.append(row)
    return rows
