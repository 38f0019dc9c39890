"""The first objective: alignment error of projected LiDAR features against image edges.

Default (``edge-dt``), one-sided LiDAR -> image, per frame f and candidate c::

    E_f = w1 * mean_depth_edges(rho) + w2 * mean_intensity_edges(rho) - contrast * mean_smooth(rho)

with ``rho`` the truncated DT value at the projected point (``outside`` when out of view), and

    f1 = mean_f E_f + k * SE,    SE^2 = (1 / F^2) sum_f sum_g w_g^2 s_fg^2 / N_fg.

* The mean over the first ``n`` points of a random, stratified order is an estimate of the mean
  over all of them, with standard error SE. A search that tries M poses and keeps the best is
  fooled by the luckiest of M noisy estimates, about ``sqrt(2 ln M)`` standard errors below its
  true value (the expected maximum of M Gaussians): with few points it finds poses, far from
  the truth, that happen to align those few points. Charging ``k SE`` with
  ``k = sqrt(2 ln M)`` (M = pop x gens) cancels that winner's curse, so f1 falls as ``n``
  grows and the Pareto front spans the ``n`` range instead of collapsing onto a few lucky
  small subsets. Measured on the KITTI sample: with k = 2 the front held only n = 20-22 and
  its knee was 1.4 deg / 12 cm off; with k = 4.6 it spanned n = 20-1860.
* The smooth-point term rewards poses that put surface points away from image edges, which
  stops the optimiser from parking every point in heavily textured regions.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..features.lidar import DEPTH_EDGE, INTENSITY_EDGE, SMOOTH
from .scene import N_GROUPS


def group_weights(w_edge: float, contrast: float) -> np.ndarray:
    """Signed weights per feature group, shape (G,).

    Parameters
    ----------
    w_edge : float
        ``w1``, the weight of the depth edges; the intensity edges get ``1 - w_edge``.
    contrast : float
        The weight of the smooth-surface points, subtracted (they should lie away from image
        edges).

    Returns
    -------
    ndarray, shape (G,)
        Indexed by ``DEPTH_EDGE``, ``INTENSITY_EDGE`` and ``SMOOTH``
        (:mod:`paretocal.features.lidar`).
    """
    w = np.zeros(N_GROUPS)
    w[DEPTH_EDGE] = w_edge
    w[INTENSITY_EDGE] = 1.0 - w_edge
    w[SMOOTH] = -contrast
    return w


def combine(S1: np.ndarray, S2: np.ndarray, W1: np.ndarray, W2: np.ndarray,
            outside: np.ndarray, weights: np.ndarray, ucb_k: float) -> dict[str, np.ndarray]:
    """Objective f1 from per-group sums.

    Parameters
    ----------
    S1, S2 : ndarray, shape (C, F, G)
        Weighted sums of the per-point cost and of its square.
    W1, W2 : ndarray, shape (C, F, G)
        Sums of the point weights and of their squares (counts when unweighted).
    outside : ndarray, shape (F,)
        Neutral value used as the mean of a group with no point in the sample.
    weights : ndarray, shape (G,)
    ucb_k : float

    Returns
    -------
    dict with ``f1`` (C,), ``mean`` (C, G) group means over frames in px, ``se`` (C,) and
    ``per_frame`` (C, F), each frame's weighted term (no sampling-error charge)
    """
    mean, term_parts, se_parts = _per_group(S1, S2, W1, W2, outside.astype(np.float64),
                                            np.asarray(weights, dtype=np.float64))
    F = S1.shape[1]
    # The reductions stay numpy's (pairwise sums), so f1 is the same bit for bit as when every
    # step was a numpy array operation.
    term = term_parts.sum(axis=2)                                       # (C, F)
    se2 = se_parts[..., weights != 0].sum(axis=(1, 2)) / F**2
    se = np.sqrt(se2)
    f1 = term.mean(axis=1) + ucb_k * se
    return {"f1": f1, "mean": mean.mean(axis=1), "se": se, "per_frame": term}


@njit(cache=True, error_model="numpy")
def _per_group(S1, S2, W1, W2, outside, weights):  # pragma: no cover - compiled
    """Per (candidate, frame, group): the mean cost (``outside[f]`` for an empty group), the
    weighted mean, and the weighted squared sampling error, each (C, F, G), in one pass.

    The arithmetic is numpy's elementwise arithmetic op for op: weighted variance with Kish's
    effective sample size ``n_eff = W1^2 / W2``, Bessel-corrected, floored at 0.
    """
    C, F, G = S1.shape
    mean = np.empty((C, F, G))
    wmean = np.empty((C, F, G))
    se_part = np.empty((C, F, G))
    for c in range(C):
        for f in range(F):
            for g in range(G):
                w1 = W1[c, f, g]
                w2 = W2[c, f, g]
                has = w1 > 0
                safe = w1 if has else 1.0
                m = S1[c, f, g] / safe if has else outside[f]
                n_eff = w1 * w1 / (w2 if w2 > 0 else 1.0) if has else 0.0
                var = 0.0
                if n_eff > 1:
                    var = (S2[c, f, g] / safe - m * m) * n_eff / max(n_eff - 1.0, 1e-12)
                # np.maximum(var, 0.0): a NaN stays NaN, -0.0 stays -0.0.
                var = var if (var >= 0.0 or var != var) else 0.0
                q = var / max(n_eff, 1e-12) if n_eff > 0 else 0.0
                wg = weights[g]
                mean[c, f, g] = m
                wmean[c, f, g] = m * wg
                se_part[c, f, g] = q * (wg * wg)
    return mean, wmean, se_part
