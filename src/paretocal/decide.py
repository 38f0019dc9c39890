"""Choosing one calibration from the Pareto front.

* ``knee``: the solution farthest below the straight line joining the two ends of the front,
  in objectives min-max normalised over the front. On a convex front this is where a further
  gain in accuracy starts to cost disproportionately more computation. (pymoo's
  ``HighTradeoffPoints`` is not used: in pymoo 0.6.2 it ignores its epsilon and can return
  nothing.)
* ``budget``: the lowest f1 whose modelled evaluation time is within ``budget_ms``.
* ``min-chamfer``: the lowest f1 regardless of cost.
"""

from __future__ import annotations

import numpy as np

from .errors import SettingsError


def knee_index(F: np.ndarray) -> int:
    """Index of the knee of a two-objective front F (k, 2), both minimised.

    Returns the solution of largest perpendicular distance below the chord between the
    extreme solutions in normalised objective space; with fewer than three solutions, or a
    front with no point below its chord, the lowest-f1 solution.
    """
    F = np.asarray(F, dtype=np.float64)
    if len(F) < 3:
        return int(np.argmin(F[:, 0]))
    lo, hi = F.min(axis=0), F.max(axis=0)
    Z = (F - lo) / np.where(hi > lo, hi - lo, 1.0)
    a = Z[np.argmin(Z[:, 0])]            # best accuracy end
    b = Z[np.argmin(Z[:, 1])]            # cheapest end
    d = b - a
    norm = np.hypot(*d)
    if norm == 0:
        return int(np.argmin(F[:, 0]))
    # Signed distance; positive on the side of the ideal point (0, 0).
    dist = ((Z[:, 0] - a[0]) * d[1] - (Z[:, 1] - a[1]) * d[0]) / norm
    ideal_side = np.sign((0 - a[0]) * d[1] - (0 - a[1]) * d[0]) or 1.0
    dist *= ideal_side
    i = int(np.argmax(dist))
    return i if dist[i] > 0 else int(np.argmin(F[:, 0]))


def choose(F: np.ndarray, ms: np.ndarray, rule: str = "knee",
           budget_ms: float | None = None) -> tuple[int, dict]:
    """Pick a solution of the front.

    Parameters
    ----------
    F : ndarray, shape (k, 2)
        Front objectives ``[f1, f2]``.
    ms : ndarray, shape (k,)
        Modelled evaluation time of each solution in milliseconds.
    rule : {"knee", "budget", "min-chamfer"}
    budget_ms : float, optional
        Required by ``budget``.

    Returns
    -------
    index : int
    decision : dict
        The rule and what it used, for ``result.json``.
    """
    if rule == "knee":
        i = knee_index(F)
        return i, {"rule": "knee", "method": "max distance below the chord (normalised)"}
    if rule == "min-chamfer":
        return int(np.argmin(F[:, 0])), {"rule": "min-chamfer"}
    if rule == "budget":
        if budget_ms is None:
            raise SettingsError("--budget-ms is required by the budget rule")
        ok = np.flatnonzero(np.asarray(ms) <= budget_ms)
        if len(ok) == 0:
            raise SettingsError(f"--budget-ms {budget_ms:g}: no solution of the front fits; the "
                                f"cheapest needs {float(np.min(ms)):.4g} ms")
        i = int(ok[np.argmin(F[ok, 0])])
        return i, {"rule": "budget", "budget_ms": float(budget_ms),
                   "solutions_within_budget": int(len(ok))}
    raise SettingsError(f"unknown decision rule {rule!r}")
