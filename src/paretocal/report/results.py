"""Writing a calibration run: result.json, pareto.csv, extrinsic.yaml, exports and figures.

The exports (:mod:`paretocal.io.exports`) are the chosen extrinsic as KITTI ``calib_velo_to_cam.txt``, ROS
``tf_static.yaml`` and its inverse ``extrinsic_inverse.yaml``.

Every file is written atomically (temporary file, then rename).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from ..io.atomic import atomic_write_text
from ..io.exports import kitti_rect_of, write_exports
from ..io.extrinsic import write_extrinsic
from ..io.frame import Frame
from ..search.problem import VARIABLES

FRONT_CSV_FIXED = list(VARIABLES) + ["chamfer", "cost", "t_norm", "m_norm", "ms", "bytes"]


def front_csv(result) -> str:
    """``pareto.csv`` text: one row per front solution, the chosen one flagged."""
    front = result.front
    cols = front.columns
    extra = [k for k in ("chamfer_holdout", "deviation_px", "points", "edge_px",
                         "intensity_px", "smooth_px", "sampling_se", "in_view") if k in cols]
    ref = [k for k in cols if k.startswith("ref_")]
    header = FRONT_CSV_FIXED + extra + ref + ["chosen"]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for i in range(len(front.X)):
        x = front.X[i]
        row = [f"{v:.6f}" for v in x[:6]] + [str(int(round(x[6])))]
        row += [f"{front.F[i, 0]:.6f}", f"{front.F[i, 1]:.6f}",
                f"{cols['t_norm'][i]:.6f}", f"{cols['m_norm'][i]:.6f}",
                f"{cols['ms'][i]:.6g}", str(int(round(cols['bytes'][i])))]
        row += [f"{cols[k][i]:.6g}" for k in extra + ref]
        row.append("1" if i == result.chosen else "0")
        w.writerow(row)
    return buf.getvalue()


def partial_front_csv(X: np.ndarray, F: np.ndarray) -> str:
    """CSV of an interrupted search's non-dominated set: the seven variables, f1 and f2."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(list(VARIABLES) + ["chamfer", "cost"])
    for x, f in zip(X, F):
        w.writerow([f"{v:.6f}" for v in x[:6]] + [str(int(round(x[6]))), f"{f[0]:.6f}",
                                                 f"{f[1]:.6f}"])
    return buf.getvalue()


def strict_json(doc):
    """``doc`` with every number that is not finite (NaN, infinity) as None, numpy values as
    Python's: what ``json.dumps(..., allow_nan=False)`` writes as standard JSON (a one-frame
    run's jackknife has no value; strict JSON readers refuse the ``NaN`` token)."""
    if isinstance(doc, dict):
        return {k: strict_json(v) for k, v in doc.items()}
    if isinstance(doc, (list, tuple)):
        return [strict_json(v) for v in doc]
    if isinstance(doc, np.ndarray):
        return strict_json(doc.tolist())
    if isinstance(doc, np.generic):
        doc = doc.item()
    if isinstance(doc, float) and not np.isfinite(doc):
        return None
    return doc


def dumps(doc, indent: int = 2) -> str:
    """Standard JSON text of ``doc`` (:func:`strict_json`), with a final newline."""
    return json.dumps(strict_json(doc), indent=indent, allow_nan=False) + "\n"


def write_outputs(result, out_dir: str | Path, frames: list[Frame] | None = None,
                  figures: bool = True, overlay_frame: int = 0) -> list[Path]:
    """Write a run's output files into ``out_dir``, beside whatever it holds; returns the
    paths written. A run folder is written whole by :func:`paretocal.write_run`
    (:mod:`paretocal.rundir`), which stages these files and replaces a previous run's.

    Parameters
    ----------
    result : CalibrationResult
        The calibration (:func:`paretocal.calibrate`).
    out_dir : str or Path
        The run folder (made when missing).
    frames : list of Frame, optional
        The frames calibrated: needed for the overlays and ``interactive.html``.
    figures : bool
        Write ``pareto.png``, the overlays and ``interactive.html``.
    overlay_frame : int
        The index of the frame the overlays show.

    Returns
    -------
    list of Path
        The files written (docs/conventions.md section 3).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    doc = result.to_dict()
    atomic_write_text(out / "result.json", dumps(doc))
    written.append(out / "result.json")
    atomic_write_text(out / "pareto.csv", front_csv(result))
    written.append(out / "pareto.csv")
    write_extrinsic(out / "extrinsic.yaml", result.T_cam_lidar,
                    comment=f"paretocal {doc['version']}: chosen T_cam_lidar (LiDAR -> camera), "
                            f"rule {result.decision.rule}, n = {result.n_points}")
    written.append(out / "extrinsic.yaml")
    written += write_exports(out, result.T_cam_lidar, kitti_rect_of(frames), str(doc["version"]))
    if figures:
        from .figures import overlay_figure, pareto_figure

        pareto_figure(result, out / "pareto.png")
        written.append(out / "pareto.png")
        if frames:
            f = frames[min(overlay_frame, len(frames) - 1)]
            z_min = result.settings.features.z_min
            overlay_figure(f, result.T_init, out / "overlay_before.png",
                           f"before: initial extrinsic (frame {f.name})", z_min)
            overlay_figure(f, result.T_cam_lidar, out / "overlay_after.png",
                           f"after: chosen calibration, n = {result.n_points} (frame {f.name})",
                           z_min)
            written += [out / "overlay_before.png", out / "overlay_after.png"]
            if result.T_ref is not None:
                overlay_figure(f, result.T_ref, out / "overlay_reference.png",
                               f"dataset reference extrinsic (frame {f.name})", z_min)
                written.append(out / "overlay_reference.png")
            from .interactive import write_interactive
            written.append(write_interactive(result, frames, out / "interactive.html", overlay_frame))
    return written
