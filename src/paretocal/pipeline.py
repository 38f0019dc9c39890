"""The calibration pipeline: frames -> features -> objective -> search -> decision -> result."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import __version__
from .config import Settings
from .decide import decide, reprojection_deviation
from .errors import DegenerateSceneError, InputError, SettingsError
from .features.lidar import GROUP_NAMES
from .features.prepare import FrameFeatures, frame_rings, prepare_frame
from .features.rings import MIN_PURITY, MIN_RINGS, Rings
from .geometry import pose_error
from .io.frame import Frame
from .io.layouts import load_frames
from .quality import quality_report
from .objective import CalibrationObjective, build_scene, get_evaluator, measure_cost_model
from .objective.cost import CostModel
from .search import VARIABLES, coarse_seeds, polish_front, run_nsga2
from .search.basin import prefer_near
from .search.checkpoint import Checkpoint, fingerprint
from .verdict import (MIN_POINTS_PER_FRAME, RELIABLE_MIN_FRAMES, gather_evidence,  # noqa: F401
                      reliability, verdict_text)

log = logging.getLogger(__name__)

#: A frame with fewer Canny edge pixels is blank for the objective: a real photograph has
#: thousands (a KITTI frame about 30 000); a flat or black image gives none, or a few dozen
#: from noise and compression, which no LiDAR edge could be aligned with.
MIN_EDGE_PIXELS = 100
DEFAULT_N_MIN = 20

@dataclass
class Front:
    """The final non-dominated set, sorted by cost.

    Attributes
    ----------
    X : ndarray, shape (k, 7)
        ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
    F : ndarray, shape (k, 2)
        ``[f1, f2]``.
    T : ndarray, shape (k, 4, 4)
        The extrinsics.
    columns : dict of str -> ndarray (k,)
        Per-solution figures: chamfer parts, ``ms``, ``bytes``, ``in_view`` and, when a
        reference is known, the reference errors.
    """

    X: np.ndarray
    F: np.ndarray
    T: np.ndarray
    columns: dict


@dataclass
class CalibrationResult:
    """Everything a calibration run produced (see :func:`calibrate`)."""

    T_cam_lidar: np.ndarray
    T_init: np.ndarray
    T_ref: np.ndarray | None
    chosen: int
    front: Front
    decision: dict
    cost_model: CostModel
    settings: Settings
    evaluations: int
    wall_s: float
    timings: dict
    frames: list[str]
    feature_counts: dict
    n_range: tuple[int, int]
    history: list = field(default_factory=list)
    nsga_front: tuple | None = None
    quality: dict | None = None
    #: ``{"verdict": "ok" | "unreliable", "reasons": [...], ...}`` (see :func:`reliability`).
    reliability: dict | None = None
    #: What was done about motion during the sweeps (see :func:`compensate_motion`).
    motion: dict | None = None
    #: What the input files offered: the point fields used, the camera model, notes.
    inputs: dict | None = None
    #: The verdict's own checks (restart, image-cloud agreement, per-axis intervals; see
    #: :func:`paretocal.verdict.gather_evidence`); written inside ``reliability``.
    evidence: dict | None = None
    #: The frames as calibrated (de-skewed when the motion was compensated); not in JSON.
    sweeps: list | None = None
    #: The final objective (feature points chosen at the estimate) and the grid seeds of the
    #: search, for studies that evaluate more candidates; not written to result.json.
    objective: CalibrationObjective | None = None
    seed_poses: np.ndarray | None = None

    @property
    def correction(self) -> dict[str, float]:
        x = self.front.X[self.chosen]
        return {k: float(v) for k, v in zip(VARIABLES[:6], x[:6])}

    @property
    def n_points(self) -> int:
        return int(round(self.front.X[self.chosen, 6]))

    @property
    def reference_error(self) -> dict | None:
        if self.T_ref is None:
            return None
        e = pose_error(self.T_cam_lidar, self.T_ref)
        return {k: float(v) for k, v in e.items()}

    @property
    def initial_error(self) -> dict | None:
        if self.T_ref is None:
            return None
        e = pose_error(self.T_init, self.T_ref)
        return {k: float(v) for k, v in e.items()}

    def objectives(self) -> dict[str, float]:
        i, c = self.chosen, self.front.columns
        out = {"chamfer": float(self.front.F[i, 0]), "cost": float(self.front.F[i, 1])}
        for k in ("chamfer_holdout", "deviation_px", "t_norm", "m_norm", "ms", "bytes", "edge_px",
                  "intensity_px", "smooth_px", "sampling_se", "in_view"):
            if k in c:
                out[k] = float(c[k][i])
        return out

    def to_dict(self) -> dict:
        """The ``result.json`` document (docs/conventions.md section 3)."""
        return {
            "T_cam_lidar": self.T_cam_lidar.tolist(),
            "T_init": self.T_init.tolist(),
            "correction": self.correction,
            "n_points": self.n_points,
            "objectives": self.objectives(),
            "decision": self.decision,
            "reference_error": self.reference_error,
            "initial_error": self.initial_error,
            "evaluations": int(self.evaluations),
            "wall_s": round(float(self.wall_s), 3),
            "seed": int(self.settings.search.seed),
            "version": __version__,
            "config": self.settings.to_dict(),
            "frames": self.frames,
            "n_range": list(self.n_range),
            "front_size": int(len(self.front.X)),
            "features": self.feature_counts,
            "cost_model": self.cost_model.to_dict(),
            "timings_s": {k: round(float(v), 3) for k, v in self.timings.items()},
            "ucb_k": round(float(self.settings.ucb_k), 4),
            "quality": self.quality,
            "motion": self.motion,
            "inputs": self.inputs,
            "reliability": self.reliability if self.reliability is not None
            else reliability(self),
        }


def resolve_init(frames: list[Frame], T_init: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """The initial extrinsic and the reference: ``--init`` wins; the dataset's is the fallback.

    The reference is returned only when an initial guess was given independently of it, so the
    reported error is never trivially zero.
    """
    T_ref = frames[0].T_ref
    if T_ref is not None and any(f.T_ref is None or not np.allclose(f.T_ref, T_ref, atol=1e-9)
                                 for f in frames):
        log.warning("frames carry different reference extrinsics; the first frame's is used")
    if T_init is None:
        if T_ref is None:
            raise InputError("no initial extrinsic: the source has no T_cam_lidar; pass --init")
        return T_ref.copy(), None
    return np.asarray(T_init, dtype=np.float64), T_ref


def prepare_features(frames: list[Frame], T_init: np.ndarray, settings: Settings,
                     progress=None, rings: list[Rings] | None = None) -> list[FrameFeatures]:
    """Features of every frame, each with its own seeded stream (independent of frame count).

    ``rings`` (from :func:`sweep_rings`) saves recovering each sweep's rings again.
    """
    seq = np.random.SeedSequence(settings.search.seed)
    out = []
    for k, (frame, child) in enumerate(zip(frames, seq.spawn(len(frames)))):
        out.append(prepare_frame(frame, T_init, settings.features, settings.objective,
                                 np.random.default_rng(child),
                                 rings=None if rings is None else rings[k]))
        if progress is not None:
            progress(k + 1, len(frames))
    return out


def compensate_motion(frames: list[Frame], settings: Settings) -> tuple[list[Frame], dict]:
    """De-skew every sweep to its image time with ego-motion estimated from the sequence.

    A spinning LiDAR on a moving vehicle stores each point at its own time (a 10 Hz sweep at
    30 m/s spans 3 m); the image is exposed at one time. When every cloud has per-point time,
    the twist is estimated by registering consecutive sweeps (:func:`paretocal.motion.
    estimate_motion`) and each sweep is expressed at its centre time plus
    ``settings.motion.time_offset_s``. The motion is applied only when the registration
    constrains it along every axis; otherwise the sweeps stay as recorded and the returned
    record says why.

    Returns
    -------
    frames : list of Frame
        De-skewed copies (points in the same order), or the input frames.
    info : dict
        ``compensated`` (bool), ``reason`` (when not), the estimate's figures, and
        ``max_shift_m``: the largest displacement the de-skew applied to a point.
    """
    import dataclasses

    from . import motion as mo

    m = settings.motion
    if m.deskew == "off":
        return frames, {"compensated": False, "reason": "de-skewing is off (motion.deskew)"}
    if any(f.time is None for f in frames):
        return frames, {"compensated": False,
                        "reason": "the clouds carry no per-point time: motion during a sweep "
                                  "is not compensated (a moving vehicle's clouds are skewed)"}
    if len(frames) < 2:
        return frames, {"compensated": False,
                        "reason": "one frame: ego-motion needs a sequence of sweeps"}
    order = np.argsort([float(np.median(f.time)) for f in frames], kind="stable")
    clouds = [(np.asarray(frames[k].points[:, :3], dtype=np.float64), frames[k].time)
              for k in order]
    try:
        est = mo.estimate_motion(clouds, per_frame=m.per_frame, points=m.points,
                                 seed=settings.search.seed)
    except ValueError as exc:
        return frames, {"compensated": False, "reason": f"ego-motion estimate failed: {exc}"}
    info = {"speed_mps": round(float(est.speed), 3),
            "speed_spread_mps": round(float(est.speed_spread), 3),
            "v_mps": [round(float(v), 3) for v in est.twist.v],
            "yaw_rate_dps": round(float(np.degrees(est.twist.w[2])), 3),
            "observable_xyz": [bool(v) for v in est.observable],
            "median_share_xyz": [round(float(v), 4) for v in np.median(est.share, axis=0)],
            "time_offset_s": m.time_offset_s}
    sweep = max(float(np.ptp(f.time)) for f in frames)
    info["skew_m"] = round(float(est.speed) * sweep, 3)
    if not est.compensable:
        axes = "".join(a for a, ok in zip("xyz", est.observable) if not ok)
        info.update(compensated=False,
                    reason=f"ego-motion is not observable along {axes} (the scene does not "
                           "constrain scan-to-scan registration there): not compensated")
        return frames, info
    out = list(frames)
    shift = 0.0
    for j, k in enumerate(order):
        f = frames[k]
        t_ref = mo.sweep_centre(f.time) + m.time_offset_s
        xyz = mo.deskew(f.points[:, :3], f.time, t_ref, est.frame_motion(j))
        shift = max(shift, float(np.max(np.linalg.norm(xyz - f.points[:, :3], axis=1))))
        pts = f.points.copy()
        pts[:, :3] = xyz
        out[k] = dataclasses.replace(f, points=np.ascontiguousarray(pts, dtype=np.float32))
    info.update(compensated=True, max_shift_m=round(shift, 3))
    log.info("de-skewed %d sweeps: %.2f m/s, largest shift %.2f m", len(frames), est.speed,
             shift)
    return out, info


def warn_unlocated(frames: list[Frame], info: dict) -> None:
    """Tell the user when the LiDAR's pose is needed and could not be found (``info`` from
    :func:`locate_lidar`); called after the input checks so that bad input reads one line."""
    if info.get("source") != "unknown":
        return
    log.warning("%s: the returns do not lie on rings about the cloud's origin and the LiDAR's "
                "pose could not be estimated (%s); rings and edges are taken about the cloud's "
                "origin and may be poor: give lidar_pose in calib.yaml", frames[0].points_path,
                info.get("reason", ""))


def locate_lidar(frames: list[Frame],
                 settings: Settings) -> tuple[list[Frame], dict, Rings | None]:
    """The LiDAR's pose in the clouds' frame: given, not needed, or estimated from a sweep.

    Ring geometry is taken about the sensor's own origin and axis. A pose in calib.yaml
    (``lidar_pose``) is used as given; a cloud with a ring field, or whose rings fit the line
    model about its own origin, needs none. Otherwise (a cloud stored in a vehicle frame) the
    pose is estimated from the first sweep
    (:func:`~paretocal.features.sensor.estimate_sensor_pose`) and, when the rings fit the line
    model in the estimated frame, given to every frame (one rig, one mount).

    Returns
    -------
    frames : list of Frame
        With ``sensor_pose`` set when it was estimated.
    info : dict
        ``source``: "calib.yaml", "ring field", "cloud origin", "estimated" or "unknown",
        with the estimate's summary and the rings' purity where they were checked.
    first_rings : Rings or None
        The first frame's rings about the pose returned, when they were recovered here (for
        :func:`sweep_rings`, which then need not recover them again).
    """
    import dataclasses

    from .features.sensor import estimate_sensor_pose

    if any(f.sensor_pose is not None for f in frames):
        return frames, {"source": "calib.yaml"}, None
    if settings.features.ring_method in ("field", "scan", "elevation"):
        return frames, {"source": "cloud origin", "note": "ring method "
                        f"{settings.features.ring_method!r} asked for"}, None
    first = frames[0]
    if first.ring is not None:
        return frames, {"source": "ring field"}, None
    rng = np.random.default_rng(np.random.SeedSequence([settings.search.seed, 2]))
    here = frame_rings(first, settings.features, rng)
    if here.purity >= MIN_PURITY and here.n_rings >= MIN_RINGS:
        return frames, {"source": "cloud origin", "purity": round(float(here.purity), 4)}, here
    est = estimate_sensor_pose(first.points, rng)
    if est is None or not est.ok:
        why = "no ground plane to start from" if est is None else "; ".join(est.notes)
        return frames, {"source": "unknown", "purity_at_origin": round(float(here.purity), 4),
                        "estimate": None if est is None else est.summary(), "reason": why}, here
    moved = [dataclasses.replace(f, sensor_pose=est.pose) for f in frames]
    there = frame_rings(moved[0], settings.features, rng)
    info = {"source": "estimated", "estimate": est.summary(),
            "purity_at_origin": round(float(here.purity), 4),
            "purity": round(float(there.purity), 4), "n_rings": int(there.n_rings)}
    if there.purity < MIN_PURITY or there.n_rings < MIN_RINGS:
        info.update(source="unknown", reason="the rings do not fit the line model in the "
                    "estimated frame either")
        return frames, info, here
    p = est.pose[:3, 3]
    log.info("%s: the LiDAR's pose was estimated from the sweep: at (%.2f, %.2f, %.2f) m in "
             "the cloud's frame, axis tilted %.2f deg (%d rings, purity %.3f); give "
             "lidar_pose in calib.yaml to set it", first.points_path, p[0], p[1], p[2],
             est.tilt_deg, there.n_rings, there.purity)
    return moved, info, there


def sweep_rings(frames: list[Frame], settings: Settings,
                first: Rings | None = None) -> list[Rings]:
    """The rings of every frame's sweep (see :func:`~paretocal.features.prepare.frame_rings`);
    :func:`warn_rings` tells the user about the implausible ones.

    One sensor keeps its lasers' lines from sweep to sweep: once a sweep's rings were found
    by the line search and are plausible, the next sweeps are labelled with its line model
    first (measured on the KITTI drive in firing and random order: 0.4 s a sweep instead of
    1.5-2.7 s, every point on its true ring as before); a sweep the model does not fit is
    searched afresh. ``first``: the first frame's rings when already known (from
    :func:`locate_lidar`)."""
    seq = np.random.SeedSequence([settings.search.seed, 1])
    out, model = [], None
    for k, (f, child) in enumerate(zip(frames, seq.spawn(len(frames)))):
        r = (first if k == 0 and first is not None else
             frame_rings(f, settings.features, np.random.default_rng(child), model))
        if r.method == "lines" and r.n_rings >= MIN_RINGS and r.purity >= MIN_PURITY:
            model = r
        out.append(r)
    return out


def warn_rings(frames: list[Frame], rings: list[Rings]) -> None:
    """One warning per ring problem (not per frame), naming a file and what to do.

    Rings that do not fit the line model (purity below
    :data:`~paretocal.features.rings.MIN_PURITY`) are still used, but a wrong ring structure
    makes depth edges noise. Called once the scene is known to be usable, so that a bad-input
    error is the only line the user sees.
    """
    notes = sorted({n for r in rings for n in r.notes})
    for n in notes[:3]:
        log.warning("%s", n)
    bad = [(f, r) for f, r in zip(frames, rings) if r.purity < MIN_PURITY]
    if bad:
        f, r = bad[0]
        hint = ("the cloud is not in the sensor's own frame: give the LiDAR's pose "
                "(lidar_pose in calib.yaml)" if f.sensor_pose is None else
                "check lidar_pose in calib.yaml")
        log.warning("%s: laser rings do not fit a spinning LiDAR (%d rings, %.0f %% of the "
                    "returns on their ring's cone; %d of %d frames like this); depth edges "
                    "will be unreliable; %s", f.points_path, r.n_rings, 100 * r.purity,
                    len(bad), len(frames), hint)


def _check_scene(feats: list[FrameFeatures], frames: list[Frame] | None = None,
                 T_view: np.ndarray | None = None, z_min: float = 0.1) -> None:
    """Refuse scenes that cannot constrain the extrinsic, saying which frames and why.

    Raises :class:`DegenerateSceneError` when a frame's image has no edges, or when no frame
    has :data:`MIN_POINTS_PER_FRAME` LiDAR feature points in view at ``T_view``; the message
    then says whether the points lie behind the camera, outside the image or are simply too
    few, and whether the inverse or a half-turned extrinsic would see them. Frames with too
    few points among good ones are only reported (a warning): they add little, but no harm.
    """
    blank = [f"{f.name} ({len(f.image.edge_uv)} px)" for f in feats
             if len(f.image.edge_uv) < MIN_EDGE_PIXELS]
    if blank:
        raise DegenerateSceneError(
            f"no image edges in frame(s) {_names(blank)} (fewer than {MIN_EDGE_PIXELS} edge "
            "pixels): the images are blank or the Canny thresholds (canny_low, canny_high) are "
            "too high; leave these frames out with --frames")
    few = [k for k, f in enumerate(feats) if len(f.xyz) < MIN_POINTS_PER_FRAME]
    if not few:
        return
    listed = _names([f"{feats[k].name} ({len(feats[k].xyz)})" for k in few])
    cause = ""
    if frames is not None and T_view is not None:
        cause = "; " + _view_diagnosis([frames[k] for k in few], T_view, z_min)
    if len(few) == len(feats):
        raise DegenerateSceneError(
            f"too few LiDAR feature points in view at the initial extrinsic (fewer than "
            f"{MIN_POINTS_PER_FRAME} per frame: {listed}){cause}")
    log.warning("frame(s) %s: fewer than %d LiDAR feature points in view at the initial "
                "extrinsic%s; they add little to the calibration", listed, MIN_POINTS_PER_FRAME,
                cause)


def _names(items: list[str], most: int = 5) -> str:
    more = f" and {len(items) - most} more" if len(items) > most else ""
    return ", ".join(items[:most]) + more


def _view_diagnosis(frames: list[Frame], T: np.ndarray, z_min: float) -> str:
    """Why few points are in view at ``T``: a short clause for an error message."""
    from .camera import project
    from .geometry import invert, rotation_zyx

    def counts(T_try):
        front = seen = 0
        for f in frames:
            _, z, visible = project(f.points, f.camera, T_try, z_min)
            front += int((z > z_min).sum())
            seen += int(visible.sum())
        return front, seen

    total = sum(len(f.points) for f in frames)
    front, seen = counts(T)
    if front < 0.01 * total:
        why = (f"{front} of {total} LiDAR points lie in front of the camera: nearly every "
               "point is behind it")
    elif seen < 0.01 * total:
        why = (f"{seen} of {total} LiDAR points project into the image ({front} are in front "
               "of the camera): the extrinsic or the camera intrinsics (K, width, height) are "
               "wrong")
    else:
        why = (f"{seen} of {total} LiDAR points project into the image but few are edges: "
               "the sweep is too sparse there or the feature thresholds too strict")
    # Two classic mistakes, cheap to test: the inverse transform and a half turn.
    half = np.eye(4)
    half[:3, :3] = rotation_zyx(0.0, 180.0, 0.0)        # 180 deg about the camera's y axis
    hints = [("is it inverted (T_lidar_cam given for T_cam_lidar)?", invert(T)),
             ("is it turned 180 deg about the vertical axis?", half @ T)]
    best = max(((counts(T_try)[1], text) for text, T_try in hints), key=lambda c: c[0])
    if best[0] > max(20 * seen, 1000):
        why += f"; {best[0]} points would be in view with the initial extrinsic fixed: {best[1]}"
    else:
        why += "; check --init and the camera"
    return why


class _Stage:
    """The objective built from the frames' features as seen from ``T_view``.

    Attributes: ``feats`` (search part of each frame's features), ``scene``, ``holdout``
    (held-out scene or None), ``n_min``, ``n_max``, ``cost`` (the measured cost model) and
    ``objective`` (corrections relative to ``T_init``).
    """

    def __init__(self, frames: list[Frame], T_view: np.ndarray, T_init: np.ndarray,
                 settings: Settings, progress=None, rings: list[Rings] | None = None):
        feats_all = prepare_features(frames, T_view, settings, progress, rings)
        _check_scene(feats_all, frames, T_view, settings.features.z_min)
        o, z_min = settings.objective, settings.features.z_min
        parts = [f.split(o.holdout) for f in feats_all]
        self.feats = [p[0] for p in parts]
        self.scene = build_scene(self.feats, z_min, o.outside)
        self.holdout = (build_scene([p[1] for p in parts], z_min, o.outside)
                        if o.holdout > 0 else None)
        self.n_min, self.n_max = n_range(settings, self.scene.points_per_frame)
        self.cost = measure_cost_model(self.scene, get_evaluator(o.evaluator), T_view,
                                       self.n_min, self.n_max)
        self.objective = CalibrationObjective(self.scene, T_init, o, self.cost,
                                              [f.image.edge_uv for f in self.feats],
                                              ucb_k=settings.ucb_k)


def n_range(settings: Settings, points_per_frame: np.ndarray) -> tuple[int, int]:
    """The search's range of points per frame, validated against what the frames hold."""
    most = int(points_per_frame.max())
    s = settings.search
    n_max = most if s.n_max is None else int(s.n_max)
    n_min = min(DEFAULT_N_MIN, n_max) if s.n_min is None else int(s.n_min)
    if n_max > most:
        raise SettingsError(f"--n-max {n_max}: the frames hold at most {most} feature points "
                            "per frame")
    if n_min > n_max:
        raise SettingsError(f"--n-min {n_min} is larger than the largest n ({n_max})")
    return n_min, n_max


def calibrate(source: str | Path | list[Frame], T_init: np.ndarray | None = None,
              settings: Settings | None = None, progress=None,
              checkpoint: Checkpoint | None = None) -> CalibrationResult:
    """Calibrate the camera-LiDAR extrinsic of a set of frames.

    Parameters
    ----------
    source : path or list of Frame
        A dataset folder (any layout of docs/conventions.md section 2) or frames already loaded.
    T_init : ndarray, shape (4, 4), optional
        Initial ``T_cam_lidar``; the dataset's own extrinsic when omitted.
    settings : Settings, optional
    progress : callable, optional
        ``progress(stage, done, total)`` for ``stage`` in ``features``, ``search``, ``polish``
        (the polish reports its passes: the first, and the one after re-selecting points).
    checkpoint : Checkpoint, optional
        Save the search every few generations and resume from a saved state of the same run
        (see :mod:`paretocal.search.checkpoint`); an interrupt during the search raises
        :class:`~paretocal.search.checkpoint.SearchInterrupted`.

    Returns
    -------
    CalibrationResult
    """
    settings = (settings or Settings()).validate()
    t_start = time.perf_counter()
    timings = {}
    if isinstance(source, (str, Path)):
        frames = load_frames(source, settings.frames, settings.camera)
    else:
        frames = list(source)
    if not frames:
        raise InputError("no frames to calibrate")
    timings["load"] = time.perf_counter() - t_start
    T_init, T_ref = resolve_init(frames, T_init)

    def report(stage):
        return None if progress is None else (lambda done, total, *a: progress(stage, done, total))

    t0 = time.perf_counter()
    frames, lidar_info, first_rings = locate_lidar(frames, settings)
    timings["lidar_pose"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    # Rings from the sweeps as recorded (each return on its laser's cone about the sensor);
    # everything else from the sweeps de-skewed to the image time.
    rings = sweep_rings(frames, settings, first_rings)
    timings["rings"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    frames, motion_info = compensate_motion(frames, settings)
    timings["motion"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    stage = _Stage(frames, T_init, T_init, settings, report("features"), rings)
    warn_unlocated(frames, lidar_info)
    warn_rings(frames, rings)
    feats, scene, objective, cost_model = stage.feats, stage.scene, stage.objective, stage.cost
    n_min, n_max = stage.n_min, stage.n_max
    timings["features"] = time.perf_counter() - t0
    d = settings.decision
    if d.rule == "budget" and d.budget_ms < float(cost_model.time_ms(cost_model.points_min)):
        raise SettingsError(f"--budget-ms {d.budget_ms:g}: below the cheapest evaluation "
                            f"({float(cost_model.time_ms(cost_model.points_min)):.4g} ms at "
                            f"n = {n_min}); raise the budget or lower --n-min")
    seeds = None
    if settings.search.seed_grid_deg:
        t0 = time.perf_counter()
        seeds = coarse_seeds(feats, T_init, settings, cost_model, n_max)
        timings["seed_grid"] = time.perf_counter() - t0
    if checkpoint is not None:
        checkpoint.key = fingerprint(
            settings.to_dict(), T_init, n_min, n_max,
            [(f.name, len(f.points), list(f.image.shape)) for f in frames],
            seeds if seeds is not None else np.zeros(0))
    res = run_nsga2(objective, settings.search, n_min, n_max, report("search"), seeds=seeds,
                    checkpoint=checkpoint)
    timings["search"] = res.wall_s
    timings["search_objective"] = res.objective_s

    X, F = res.X, res.F
    evaluations = res.evaluations
    basin = None
    steps = 1 + int(settings.features.reselect)
    if d.refine:
        t0 = time.perf_counter()
        if progress is not None:
            progress("polish", 0, steps)
        X, F, ev = polish_front(objective, X, F, settings, n_min, n_max)
        evaluations += ev
        # A pose far from the start replaces the start's own basin only when the frames
        # clearly prefer it (search.basin).
        X, F, basin, ev = prefer_near(objective, X, F, settings, n_min, n_max)
        evaluations += ev
        if progress is not None:
            progress("polish", 1, steps)
        timings["polish"] = time.perf_counter() - t0
        if settings.features.reselect:
            # Choose the feature points again, by what is in view at the estimate rather than
            # at the initial guess: points the initial guess wrongly kept (or dropped) bias the
            # objective, and that bias grows with the initial error.
            t0 = time.perf_counter()
            T_est = objective.transforms(X[np.argmin(F[:, 0])][None])[0]
            stage = _Stage(frames, T_est, T_init, settings, rings=rings)
            feats, scene, objective, cost_model = (stage.feats, stage.scene, stage.objective,
                                                   stage.cost)
            n_min, n_max = stage.n_min, stage.n_max
            X = X.copy()
            X[:, 6] = np.clip(X[:, 6], n_min, n_max)
            X, F, ev = polish_front(objective, X, objective.evaluate(X), settings, n_min, n_max)
            evaluations += ev + len(X)
            timings["reselect"] = time.perf_counter() - t0
            if progress is not None:
                progress("polish", 2, steps)

    T = objective.transforms(X)
    chamfer_parts = objective.chamfer(X)
    costs = objective.cost(X)
    columns = {"t_norm": costs["t_norm"], "m_norm": costs["m_norm"], "ms": costs["ms"],
               "bytes": costs["bytes"], "points": costs["points"],
               "sampling_se": chamfer_parts["se"], "in_view": chamfer_parts["in_view"]}
    for g, name in enumerate(GROUP_NAMES):
        short = {"depth_edge": "edge_px", "intensity_edge": "intensity_px", "smooth": "smooth_px"}
        columns[short[name]] = chamfer_parts["mean"][:, g]
    if stage.holdout is not None:
        columns["chamfer_holdout"] = holdout_score(stage.holdout, T_init, settings, X)
    # How far each solution's calibration moves projections from the best-supported one.
    best = int(np.argmin(F[:, 0]))
    check = stage.holdout if stage.holdout is not None else scene
    columns["deviation_px"] = reprojection_deviation(
        T, T[best], [check.frame_xyz(f) for f in range(check.n_frames)],
        [f.camera for f in feats], settings.features.z_min)
    if T_ref is not None:
        for k, v in pose_error(T, T_ref).items():
            columns[f"ref_{k}"] = v
    i, decision = decide(F, costs["ms"], columns["deviation_px"], d.rule, d.budget_ms,
                         d.max_deviation_px)
    decision.update({"n_points": int(round(X[i, 6])), "front_size": int(len(X)),
                     "polished": bool(d.refine), "best_supported_n": int(round(X[best, 6])),
                     "basin": basin})
    quality = quality_report(objective, X[i])
    t0 = time.perf_counter()
    evidence = gather_evidence(objective, settings, n_min, n_max, X[i], quality)
    timings["verdict"] = time.perf_counter() - t0
    wall = time.perf_counter() - t_start
    timings["total"] = wall
    result = CalibrationResult(
        T_cam_lidar=T[i], T_init=T_init, T_ref=T_ref, chosen=i,
        front=Front(X=X, F=F, T=T, columns=columns), decision=decision,
        cost_model=cost_model, settings=settings, evaluations=evaluations, wall_s=wall,
        timings=timings, frames=[f.name for f in frames],
        feature_counts=_feature_counts(feats), n_range=(n_min, n_max), history=res.history,
        nsga_front=(res.X, res.F), quality=quality, objective=objective, seed_poses=seeds)
    result.motion = motion_info
    result.inputs = _inputs(frames)
    result.inputs["lidar_pose_source"] = lidar_info
    result.inputs["rings"] = [{"frame": f.name, "method": r.method, "n_rings": int(r.n_rings),
                               "purity": round(float(r.purity), 4)}
                              for f, r in zip(frames, rings)]
    result.sweeps = frames
    result.evidence = evidence
    result.reliability = reliability(result)
    if result.reliability["verdict"] != "ok":
        log.warning("the result may be unreliable: %s", "; ".join(result.reliability["reasons"]))
    return result


def _inputs(frames: list[Frame]) -> dict:
    """What the inputs offered (result.json ``inputs``): the point-cloud fields that gave
    intensity, ring and time, the reader's notes, the camera model and the LiDAR pose."""
    pf = dict(frames[0].point_fields or {})
    notes = sorted({w for f in frames for w in (f.point_fields or {}).get("warnings", ())})
    pf.pop("warnings", None)
    cam = frames[0].camera
    return {"point_fields": pf, "notes": notes,
            "camera_model": getattr(cam, "model", "pinhole"),
            "lidar_pose": None if frames[0].sensor_pose is None
            else np.asarray(frames[0].sensor_pose).tolist(),
            "mask": frames[0].mask is not None}


def holdout_score(scene, T_init: np.ndarray, settings: Settings, X: np.ndarray) -> np.ndarray:
    """Each solution's pose scored on every held-out point (no sampling-error term), shape (k,)."""
    dummy = CostModel(0.0, 1.0, 0.0, 1.0, 0, 1, {})
    obj = CalibrationObjective(scene, T_init, settings.objective, dummy, ucb_k=0.0)
    Xa = np.array(X, dtype=np.float64, copy=True)
    Xa[:, 6] = int(scene.points_per_frame.max())
    return obj.chamfer(Xa)["f1"]


def _feature_counts(feats: list[FrameFeatures]) -> dict:
    per = [f.counts() for f in feats]
    total = {g: int(sum(p[g] for p in per)) for g in GROUP_NAMES}
    summaries = [f.rings for f in feats if f.rings]
    ring_info = None
    if summaries:
        ring_info = {"methods": sorted({s["method"] for s in summaries}),
                     "min_purity": min(s["purity"] for s in summaries),
                     "spacing_deg_median": summaries[0]["spacing_deg_median"]}
    return {"per_frame_mean": {g: round(total[g] / len(feats), 1) for g in GROUP_NAMES},
            "total": total, "rings": sorted({f.n_rings for f in feats}),
            "ring_recovery": ring_info,
            # Frames with enough feature points in view to constrain anything.
            "frames_contributing": int(sum(len(f.xyz) >= MIN_POINTS_PER_FRAME
                                           for f in feats))}
