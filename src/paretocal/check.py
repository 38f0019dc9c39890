"""Is a given extrinsic calibrated? A verdict without ground truth (``paretocal check``).

The extrinsic is scored against its 3^6 - 1 grid neighbours (Levinson & Thrun's test: a
correct calibration is a local minimum of the edge objective, so few neighbours score better),
and the objective is polished locally from it. A correct extrinsic stays put up to the
objective's own bias; a miscalibrated one moves towards the optimum. The verdict compares how far
it moves with tolerances halfway between that bias and the errors worth flagging: on the KITTI
sample the reference moved 0.12 deg / 1.5 cm (2.7 px), extrinsics perturbed by 1 deg or 10 cm on
one axis moved 0.9-1.1 deg or 7-10 cm (4.6-15.6 px), so 0.5 deg / 5 cm are the defaults.
"""

from __future__ import annotations

import numpy as np

from .config import Settings
from .geometry import pose_error
from .io.frame import Frame
from .quality import (displacement_px, local_optimum, neighbour_fraction, pixel_fd_step,
                      quality_report)

NEIGHBOUR_STEP = np.array([0.05, 0.05, 0.05, 0.5, 0.5, 0.5])   # m and deg


def check_extrinsic(frames: list[Frame], T: np.ndarray, settings: Settings | None = None,
                    rot_tol_deg: float = 0.5, trans_tol_cm: float = 5.0,
                    progress=None) -> dict:
    """Check ``T`` (4, 4) on ``frames``.

    ``progress(stage, done, total)``, if given, is told of the feature extraction per frame
    and of the three steps after it (neighbours, local optimum, quality report).

    Returns
    -------
    dict
        ``verdict`` ("calibrated" or "miscalibrated"), ``score`` (the move to the local optimum
        relative to the tolerances; above 1 is miscalibrated), ``moved`` (deg, cm, px),
        ``neighbour_fraction`` and ``best_neighbour_gain_px``, ``T_checked`` (``T``),
        ``T_local_optimum``, the
        ``quality`` report at the local optimum, and ``weak`` with ``notes``: True when the
        check itself has too little to go on (fewer frames than a calibration needs to be
        trusted), with what to do.
    """
    from .inputs import prepare_lidar
    from .stage import Stage, feature_counts

    settings = (settings or Settings()).validate()
    T = np.asarray(T, dtype=np.float64)
    def tick(stage, done, total):
        if progress is not None:
            progress(stage, done, total)

    # The LiDAR steps of a calibration (the sensor located in its cloud, the rings, the
    # sweeps de-skewed): without them a cloud stored in a vehicle frame gives noise for edges.
    lidar = prepare_lidar(frames, settings, [(frames[0].camera, T)])
    stage = Stage(lidar.frames, T, T, settings, lambda d, t: tick("features", d, t),
                  rings=lidar.rings)
    obj = stage.objective
    x0 = np.zeros(7)
    x0[6] = stage.n_max
    frac, gain = neighbour_fraction(obj, x0, NEIGHBOUR_STEP)
    tick("check", 1, 3)
    xo = local_optimum(obj, x0)
    tick("check", 2, 3)
    T_opt = obj.transforms(xo[None])[0]
    move = pose_error(T_opt, T)
    moved = {"rotation_deg": float(move["rotation_deg"]),
             "translation_cm": float(move["translation_cm"]),
             "pixels": displacement_px(obj, x0, xo)}
    score = max(moved["rotation_deg"] / rot_tol_deg, moved["translation_cm"] / trans_tol_cm)
    quality = quality_report(obj, xo, pixel_fd_step(obj, xo))
    tick("check", 3, 3)
    from .pipeline import RELIABLE_MIN_FRAMES

    notes = []
    if len(frames) < RELIABLE_MIN_FRAMES:
        notes.append(f"only {len(frames)} frame(s): the check itself is weak (one scene's "
                     "biases can move a correct extrinsic or hold a wrong one); check on at "
                     f"least {RELIABLE_MIN_FRAMES} frames of varied scenes")
    return {
        "weak": bool(notes),
        "notes": notes,
        "verdict": "miscalibrated" if score > 1.0 else "calibrated",
        "score": float(score),
        "tolerances": {"rotation_deg": rot_tol_deg, "translation_cm": trans_tol_cm},
        "moved": moved,
        "neighbour_fraction": frac,
        "best_neighbour_gain_px": gain,
        "neighbour_step": {"translation_cm": 5.0, "rotation_deg": 0.5},
        "T_checked": T.tolist(),
        "T_local_optimum": T_opt.tolist(),
        "quality": quality.to_dict(),
        "frames": [f.name for f in frames],
        "features": feature_counts(stage.feats),
    }
