"""Near or far: which of two local optima the data and the stated initial error support.

The search looks over the whole box the stated initial error allows, and on some scenes it finds
a pose far from the start that scores a little better than the optimum next to the start: with
two frames of one scene, a rotation of 20 degrees can align a few long edges by chance. Which
basin the data support is a question about frames, not about one number: each frame is an
independent look at the scene, so the per-frame difference of the objective between the two
poses is a paired sample (a one-sided paired t test).

The stated initial error (``--init-error``) is the prior. Inside it every pose is as plausible
as the start, so the data decide: the pose that scores better over all points is kept, and the
two are *ambiguous* when the test cannot tell them apart (p above :data:`AMBIGUOUS_P`) while
they differ by more than a usable calibration allows. The box is wider than the stated error
(see ``SearchSettings.bound_r``), and a pose beyond the stated error replaces the start's own
basin only on clear evidence: p below :data:`CLEAR_P` (with two frames that needs t > 32, with
twenty t > 2.5). Otherwise the front is rebuilt around the start's basin and the alternative is
reported as ambiguous when the data lean towards it.
"""

from __future__ import annotations

import math

from typing import Any

import numpy as np

from ..config import SearchSettings
from ..objective.objective import AlignmentObjective, PopulationObjective
from ..quality import displacement_px, local_optimum
from .front_polish import polish_front

#: One-sided p value of the paired t test (per-frame objective differences) below which the
#: data "clearly prefer" a pose beyond the stated initial error.
CLEAR_P = 0.01
#: Two distinct optima inside the stated error are ambiguous when the one kept is not
#: preferred at this level (the conventional 5 %).
AMBIGUOUS_P = 0.05
#: ... and they differ by more than a usable calibration may be off (deg, m): 1 deg moves a
#: point 20 m away by 35 cm.
USABLE_DEG = 1.0
USABLE_M = 0.10
#: With one frame there is no test: the start's basin is kept.
MIN_FRAMES = 2
#: Two poses whose projections differ by less than this share of the distance-transform
#: truncation are one basin: the objective cannot separate them.
SAME_BASIN_SHARE = 0.25


def paired_preference(objective: AlignmentObjective, near: np.ndarray, far: np.ndarray) -> dict:
    """Per-frame comparison of two poses (7,) at every point, without the sampling charge.

    Returns ``mean_px`` (mean advantage of ``far``, positive when it scores lower), ``se_px``,
    ``t`` and its one-sided ``p`` (NaN with fewer than two frames), and ``frames_far_better``.
    """
    # Student's t survival function as sf(t, k) = stdtr(k, -t): scipy.special, without the
    # half second that importing scipy.stats takes.
    from scipy.special import stdtr

    per = objective.chamfer(np.vstack([near, far]), ucb_k=0.0)["per_frame"]          # (2, F)
    d = per[0] - per[1]
    k = len(d)
    mean = float(d.mean())
    se = float(d.std(ddof=1) / np.sqrt(k)) if k > 1 else float("nan")
    if k < 2:
        t = float("nan")
    elif se > 0:
        t = mean / se
    else:                       # every frame differs alike: a sure advantage, or none at all
        t = math.copysign(float("inf"), mean) if mean != 0 else 0.0
    p = float(stdtr(k - 1, -t)) if k > 1 else float("nan")
    return {"mean_px": mean, "se_px": se, "t": float(t), "p": p, "frames": k,
            "frames_far_better": int((d > 0).sum())}


def departure(x: np.ndarray, init_error_deg: float, init_error_m: float) -> float:
    """How far a correction ``x`` (6+,) lies from the start in units of the stated initial
    error: the largest of ``|x_axis| / error_axis`` (1 on the edge of the stated error)."""
    x = np.asarray(x, dtype=np.float64)[:6]
    return float(max(np.abs(x[:3]).max() / init_error_m, np.abs(x[3:6]).max() / init_error_deg))


def prefer_near(objective: PopulationObjective, X: np.ndarray, F: np.ndarray,
                search: SearchSettings, n_min: int, n_max: int,
                polish_iters: int) -> tuple[np.ndarray, np.ndarray, dict, int]:
    """Keep the start's basin unless the data support the front's best pose (module docstring).

    Parameters
    ----------
    objective : CalibrationObjective
    X, F : ndarray, shapes (k, 7) and (k, 2)
        The polished front.
    search : SearchSettings
        The box and the stated initial error.
    n_min, n_max : int
    polish_iters : int
        Newton iterations of the front's polish when the front is rebuilt.

    Returns
    -------
    X, F : ndarray
        The front, unchanged when both optima are one basin; else every n of it polished
        again from the optimum kept, and when a solution of it lies nearer the other optimum
        (in mean pixel displacement), rebuilt around the one kept (n grid, valleys,
        cross-seeds: :func:`polish_front`).
    info : dict
        ``same_basin`` (bool), ``separation_px``, ``separation_deg``, ``separation_cm``, the
        paired comparison (``t``, ``mean_px``, ``p``, ...), ``departure_near`` and
        ``departure_far`` (in units of the stated initial error), ``kept`` ("near" or "far"),
        ``ambiguous`` (bool), ``alternative`` (the correction of the pose not kept, m and
        deg) and ``rebuilt`` (bool: the whole front rebuilt) when they are two basins.
    evaluations : int
    """
    from ..geometry import pose_error

    best = X[np.argmin(F[:, 0])].copy()
    best[6] = n_max
    start = np.zeros(7)
    start[6] = n_max
    near, far = local_optimum(objective, np.vstack([start, best]))
    evals = 2 * 400                                       # polish budget, order of magnitude
    sep_px = displacement_px(objective, near, far)
    T = objective.transforms(np.vstack([near, far]))
    e = pose_error(T[1], T[0])
    s = search
    info: dict[str, Any] = {
        "separation_px": round(float(sep_px), 3),
        "separation_deg": round(float(e["rotation_deg"]), 4),
        "separation_cm": round(float(e["translation_cm"]), 3),
        "departure_near": round(departure(near, s.init_error_deg, s.init_error_m), 3),
        "departure_far": round(departure(far, s.init_error_deg, s.init_error_m), 3),
        "ambiguous": False}
    limit = SAME_BASIN_SHARE * objective.scene.truncation_px
    if sep_px <= limit:
        info.update(same_basin=True, kept="far")
        return X, F, info, evals
    cmp = paired_preference(objective, near, far)
    info.update(same_basin=False, **{k: (round(v, 4) if isinstance(v, float) else v)
                                     for k, v in cmp.items()})
    tested = cmp["frames"] >= MIN_FRAMES and np.isfinite(cmp["p"])
    distinct = (e["rotation_deg"] > USABLE_DEG) or (e["translation_cm"] > 100 * USABLE_M)
    if info["departure_far"] <= 1.0:
        # Inside the stated error the data decide.
        keep_far = cmp["mean_px"] >= 0.0
        p_kept = cmp["p"] if keep_far else 1.0 - cmp["p"]
        info["ambiguous"] = bool(distinct and (not tested or p_kept >= AMBIGUOUS_P))
    else:
        keep_far = bool(tested and cmp["p"] < CLEAR_P)
        # The data lean beyond the stated error without clear evidence.
        info["ambiguous"] = bool(distinct and not keep_far and cmp["mean_px"] > 0.0)
    kept, other = (far, near) if keep_far else (near, far)
    info.update(kept="far" if keep_far else "near", alternative=[float(v) for v in other[:6]])
    # Every n of the front starts again from the optimum kept (a front polished solution by
    # solution may straddle both basins). A front whose every solution is nearer the basin
    # kept than the other was explored there already (as a rule the search's basin was kept):
    # each n is only polished again; otherwise the whole front is rebuilt around it.
    rebuild = not np.all(displacement_px(objective, kept, X) < displacement_px(objective, other, X))
    info["rebuilt"] = bool(rebuild)
    ns = np.unique(X[:, 6])
    Xn = np.column_stack([np.tile(kept[:6], (len(ns), 1)), ns])
    Xn, Fn, ev = polish_front(objective, Xn, objective.evaluate(Xn), search, n_min, n_max,
                               polish_iters, explore=rebuild)
    return Xn, Fn, info, evals + ev + len(Xn)
