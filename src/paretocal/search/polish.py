"""Local polish of many solutions at once: a batched compass (pattern) search over the pose.

NSGA-II locates the basin but its variation operators, scaled to the +-25 deg / +-1.5 m bounds,
refine slowly. Every solution of the front is polished at its own, fixed ``n``: each iteration
tries a step of +-s along each of the six pose axes for all solutions in one objective call,
moves each solution to its best improving neighbour, and halves the step of solutions that did
not improve. A solution is only ever replaced by one with a lower f1.
"""

from __future__ import annotations

import numpy as np

DEFAULT_STEP = np.array([0.04, 0.04, 0.04, 0.4, 0.4, 0.4])      # m, m, m, deg, deg, deg
DEFAULT_MIN_STEP = np.array([5e-4, 5e-4, 5e-4, 5e-3, 5e-3, 5e-3])


def polish(chamfer, X: np.ndarray, step: np.ndarray = DEFAULT_STEP,
           min_step: np.ndarray = DEFAULT_MIN_STEP, max_iter: int = 200,
           lower: np.ndarray | None = None, upper: np.ndarray | None = None):
    """Compass search on the first six columns of each row of X, in parallel.

    Parameters
    ----------
    chamfer : callable
        ``chamfer(X) -> f1`` for X of shape (C, 7), vectorised.
    X : ndarray, shape (k, 7)
        Starting solutions; column 6 (n) is held fixed.
    step, min_step : ndarray, shape (6,)
        Initial and final step per axis (metres and degrees).
    max_iter : int
    lower, upper : ndarray, shape (7,), optional
        Bounds the pose must stay within.

    Returns
    -------
    X : ndarray, shape (k, 7)
    f1 : ndarray, shape (k,)
    evaluations : int
    """
    X = np.array(X, dtype=np.float64, copy=True)
    k = len(X)
    f = np.asarray(chamfer(X), dtype=np.float64)
    evals = k
    scale = np.tile(np.asarray(step, dtype=np.float64), (k, 1))
    dirs = np.vstack([np.eye(6), -np.eye(6)])                      # (12, 6)
    active = np.ones(k, dtype=bool)
    for _ in range(max_iter):
        idx = np.flatnonzero(active)
        if len(idx) == 0:
            break
        cand = np.repeat(X[idx, None, :], 12, axis=1)              # (a, 12, 7)
        cand[:, :, :6] += dirs[None] * scale[idx, None, :]
        if lower is not None:
            cand[:, :, :6] = np.clip(cand[:, :, :6], lower[:6], upper[:6])
        fc = np.asarray(chamfer(cand.reshape(-1, 7)), dtype=np.float64).reshape(len(idx), 12)
        evals += fc.size
        best = fc.argmin(axis=1)
        fbest = fc[np.arange(len(idx)), best]
        better = fbest < f[idx]
        win = idx[better]
        X[win] = cand[better, best[better]]
        f[win] = fbest[better]
        lose = idx[~better]
        scale[lose] *= 0.5
        active[lose] = (scale[lose] >= min_step).any(axis=1)
    return X, f, evals
