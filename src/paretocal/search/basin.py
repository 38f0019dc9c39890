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

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import SearchSettings
from ..objective.objective import AlignmentObjective, PopulationObjective
from ..quality import cm_written, displacement_px, local_optimum
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


@dataclass(frozen=True)
class BasinTest:
    """The near/far basin test of a polished front (:func:`prefer_near`): the local optimum
    next to the start ("near") against the one of the front's best solution ("far"). The
    figures are held as ``result.json`` writes them (``decision.basin``), rounded.

    Attributes
    ----------
    separation_px : float
        Mean displacement of the feature points between the two optima (px, 3 decimals).
    separation_deg : float
        Rotation between them (deg, 4 decimals).
    separation_m : float
        Translation between them (m; written in cm, 3 decimals).
    departure_near, departure_far : float
        How far each lies from the start in units of the stated initial error (3 decimals;
        :func:`departure`).
    ambiguous : bool
        Two distinct optima the frames do not tell apart (module docstring).
    same_basin : bool
        One basin: the objective cannot separate them.
    kept : str
        ``"near"`` or ``"far"``.
    mean_px, se_px, t, p : float or None
        The paired comparison of two basins (:func:`paired_preference`, 4 decimals; ``mean_px``
        positive when "far" fits better, ``p`` one-sided; NaN where there is no test); None
        for one basin.
    frames, frames_far_better : int or None
        Frames compared, and those that prefer "far"; None for one basin.
    alternative : ndarray, shape (6,), or None
        The correction of the optimum not kept (m, deg); None for one basin.
    rebuilt : bool or None
        Whether the whole front was rebuilt around the optimum kept; None for one basin.
    """

    separation_px: float
    separation_deg: float
    separation_m: float
    departure_near: float
    departure_far: float
    ambiguous: bool
    same_basin: bool
    kept: str
    mean_px: float | None = None
    se_px: float | None = None
    t: float | None = None
    p: float | None = None
    frames: int | None = None
    frames_far_better: int | None = None
    alternative: np.ndarray | None = None
    rebuilt: bool | None = None

    def to_dict(self) -> dict[str, Any]:
        """As ``result.json`` writes it (``decision.basin``; the separation in cm)."""
        out: dict[str, Any] = {
            "separation_px": float(self.separation_px),
            "separation_deg": float(self.separation_deg),
            "separation_cm": cm_written(self.separation_m, 3),
            "departure_near": float(self.departure_near),
            "departure_far": float(self.departure_far),
            "ambiguous": bool(self.ambiguous), "same_basin": bool(self.same_basin)}
        if self.frames is not None:
            out.update(mean_px=self.mean_px, se_px=self.se_px, t=self.t, p=self.p,
                       frames=int(self.frames), frames_far_better=self.frames_far_better)
        out["kept"] = self.kept
        if self.alternative is not None:
            out["alternative"] = [float(v) for v in self.alternative]
        if self.rebuilt is not None:
            out["rebuilt"] = bool(self.rebuilt)
        return out

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "BasinTest":
        """Read back from :meth:`to_dict`'s form (``result.json``'s ``decision.basin``)."""
        def opt(key, kind):
            v = doc.get(key)
            return None if v is None else kind(v)

        alt = doc.get("alternative")
        return cls(separation_px=float(doc["separation_px"]),
                   separation_deg=float(doc["separation_deg"]),
                   separation_m=float(doc["separation_cm"]) / 100.0,
                   departure_near=float(doc["departure_near"]),
                   departure_far=float(doc["departure_far"]),
                   ambiguous=bool(doc.get("ambiguous", False)),
                   same_basin=bool(doc.get("same_basin", False)), kept=str(doc["kept"]),
                   mean_px=opt("mean_px", float), se_px=opt("se_px", float),
                   t=opt("t", float), p=opt("p", float), frames=opt("frames", int),
                   frames_far_better=opt("frames_far_better", int),
                   alternative=None if alt is None else np.array(alt, dtype=np.float64),
                   rebuilt=opt("rebuilt", bool))


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
                polish_iters: int) -> tuple[np.ndarray, np.ndarray, BasinTest, int]:
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
    info : BasinTest
        Whether they are one basin, their separation, the paired comparison,
        ``departure_near`` and ``departure_far`` (in units of the stated initial error),
        ``kept`` ("near" or "far"), ``ambiguous``, and when they are two basins the
        ``alternative`` (the correction of the pose not kept, m and deg) and ``rebuilt`` (the
        whole front rebuilt).
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
    info = BasinTest(separation_px=round(float(sep_px), 3),
                     separation_deg=round(float(e["rotation_deg"]), 4),
                     separation_m=round(float(e["translation_cm"]), 3) / 100.0,
                     departure_near=round(departure(near, s.init_error_deg, s.init_error_m), 3),
                     departure_far=round(departure(far, s.init_error_deg, s.init_error_m), 3),
                     ambiguous=False, same_basin=True, kept="far")
    limit = SAME_BASIN_SHARE * objective.scene.truncation_px
    if sep_px <= limit:
        return X, F, info, evals
    cmp = paired_preference(objective, near, far)
    tested = cmp["frames"] >= MIN_FRAMES and np.isfinite(cmp["p"])
    distinct = (e["rotation_deg"] > USABLE_DEG) or (e["translation_cm"] > 100 * USABLE_M)
    if info.departure_far <= 1.0:
        # Inside the stated error the data decide.
        keep_far = cmp["mean_px"] >= 0.0
        p_kept = cmp["p"] if keep_far else 1.0 - cmp["p"]
        ambiguous = bool(distinct and (not tested or p_kept >= AMBIGUOUS_P))
    else:
        keep_far = bool(tested and cmp["p"] < CLEAR_P)
        # The data lean beyond the stated error without clear evidence.
        ambiguous = bool(distinct and not keep_far and cmp["mean_px"] > 0.0)
    kept, other = (far, near) if keep_far else (near, far)
    # Every n of the front starts again from the optimum kept (a front polished solution by
    # solution may straddle both basins). A front whose every solution is nearer the basin
    # kept than the other was explored there already (as a rule the search's basin was kept):
    # each n is only polished again; otherwise the whole front is rebuilt around it.
    rebuild = not np.all(displacement_px(objective, kept, X) < displacement_px(objective, other, X))
    info = dataclasses.replace(
        info, ambiguous=ambiguous, same_basin=False, kept="far" if keep_far else "near",
        mean_px=round(cmp["mean_px"], 4), se_px=round(cmp["se_px"], 4), t=round(cmp["t"], 4),
        p=round(cmp["p"], 4), frames=cmp["frames"], frames_far_better=cmp["frames_far_better"],
        alternative=np.array(other[:6], dtype=np.float64), rebuilt=bool(rebuild))
    ns = np.unique(X[:, 6])
    Xn = np.column_stack([np.tile(kept[:6], (len(ns), 1)), ns])
    Xn, Fn, ev = polish_front(objective, Xn, objective.evaluate(Xn), search, n_min, n_max,
                               polish_iters, explore=rebuild)
    return Xn, Fn, info, evals + ev + len(Xn)
