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
        if lower is not None and upper is not None:
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


DEFAULT_FD_STEP = np.array([0.01, 0.01, 0.01, 0.1, 0.1, 0.1])   # m, m, m, deg, deg, deg


def fd_stencil(h: np.ndarray) -> np.ndarray:
    """Offsets (28, 6) for a finite-difference gradient and Hessian: centre, +-h_i, h_i + h_j."""
    e = np.eye(6) * h
    pairs = [e[i] + e[j] for i in range(6) for j in range(i + 1, 6)]
    return np.vstack([np.zeros(6), e, -e, pairs])


def fd_gradient_hessian(chamfer, X: np.ndarray, h: np.ndarray = DEFAULT_FD_STEP,
                        f0: np.ndarray | None = None):
    """Finite-difference gradient and Hessian of f1 over the pose, for many solutions at once.

    Parameters
    ----------
    chamfer : callable
        ``chamfer(X) -> f1`` for X of shape (C, 7).
    X : ndarray, shape (k, 7)
    h : ndarray, shape (6,)
        Difference steps (m, deg); large enough to average over pixel-scale roughness.
    f0 : ndarray, shape (k,), optional
        f1 at X when already known (the stencil's centre is then not evaluated again; the
        objective is deterministic, so the derivatives are the same).

    Returns
    -------
    f : ndarray, shape (k,)
    g : ndarray, shape (k, 6)
        Gradient per metre / degree.
    H : ndarray, shape (k, 6, 6)
        Hessian per metre / degree squared.
    """
    k = len(X)
    S = fd_stencil(h)
    if f0 is not None:
        S = S[1:]
    cand = np.repeat(X[:, None, :], len(S), axis=1)
    cand[:, :, :6] += S[None]
    v = np.asarray(chamfer(cand.reshape(-1, 7)), dtype=np.float64).reshape(k, len(S))
    if f0 is not None:
        v = np.column_stack([np.asarray(f0, dtype=np.float64), v])
    return stencil_derivatives(v, h)


def stencil_derivatives(v: np.ndarray, h: np.ndarray):
    """Value, gradient and Hessian from objective values on :func:`fd_stencil`.

    Parameters
    ----------
    v : ndarray, shape (k, 28)
        Values at the stencil's offsets, in its order.
    h : ndarray, shape (6,)

    Returns
    -------
    f0 : ndarray, shape (k,); g : ndarray, shape (k, 6); H : ndarray, shape (k, 6, 6)
    """
    v = np.atleast_2d(v)
    k = len(v)
    f0, fp, fm, fpp = v[:, 0], v[:, 1:7], v[:, 7:13], v[:, 13:]
    g = (fp - fm) / (2 * h)
    H = np.zeros((k, 6, 6))
    idx = 0
    for i in range(6):
        H[:, i, i] = (fp[:, i] - 2 * f0 + fm[:, i]) / h[i] ** 2
        for j in range(i + 1, 6):
            H[:, i, j] = H[:, j, i] = (fpp[:, idx] - fp[:, i] - fp[:, j] + f0) / (h[i] * h[j])
            idx += 1
    return f0, g, H


def newton_step(g: np.ndarray, H: np.ndarray, h: np.ndarray, max_step: float,
                eig_floor: float = 1e-3) -> np.ndarray:
    """Steps to the minima of the local quadratics, batched, shape (k, 6) in m and deg.

    Worked in units of ``h`` (metres and degrees comparable); the Hessian's eigenvalues are
    taken in absolute value and floored at ``eig_floor`` times the largest (so the step always
    descends, and the noise-level flattest curvatures do not send it far); the step is capped
    at ``max_step`` units of ``h``.
    """
    gs = np.atleast_2d(g) * h
    Hs = np.atleast_3d(H) * h[None, :, None] * h[None, None, :]
    w, V = np.linalg.eigh(Hs)
    floor = np.maximum(np.abs(w).max(axis=1, keepdims=True) * eig_floor, 1e-12)
    w = np.maximum(np.abs(w), floor)
    step = -np.einsum("kij,kj->ki", V, np.einsum("kji,kj->ki", V, gs) / w)
    norm = np.linalg.norm(step, axis=1, keepdims=True)
    step *= np.minimum(1.0, max_step / np.maximum(norm, 1e-12))
    return step * h


def newton_polish(chamfer, X: np.ndarray, h: np.ndarray = DEFAULT_FD_STEP, iters: int = 8,
                  max_step: float = 3.0, lower: np.ndarray | None = None,
                  upper: np.ndarray | None = None, eig_floor: float = 1e-3):
    """Damped Newton steps with finite-difference derivatives, batched over solutions.

    Each iteration costs 28 + 5 evaluations per solution (27 + 5 after the first: the
    stencil's centre is the point the last line search evaluated). Directions come from the Hessian with
    its eigenvalues floored (so the step always descends); steps are capped at ``max_step``
    difference steps, and a line search over {1, 1/2, 1/4, 1/8, 1/16} keeps a step only when
    it lowers f1. Unlike a coordinate search, this follows the narrow diagonal valleys that
    rotation-translation coupling creates. Eigenvalues below ``eig_floor`` times the largest
    (in units of h) are raised to it: finite differences of a rough objective make the flattest
    curvatures noise, and a step along them is left to the line search and the trust region.

    Returns
    -------
    X : ndarray, shape (k, 7)
    f1 : ndarray, shape (k,)
    evaluations : int
    """
    X = np.array(X, dtype=np.float64, copy=True)
    k = len(X)
    f = np.full(k, np.inf)
    evals = 0
    alphas = np.array([1.0, 0.5, 0.25, 0.125, 0.0625])
    active = np.ones(k, dtype=bool)
    for _ in range(iters):
        idx = np.flatnonzero(active)
        if len(idx) == 0:
            break
        known = f[idx] if np.all(np.isfinite(f[idx])) else None
        f0, g, H = fd_gradient_hessian(chamfer, X[idx], h, known)
        evals += (28 if known is None else 27) * len(idx)
        f[idx] = np.minimum(f[idx], f0)
        step = newton_step(g, H, h, max_step, eig_floor)
        cand = np.repeat(X[idx, None, :], len(alphas), axis=1)
        cand[:, :, :6] += alphas[None, :, None] * step[:, None, :]
        if lower is not None and upper is not None:
            cand[:, :, :6] = np.clip(cand[:, :, :6], lower[:6], upper[:6])
        fc = np.asarray(chamfer(cand.reshape(-1, 7)), dtype=np.float64).reshape(len(idx), -1)
        evals += fc.size
        best = fc.argmin(axis=1)
        fbest = fc[np.arange(len(idx)), best]
        better = fbest < f[idx] - 1e-9
        X[idx[better]] = cand[better, best[better]]
        f[idx[better]] = fbest[better]
        active[idx[~better]] = False
    if not np.all(np.isfinite(f)):            # iters = 0: nothing was evaluated
        f = np.asarray(chamfer(X), dtype=np.float64)
        evals += k
    return X, f, evals
