"""Near or far: a pose far from the start replaces the start's own basin only on clear evidence.

The search looks over the whole box the stated initial error allows, and on some scenes it finds
a pose far from the start that scores a little better than the optimum next to the start: with
two frames of one scene, a rotation of 20 degrees can align a few long edges by chance. Which
basin the data support is a question about frames, not about one number: each frame is an
independent look at the scene, so the per-frame difference of the objective between the two
poses is a paired sample. The far pose is taken only when its advantage is clear: a one-sided
paired t test at level :data:`CLEAR_P` (with two frames that needs t > 32, with twenty t > 2.5).
Otherwise the front is rebuilt around the start's basin and the alternative is reported, so
that the verdict can say that the data could not tell the two apart.
"""

from __future__ import annotations

import numpy as np

from ..quality import displacement_px, local_optimum
from .refine import polish_front

#: One-sided p value of the paired t test (per-frame objective differences) below which the
#: data "clearly prefer" the far pose.
CLEAR_P = 0.01
#: With one frame there is no test: the start's basin is kept.
MIN_FRAMES = 2
#: Two poses whose projections differ by less than this share of the distance-transform
#: truncation are one basin: the objective cannot separate them.
SAME_BASIN_SHARE = 0.25


def paired_preference(objective, near: np.ndarray, far: np.ndarray) -> dict:
    """Per-frame comparison of two poses (7,) at every point, without the sampling charge.

    Returns ``mean_px`` (mean advantage of ``far``, positive when it scores lower), ``se_px``,
    ``t`` and its one-sided ``p`` (NaN with fewer than two frames), and ``frames_far_better``.
    """
    from scipy.stats import t as student_t

    saved = objective.ucb_k
    objective.ucb_k = 0.0
    try:
        per = objective.chamfer(np.vstack([near, far]))["per_frame"]          # (2, F)
    finally:
        objective.ucb_k = saved
    d = per[0] - per[1]
    k = len(d)
    mean = float(d.mean())
    se = float(d.std(ddof=1) / np.sqrt(k)) if k > 1 else float("nan")
    t = mean / se if k > 1 and se > 0 else (float("inf") * np.sign(mean) if k > 1 else float("nan"))
    p = float(student_t.sf(t, k - 1)) if k > 1 and np.isfinite(t) else (
        0.0 if k > 1 and t > 0 else float("nan"))
    return {"mean_px": mean, "se_px": se, "t": float(t), "p": p, "frames": k,
            "frames_far_better": int((d > 0).sum())}


def prefer_near(objective, X: np.ndarray, F: np.ndarray, settings, n_min: int,
                n_max: int) -> tuple[np.ndarray, np.ndarray, dict, int]:
    """Keep the start's basin unless the frames clearly prefer the front's best pose.

    Parameters
    ----------
    objective : CalibrationObjective
    X, F : ndarray, shapes (k, 7) and (k, 2)
        The polished front.
    settings : Settings
    n_min, n_max : int

    Returns
    -------
    X, F : ndarray
        The front, rebuilt around the start's basin when the far pose was not clearly better.
    info : dict
        ``same_basin`` (bool), ``separation_px``, ``separation_deg``, ``separation_cm``, the
        paired comparison (``t``, ``mean_px``, ...), ``kept`` ("near" or "far") and
        ``alternative`` (the correction of the pose not kept, m and deg).
    evaluations : int
    """
    from ..geometry import pose_error

    best = X[np.argmin(F[:, 0])].copy()
    best[6] = n_max
    start = np.zeros(7)
    start[6] = n_max
    near = local_optimum(objective, start)
    far = local_optimum(objective, best)
    evals = 2 * 400                                       # polish budget, order of magnitude
    sep_px = displacement_px(objective, near, far)
    T = objective.transforms(np.vstack([near, far]))
    e = pose_error(T[1], T[0])
    info = {"separation_px": round(float(sep_px), 3),
            "separation_deg": round(float(e["rotation_deg"]), 4),
            "separation_cm": round(float(e["translation_cm"]), 3)}
    limit = SAME_BASIN_SHARE * objective.scene.truncation_px
    if sep_px <= limit:
        info.update(same_basin=True, kept="far")
        return X, F, info, evals
    cmp = paired_preference(objective, near, far)
    info.update(same_basin=False, **{k: (round(v, 4) if isinstance(v, float) else v)
                                     for k, v in cmp.items()})
    clear = cmp["frames"] >= MIN_FRAMES and np.isfinite(cmp["p"]) and cmp["p"] < CLEAR_P
    if clear:
        info.update(kept="far", alternative=[float(v) for v in near[:6]])
        return X, F, info, evals
    # Rebuild the front around the start's basin: every n of the front starts from ``near``.
    ns = np.unique(X[:, 6])
    Xn = np.column_stack([np.tile(near[:6], (len(ns), 1)), ns])
    Xn, Fn, ev = polish_front(objective, Xn, objective.evaluate(Xn), settings, n_min, n_max)
    info.update(kept="near", alternative=[float(v) for v in far[:6]])
    return Xn, Fn, info, evals + ev + len(Xn)
