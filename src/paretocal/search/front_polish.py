"""The polish of a whole front after the search (see :func:`polish_front`)."""

from __future__ import annotations

import numpy as np

from ..config import SearchSettings
from ..objective.objective import PopulationObjective
from .nsga import front_of
from .polish import DEFAULT_FD_STEP, fd_gradient_hessian, newton_polish, polish
from .problem import bounds

FINISH_STEP = np.array([0.005, 0.005, 0.005, 0.05, 0.05, 0.05])  # compass steps after Newton


def polish_front(objective: PopulationObjective, X: np.ndarray, F: np.ndarray,
                 search: SearchSettings, n_min: int, n_max: int, iters: int, grid: int = 12,
                 max_front: int = 32, explore: bool = True):
    """Polish every front solution at its own n, plus the best pose at a grid of n values.

    Damped Newton steps with finite-difference derivatives (batched over all solutions) follow
    the diagonal valleys of the objective; a short compass search then settles each solution.
    The grid fills parts of the n range the search's front did not reach, so the final front
    shows the whole trade-off; a grid solution enters the front only if it is non-dominated.

    Then the weakly determined directions of the best pose are explored: edge alignment
    constrains some combinations poorly (a small pitch against a few centimetres of height
    aligns everything near one depth), and a neighbouring minimum along such a valley can be
    almost as good. Starts along the three flattest eigen-directions of the Hessian at the
    largest n are polished, and the best pose at the largest n then seeds every n of the
    front again; each n keeps whichever basin scores lower.

    Parameters
    ----------
    objective : PopulationObjective
        Has ``chamfer(X)["f1"]`` and ``cost(X)["f2"]`` for X of shape (C, 7).
    X : ndarray, shape (k, 7)
        The front's solutions ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
    F : ndarray, shape (k, 2)
        Their objectives ``[f1, f2]``.
    search : SearchSettings
        The search's settings; with ``n_min`` and ``n_max`` they give the box.
    n_min, n_max : int
        The range of points per frame.
    iters : int
        Newton iterations per polish (``decision.polish_iters``).
    grid : int
        Values of ``n`` (geometric) at which the best pose is polished.
    max_front : int
        Most front solutions polished, spread along the front by cost.
    explore : bool
        False: polish the solutions of ``X`` and nothing else (no n grid, valley starts or
        cross-seeding), for a front whose every solution already starts from one well-polished
        pose.

    Returns
    -------
    X : ndarray, shape (m, 7)
        The new front.
    F : ndarray, shape (m, 2)
        Its objectives.
    evaluations : int
        The evaluations spent.
    """
    xl, xu = bounds(search, n_min, n_max)
    fun = lambda Z: objective.chamfer(Z)["f1"]  # noqa: E731
    evals = 0

    def run(seeds):
        nonlocal evals
        Z, _, e1 = newton_polish(fun, seeds, iters=iters, lower=xl, upper=xu)
        Z, f, e2 = polish(fun, Z, step=FINISH_STEP, lower=xl, upper=xu)
        evals += e1 + e2
        return Z, f

    ns = np.unique(np.rint(np.geomspace(max(n_min, 1), n_max, grid)))

    def with_grid(pose):
        return np.column_stack([np.tile(pose[:6], (len(ns), 1)), ns])

    if not explore:
        P, fP = run(X)
        return (*front_of(P, np.column_stack([fP, objective.cost(P)["f2"]])), evals)
    best = X[np.argmin(F[:, 0])]
    if len(X) > max_front:
        # Polish a subset spread evenly along the front by cost: enough to draw the trade-off.
        X = X[np.unique(np.rint(np.linspace(0, len(X) - 1, max_front)).astype(int))]
    P, fP = run(np.vstack([X, with_grid(best)]))
    top = np.flatnonzero(P[:, 6] == P[:, 6].max())
    anchor = P[top[np.argmin(fP[top])]]
    V, fV = run(valley_starts(fun, anchor))
    evals += 28
    if fV.min() < fP[top].min() - 1e-9:
        anchor = V[np.argmin(fV)]
    # Cross-seed: every n of the front also starts from the best pose found with the most
    # points, so that a basin found late (or only at large n) reaches the whole front.
    Pf, _ = front_of(P, np.column_stack([fP, objective.cost(P)["f2"]]))
    ns_all = np.unique(Pf[:, 6])
    Q, fQ = run(np.column_stack([np.tile(anchor[:6], (len(ns_all), 1)), ns_all]))
    P, fP = np.vstack([P, V, Q]), np.concatenate([fP, fV, fQ])
    Fp = np.column_stack([fP, objective.cost(P)["f2"]])
    Xf, Ff = front_of(P, Fp)
    return Xf, Ff, evals


def valley_starts(fun, x: np.ndarray, directions: int = 3,
                  offsets=(-12.0, -8.0, -4.0, 4.0, 8.0, 12.0)) -> np.ndarray:
    """Starts along the flattest Hessian eigen-directions of f1 at ``x`` (7,), shape (k, 7).

    Offsets are in units of the finite-difference steps (1 cm, 0.1 deg), so 12 units moves
    the pose by up to 12 cm or 1.2 deg along the valley.
    """
    h = DEFAULT_FD_STEP
    _, _, H = fd_gradient_hessian(fun, x[None], h)
    w, V = np.linalg.eigh(H[0] * h[:, None] * h[None, :])
    out = []
    for d in range(directions):
        for o in offsets:
            z = x.copy()
            z[:6] += o * V[:, d] * h
            out.append(z)
    return np.array(out)
