"""Several cameras, one LiDAR, one run: every camera of a rig folder calibrated, and what the
results imply together.

A rig folder's calib.yaml lists its cameras (:func:`paretocal.io.rig_cameras`). Each camera is
calibrated into its own run folder ``OUT/<name>/`` (:func:`paretocal.rundir.calibrate_run`: a
normal, resumable run folder); every point cloud is read once and the LiDAR-only steps (the
LiDAR located in its cloud, the rings, the motion compensation) are done once for all cameras
over the same clouds (:func:`paretocal.inputs.prepare_lidar`). ``OUT/rig.json`` then holds,
per camera, the chosen extrinsic and its verdict, and for each pair of cameras:

* the camera-to-camera extrinsic the two results imply, ``T_camA_camB = T_camA_lidar @
  inv(T_camB_lidar)``, and how far it is from the pair the initial extrinsics imply and, when
  the runs started elsewhere than calib.yaml, from the pair calib.yaml's extrinsics imply (the
  reference);
* the overlap: the share of the LiDAR points in view of either camera (at the chosen
  extrinsics) that are in view of both;
* where they overlap, a consistency check: the two calibrations agree when the
  camera-to-camera extrinsic they imply differs from calib.yaml's (the pair the rig states)
  by no more, per axis, than the two runs' 95 % intervals combined. Each run's true extrinsic
  lies within ``T @ D(d)``, ``|d_axis| <= h_axis`` (:func:`paretocal.verdict.intervals`), so
  the stated pair differs from the implied one by ``D(d_A) D(d_B)^-1``, whose axes are about
  ``d_A - d_B``; with independent errors, each within ``sqrt(h_A^2 + h_B^2)`` (95 %). The
  check is only as good as calib.yaml's camera-to-camera extrinsic: it tests whether the two
  calibrations moved the LiDAR alike relative to a rig whose cameras kept their relative pose.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from itertools import combinations
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import project
from ..config import Settings, dataset_settings
from ..errors import Interrupted, ParetocalError, SettingsError
from ..geometry import correction_params, invert, pose_error
from ..inputs import joint_camera, rig_lidar_steps
from ..io import load_rig_frames, rig_cameras, write_extrinsic
from ..io.atomic import atomic_write_text
from ..report.results import dumps
from ..quality import AXES
from ..result import CalibrationResult
from ..rundir import calibrate_run, check_inner_run_folder

log = logging.getLogger(__name__)

RIG_JSON = "rig.json"
#: What a camera's (or the joint) run folder in a rig's --out is, for messages.
RUN_FOLDER = "a rig camera's run folder"


def calibrate_rig(  # noqa: PLR0913 - dataset_options and joint are keyword-only
        source: str | Path, out: str | Path, settings: Settings | None = None,
        T_inits: dict[str, np.ndarray] | None = None,
        cameras: list[str] | None = None, figures: bool = True,
        checkpoint_every: int = 5, progress=None, on_camera=None, *,
        dataset_options: bool = True, joint: bool = False) -> dict:
    """Calibrate the cameras of the rig folder ``source`` into ``out/<name>/`` and write
    ``out/rig.json`` (when more than one camera was calibrated).

    Parameters
    ----------
    source : path
        A rig folder (:func:`paretocal.io.rig_cameras`).
    out : path
    settings : Settings, optional
        The same settings for every camera; what calib.yaml states (``init_error``) replaces
        the defaults these leave (:func:`~paretocal.config.dataset_settings`).
    T_inits : dict, optional
        Initial ``T_cam_lidar`` by camera name; calib.yaml's for the cameras not in it.
    cameras : list of str, optional
        The cameras to calibrate (all by default).
    figures, checkpoint_every, progress
        As for :func:`paretocal.rundir.calibrate_run`.
    on_camera : callable, optional
        ``on_camera(name, result)`` after each camera's run (for a line on the console).
    dataset_options : bool
        False: the settings are final (they state ``init_error`` even where it is the
        default).
    joint : bool
        Calibrate the cameras at once into ``out/joint/``: one correction of the LiDAR shared
        by every camera, the cameras' relative poses kept as calib.yaml states them
        (:func:`paretocal.inputs.joint_frames`); ``T_inits`` may then hold the first
        camera's only. rig.json is written also for one camera.

    Returns
    -------
    dict
        What rig.json holds (also when it is not written: one camera).
    """
    source, out = Path(source), Path(out)
    found = rig_cameras(source)
    # Once for every camera; each run then takes the settings as they are.
    settings = dataset_settings(settings, found[0][1].options, dataset_options).validate()
    names = [n for n, _ in found]
    T_inits = dict(T_inits or {})
    unknown = sorted(set(cameras or ()) - set(names)) + sorted(set(T_inits) - set(names))
    if unknown:
        raise SettingsError(f"camera {unknown[0]!r}: {source / 'calib.yaml'} lists the cameras "
                            f"{', '.join(names)}")
    if cameras:
        found = [(n, s) for n, s in found if n in cameras]
    # The rig makes its cameras' run folders: one that is a link leads the run elsewhere.
    for name in [JOINT_RUN] if joint else [n for n, _ in found]:
        check_inner_run_folder(out / name, RUN_FOLDER)
    t0 = time.perf_counter()
    if joint:
        return _calibrate_joint(source, out, settings, T_inits, [n for n, _ in found],
                                figures, checkpoint_every, progress, on_camera, t0)
    frames = load_rig_frames(found, settings.frames)
    steps = rig_lidar_steps(frames, settings, T_inits)
    results: dict[str, CalibrationResult] = {}
    for name, _ in found:
        try:
            results[name] = calibrate_run(source, out / name, T_inits.get(name), settings,
                                          frames=frames[name], figures=figures,
                                          checkpoint_every=checkpoint_every,
                                          progress=progress, rig_camera=name,
                                          lidar=steps[name], dataset_options=False)
        except Interrupted as exc:
            exc.run_dir = out / name       # the run folder to resume
            raise
        except ParetocalError as exc:
            # The cameras done so far keep their run folders; say which camera failed.
            raise type(exc)(f"camera {name}: {exc}") from None
        if on_camera is not None:
            on_camera(name, results[name])
    summary = rig_summary(results, settings.features.z_min)
    summary.update(source=str(source.resolve()),
                   lidar_steps_done=len({id(v) for v in steps.values()}),
                   wall_s=round(time.perf_counter() - t0, 2))
    if len(results) > 1:
        atomic_write_text(out / RIG_JSON, dumps(summary, indent=1))
    return summary


JOINT_RUN = "joint"


def _calibrate_joint(source: Path, out: Path, settings: Settings, T_inits: dict,
                     names: list[str], figures: bool, checkpoint_every: int, progress,
                     on_camera, t0: float) -> dict:
    """:func:`calibrate_rig` with ``joint``: one run over every camera's frames."""
    other = sorted(set(T_inits) - {names[0]})
    if other:
        raise SettingsError(f"camera {other[0]}: a joint calibration starts from the first "
                            f"camera's extrinsic ({names[0]}); the others keep their poses "
                            "relative to it as calib.yaml states them")
    try:
        result = calibrate_run(source, out / JOINT_RUN, T_inits.get(names[0]), settings,
                               figures=figures, checkpoint_every=checkpoint_every,
                               progress=progress, dataset_options=False, joint=names)
    except Interrupted as exc:
        exc.run_dir = out / JOINT_RUN
        raise
    if on_camera is not None:
        for name in names:
            on_camera(name, result)
    return write_joint_summary(result, out / JOINT_RUN, names, source,
                               wall_s=round(time.perf_counter() - t0, 2))


def write_joint_summary(result: CalibrationResult, run_dir: str | Path, names: list[str],
                        source: str | Path, **extra) -> dict:
    """Write rig.json beside the joint run folder ``run_dir`` (:func:`joint_summary`, with
    the rig folder ``source`` and ``extra``) and each camera's extrinsic as
    ``extrinsic_<name>.yaml``; return rig.json's content."""
    run_dir = Path(run_dir)
    summary = joint_summary(result, names)
    summary.update(source=str(Path(source).resolve()), **extra)
    verdict = None if result.reliability is None else result.reliability.verdict
    for cam in summary["cameras"]:
        # Each camera's extrinsic as a file of its own (an --init file), beside rig.json.
        write_extrinsic(run_dir.parent / cam["extrinsic_file"], np.asarray(cam["T_cam_lidar"]),
                        f"camera {cam['name']} of a joint calibration ({run_dir.name}/); "
                        f"verdict {verdict}")
    atomic_write_text(run_dir.parent / RIG_JSON, dumps(summary, indent=1))
    return summary


def joint_summary(result: CalibrationResult, names: list[str]) -> dict:
    """rig.json's content for a joint run: every camera's extrinsic (its mount on the first
    camera's result) and the name of the file :func:`write_joint_summary` writes it to, the
    shared verdict and intervals; no pairs (their relative poses are calib.yaml's)."""
    mounts: dict[str, np.ndarray] = {}
    for f in result.sweeps or []:
        mounts.setdefault(joint_camera(f.name),
                          np.eye(4) if f.camera.mount is None else f.camera.mount)
    cams = []
    for name in names:
        M = mounts[name]
        T, T0 = M @ result.T_cam_lidar, M @ result.T_init
        ref = None if result.T_ref is None else _err(T, M @ result.T_ref)
        cams.append({"name": name, "run": JOINT_RUN, "extrinsic_file": f"extrinsic_{name}.yaml",
                     "T_cam_lidar": _matrix(T),
                     "T_init": _matrix(T0), "T_camera_first": _matrix(M),
                     **_verdict_record(result), "reference_error": ref,
                     "intervals_95": _half_widths(result)})
    return {"joint": True, "cameras": cams, "pairs": [],
            "frames_per_camera": {n: sum(joint_camera(f) == n for f in result.frames)
                                  for n in names}}


def _verdict_record(result: CalibrationResult) -> dict:
    """A camera's ``verdict`` and ``reasons`` in rig.json (None and none without a verdict)."""
    rel = result.reliability
    return {"verdict": None if rel is None else rel.verdict,
            "reasons": [] if rel is None else list(rel.reasons)}


def _half_widths(result: CalibrationResult) -> dict[str, float | None] | None:
    """The half-widths of a run's 95 % intervals by axis, cm and deg as result.json writes
    them (None per axis not determined); None without intervals (not judged ok)."""
    iv = None if result.reliability is None else result.reliability.intervals
    return None if iv is None else iv.half_width_report()


def _err(T: np.ndarray, T_ref: np.ndarray) -> dict:
    e = pose_error(T, T_ref)
    return {k: round(float(e[k]), 4) for k in ("rotation_deg", "translation_cm")}


def _matrix(T: np.ndarray) -> list:
    return [[round(float(v), 9) for v in row] for row in np.asarray(T)]


def camera_record(name: str, result: CalibrationResult) -> dict:
    """One camera's line of rig.json."""
    ref = result.reference_error
    return {"name": name, "run": name, "T_cam_lidar": _matrix(result.T_cam_lidar),
            "T_init": _matrix(result.T_init), **_verdict_record(result),
            "reference_error": None if ref is None else {
                k: round(float(ref[k]), 4) for k in ("rotation_deg", "translation_cm")},
            "intervals_95": _half_widths(result)}


def overlap(a: CalibrationResult, b: CalibrationResult, z_min: float) -> dict:
    """LiDAR points in view of camera ``a`` and of camera ``b`` at their chosen extrinsics,
    over the frames both runs used (``a``'s de-skewed sweeps), and the share of those in view
    of either that are in view of both."""
    sweeps_b = {f.name: f for f in b.sweeps or []}
    both = either = in_a = in_b = 0
    for fa in a.sweeps or []:
        fb = sweeps_b.get(fa.name)
        if fb is None or fb.points_path != fa.points_path:
            continue
        va = _seen(fa, a.T_cam_lidar, z_min)
        vb = _seen(dataclasses.replace(fb, points=fa.points), b.T_cam_lidar, z_min)
        both += int(np.count_nonzero(va & vb))
        either += int(np.count_nonzero(va | vb))
        in_a += int(np.count_nonzero(va))
        in_b += int(np.count_nonzero(vb))
    return {"points_in_view_a": in_a, "points_in_view_b": in_b, "points_in_both": both,
            "share_of_either": round(both / either, 4) if either else 0.0}


def _seen(frame, T: np.ndarray, z_min: float) -> np.ndarray:
    """Points of ``frame`` that project into its image at ``T`` onto a usable pixel."""
    uv, _, visible = project(frame.points, frame.camera, T, z_min)
    if frame.mask is not None and visible.any():
        idx = np.flatnonzero(visible)
        u = np.clip(np.round(uv[idx, 0]).astype(int), 0, frame.camera.width - 1)
        v = np.clip(np.round(uv[idx, 1]).astype(int), 0, frame.camera.height - 1)
        visible = visible.copy()
        visible[idx] = frame.mask[v, u]
    return visible


def consistency(a: CalibrationResult, b: CalibrationResult, T_pair: np.ndarray,
                against: str) -> dict:
    """Whether the pair implied by ``a`` and ``b`` agrees with the stated pair ``T_pair``
    within the two runs' combined 95 % intervals (module docstring)."""
    G = invert(a.T_cam_lidar) @ T_pair @ b.T_cam_lidar
    p = correction_params(G)
    diff = {ax: round(float(v * (100.0 if i < 3 else 1.0)), 4)
            for i, (ax, v) in enumerate(zip(AXES, p))}
    units = {ax: ("cm" if i < 3 else "deg") for i, ax in enumerate(AXES)}
    ha = _half_widths(a) or {}
    hb = _half_widths(b) or {}
    limit: dict[str, float | None] = {}
    for ax in AXES:
        x, y = ha.get(ax), hb.get(ax)
        limit[ax] = None if x is None or y is None else round(float(np.hypot(x, y)), 4)
    bounds = {ax: v for ax, v in limit.items() if v is not None}     # in AXES' order
    checked = list(bounds)
    beyond = [ax for ax, v in bounds.items() if abs(diff[ax]) > v]
    out = {"against": against, "frame": "lidar", "difference": diff, "units": units,
           "limit_95": limit, "axes_checked": checked}
    if not checked:
        unjudged = [r for r in (a, b) if _half_widths(r) is None]
        out.update(verdict="not checked",
                   reason="a run judged unreliable has no intervals" if unjudged else
                   "neither run determines an axis to a 95 % interval")
    elif beyond:
        out.update(verdict="inconsistent", reason="beyond the combined 95 % intervals on " +
                   ", ".join(f"{ax} ({diff[ax]:+.3g} {units[ax]}, limit {limit[ax]:.3g})"
                             for ax in beyond))
    else:
        out.update(verdict="consistent", reason="within the combined 95 % intervals on " +
                   ", ".join(checked))
    return out


def pair_record(na: str, a: CalibrationResult, nb: str, b: CalibrationResult,
                z_min: float) -> dict:
    """One pair's entry of rig.json (module docstring)."""
    T_ab = a.T_cam_lidar @ invert(b.T_cam_lidar)
    init = a.T_init @ invert(b.T_init)
    rec: dict[str, Any] = {
        "cameras": [na, nb], "T_a_b": _matrix(T_ab), "T_a_b_initial": _matrix(init),
        "vs_initial": _err(T_ab, init), "T_a_b_reference": None, "vs_reference": None}
    # calib.yaml's extrinsics: the reference when the runs started elsewhere, else the start.
    ref_a = a.T_ref if a.T_ref is not None else a.T_init
    ref_b = b.T_ref if b.T_ref is not None else b.T_init
    stated = ref_a @ invert(ref_b)
    against = "initial (calib.yaml)"
    if a.T_ref is not None and b.T_ref is not None:
        rec.update(T_a_b_reference=_matrix(stated), vs_reference=_err(T_ab, stated),
                   initial_vs_reference=_err(init, stated))
        against = "reference (calib.yaml)"
    rec["overlap"] = overlap(a, b, z_min)
    if rec["overlap"]["points_in_both"] == 0:
        rec["consistency"] = {"verdict": "not checked", "against": against,
                              "reason": "no LiDAR point is in view of both cameras"}
    else:
        rec["consistency"] = consistency(a, b, stated, against)
    return rec


def rig_summary(results: dict[str, CalibrationResult], z_min: float) -> dict:
    """rig.json's content for the results by camera name."""
    return {"cameras": [camera_record(n, r) for n, r in results.items()],
            "pairs": [pair_record(na, results[na], nb, results[nb], z_min)
                      for na, nb in combinations(results, 2)]}


def pair_line(pair: dict) -> str:
    """One line per pair for the console."""
    a, b = pair["cameras"]
    parts = [f"T_{a}_{b}: {_fmt(pair['vs_initial'])} from the initial pair"]
    if pair.get("vs_reference"):
        parts.append(f"{_fmt(pair['vs_reference'])} from the reference pair")
    ov = pair["overlap"]
    parts.append(f"{100 * ov['share_of_either']:.1f} % of the points in view are seen by both")
    c = pair["consistency"]
    parts.append(f"{c['verdict']} ({c['reason']})")
    return "; ".join(parts)


def _fmt(e: dict) -> str:
    return f"{e['rotation_deg']:.3f} deg / {e['translation_cm']:.2f} cm"
