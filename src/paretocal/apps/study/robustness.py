"""Robustness of the calibration to the weights of the Chamfer's edge and intensity terms.

The paper sweeps ``w1 = 0.1 ... 0.9`` (depth-edge term) with ``w2 = 1 - w1`` (reflectance-edge
term). Each weight is calibrated from the same start with several seeds; the final objective
and, when the dataset has a reference, the errors against it are recorded.
"""

from __future__ import annotations

import itertools
import time

import numpy as np

from ...geometry import pose_error


def weight_sweep(frames, T_init: np.ndarray, settings, weights, seeds,
                 progress=None) -> list[dict]:
    """Calibrate for every (w1, seed) pair.

    Parameters
    ----------
    frames : list of Frame
    T_init : ndarray, shape (4, 4)
    settings : Settings
        Base settings; ``objective.w_edge`` and ``search.seed`` are replaced per run.
    weights : sequence of float
        Values of w1 in [0, 1].
    seeds : sequence of int
    progress : callable, optional
        ``progress(done, total)``.

    Returns
    -------
    list of dict
        Per run: ``w1``, ``w2``, ``seed``, ``f1`` (chosen solution), ``n``, ``x`` (correction,
        shape (6,)), ``T`` (4, 4), reference errors (``rotation_deg``, ``translation_cm``,
        per axis) when known, ``wall_s``.
    """
    from ...pipeline import calibrate

    runs = list(itertools.product(weights, seeds))
    rows = []
    for k, (w1, seed) in enumerate(runs):
        t0 = time.perf_counter()
        s = settings.replace(objective={"w_edge": float(w1)}, search={"seed": int(seed)})
        r = calibrate(frames, T_init, s, dataset_options=False)    # the study's settings
        row = {"w1": float(w1), "w2": round(1.0 - float(w1), 6), "seed": int(seed),
               "f1": float(r.front.F[r.chosen, 0]), "n": r.n_points,
               "x": r.front.X[r.chosen, :6].copy(), "T": r.T_cam_lidar,
               "wall_s": time.perf_counter() - t0}
        if r.reference_error is not None:
            row.update(r.reference_error)
        rows.append(row)
        if progress is not None:
            progress(k + 1, len(runs))
    return rows


def summarise_sweep(rows: list[dict]) -> dict:
    """Per weight: median f1, reference errors and seed-to-seed spread; and the best weight.

    The best weight has the lowest median of ``rotation_deg / 1 deg + translation_cm / 10 cm``
    when a reference is known; otherwise the most repeatable one, the lowest mean pairwise
    disagreement between its seeds' extrinsics (same units).
    """
    weights = sorted({r["w1"] for r in rows})
    per = []
    for w in weights:
        rs = [r for r in rows if r["w1"] == w]
        pair = [pose_error(a["T"], b["T"]) for a, b in itertools.combinations(rs, 2)]
        spread = (float(np.mean([p["rotation_deg"] + p["translation_cm"] / 10 for p in pair]))
                  if pair else float("nan"))
        d = {"w1": w, "runs": len(rs), "f1_median": float(np.median([r["f1"] for r in rs])),
             "seed_spread": spread}
        if "rotation_deg" in rs[0]:
            rot = np.array([r["rotation_deg"] for r in rs])
            tr = np.array([r["translation_cm"] for r in rs])
            d.update({"rotation_deg_median": float(np.median(rot)),
                      "rotation_deg_max": float(rot.max()),
                      "translation_cm_median": float(np.median(tr)),
                      "translation_cm_max": float(tr.max()),
                      "score": float(np.median(rot / 1.0 + tr / 10.0))})
        else:
            d["score"] = spread
        per.append(d)
    finite = [d for d in per if np.isfinite(d["score"])]
    best = min(finite, key=lambda d: d["score"])["w1"] if finite else None
    basis = ("median rotation_deg + translation_cm / 10 against the reference"
             if per and "rotation_deg_median" in per[0] else "seed-to-seed spread")
    return {"per_weight": per, "best_w1": best, "basis": basis}
