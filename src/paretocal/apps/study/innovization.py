"""Innovization: relations between the decision variables and the objectives over a Pareto set.

Deb's innovization reads design principles off a Pareto set: what all good solutions share,
and what changes, and how, as one moves along the front. Here the set is the calibration front
``[x, y, z, yaw, pitch, roll, n]`` with objectives ``[f1, f2]``. Everything reported (the
findings text included) is computed from the set; thresholds are stated in the text.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from ...search.problem import UNITS, VARIABLES

OBJECTIVES = ("f1", "f2")
STRONG = 0.7       # |rank correlation| called strong
COMMON_SPREAD = 0.02  # a variable is "shared" when its range is below this share of its bounds


def _r2(y: np.ndarray, yhat: np.ndarray) -> float:
    ss = float(np.sum((y - y.mean()) ** 2))
    return 1.0 - float(np.sum((y - yhat) ** 2)) / ss if ss > 0 else float("nan")


def correlations(X: np.ndarray, F: np.ndarray) -> list[dict]:
    """Pearson and Spearman correlation of each variable with each objective.

    Parameters
    ----------
    X : ndarray, shape (k, 7)
    F : ndarray, shape (k, 2)

    Returns
    -------
    list of dict with ``variable``, ``objective``, ``pearson``, ``spearman``, ``spearman_p``.
    """
    rows = []
    for j, v in enumerate(VARIABLES):
        for m, o in enumerate(OBJECTIVES):
            x, y = X[:, j], F[:, m]
            if np.ptp(x) == 0 or np.ptp(y) == 0 or len(x) < 3:
                r = rho = p = float("nan")
            else:
                r = float(stats.pearsonr(x, y)[0])
                rho, p = (float(a) for a in stats.spearmanr(x, y))
            rows.append({"variable": v, "objective": o, "pearson": r, "spearman": rho,
                         "spearman_p": p})
    return rows


def trends(X: np.ndarray, F: np.ndarray) -> dict:
    """Fitted trends over the set.

    * ``cost_vs_n``: f2 = a + b n (least squares), with R^2.
    * ``chamfer_vs_n``: f1 = a + b / sqrt(n) (the sampling-error shape), with R^2.
    * ``chamfer_vs_variable``: per pose variable, f1 = c0 + c1 v + c2 v^2, with R^2.
    * ``variable_vs_n``: per pose variable, v = a + b log(n), with R^2 (how the pose drifts as
      points are added).
    """
    n = X[:, 6]
    out: dict = {}
    if np.ptp(n) > 0 and len(n) >= 3:
        b, a = np.polyfit(n, F[:, 1], 1)
        out["cost_vs_n"] = {"a": float(a), "b": float(b),
                            "r2": _r2(F[:, 1], a + b * n)}
        A = np.column_stack([np.ones_like(n), 1.0 / np.sqrt(n)])
        c, *_ = np.linalg.lstsq(A, F[:, 0], rcond=None)
        out["chamfer_vs_n"] = {"a": float(c[0]), "b": float(c[1]), "r2": _r2(F[:, 0], A @ c)}
        out["variable_vs_n"] = {}
        for j, v in enumerate(VARIABLES[:6]):
            b, a = np.polyfit(np.log(n), X[:, j], 1)
            out["variable_vs_n"][v] = {"a": float(a), "b": float(b),
                                       "r2": _r2(X[:, j], a + b * np.log(n))}
    out["chamfer_vs_variable"] = {}
    for j, v in enumerate(VARIABLES[:6]):
        if np.ptp(X[:, j]) > 0 and len(n) >= 4:
            c = np.polyfit(X[:, j], F[:, 0], 2)
            out["chamfer_vs_variable"][v] = {"c2": float(c[0]), "c1": float(c[1]),
                                             "c0": float(c[2]),
                                             "r2": _r2(F[:, 0], np.polyval(c, X[:, j]))}
    return out


def findings(X: np.ndarray, F: np.ndarray, bounds: np.ndarray, corr: list[dict] | None = None,
             fits: dict | None = None) -> list[str]:
    """Plain-language statements of what the set shows, each with the figure behind it.

    Parameters
    ----------
    X, F : ndarray
        The set (k, 7) and its objectives (k, 2).
    bounds : ndarray, shape (7,)
        Half-width of each variable's search range (for "shared" variables).
    """
    corr = corr if corr is not None else correlations(X, F)
    fits = fits if fits is not None else trends(X, F)
    lines = [f"The set holds {len(X)} solutions with n = {int(X[:, 6].min())}..."
             f"{int(X[:, 6].max())} points per frame."]
    c = fits.get("cost_vs_n")
    if c:
        lines.append(f"Cost is linear in n: f2 = {c['a']:.3g} + {c['b']:.3g} n (R^2 = {c['r2']:.3f}).")
    c = fits.get("chamfer_vs_n")
    rho = next((r["spearman"] for r in corr if r["variable"] == "n" and r["objective"] == "f1"),
               float("nan"))
    if c:
        trend = "falls" if rho < 0 else "rises"
        lines.append(f"The Chamfer objective {trend} with n (Spearman rho = {rho:+.2f}); "
                     f"f1 = {c['a']:.3f} + {c['b']:.3f} / sqrt(n) fits with R^2 = {c['r2']:.2f}, "
                     "the shape of a sampling error.")
    shared, moving = [], []
    for j, v in enumerate(VARIABLES[:6]):
        spread = float(np.ptp(X[:, j]))
        if spread <= COMMON_SPREAD * bounds[j]:
            shared.append(f"{v} = {np.median(X[:, j]):+.3g} {UNITS[j]} "
                          f"(range {spread:.2g} {UNITS[j]})")
        rho_n = stats.spearmanr(X[:, 6], X[:, j])[0] if np.ptp(X[:, j]) > 0 else 0.0
        if abs(rho_n) >= STRONG:
            moving.append(f"{v} (rho = {rho_n:+.2f}, {np.ptp(X[:, j]):.3g} {UNITS[j]} "
                          "over the front)")
    if shared:
        lines.append(f"Shared by every solution (range below {100 * COMMON_SPREAD:g} % of the "
                     f"bounds): {'; '.join(shared)}.")
    if moving:
        lines.append(f"Moving monotonically with n (|Spearman rho| >= {STRONG}): "
                     f"{'; '.join(moving)}.")
    else:
        lines.append(f"No pose variable moves monotonically with n (all |Spearman rho| < {STRONG}).")
    fv = fits.get("chamfer_vs_variable", {})
    if fv:
        best = max(fv, key=lambda v: fv[v]["r2"] if np.isfinite(fv[v]["r2"]) else -1)
        lines.append(f"Of the pose variables, {best} explains most of the Chamfer spread "
                     f"(quadratic fit R^2 = {fv[best]['r2']:.2f}).")
    return lines
