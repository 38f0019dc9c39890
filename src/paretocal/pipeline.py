"""The calibration pipeline: frames -> features -> objective -> search -> decision -> verdict -> result.

Each stage lives in its own module (:mod:`.inputs`, :mod:`.stage`, :mod:`.search`, :mod:`.decide`,
:mod:`.quality`, :mod:`.verdict`, :mod:`.result`); :func:`calibrate` runs them in order. The
stages' public names stay importable from here."""

from __future__ import annotations

import dataclasses
import logging
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .config import Settings, check_population_memory, dataset_settings
from .crosscheck import MIN_FRAMES, motion_agreement, recording_motion
from .decide import decide, reprojection_deviation
from .errors import STOP, InputError, Interrupted, SettingsError
from .features.lidar import GROUP_NAMES
from .geometry import pose_error
from .io.frame import Frame
from .io.layouts import load_frames, source_options
from .quality import at_every_point, pixel_fd_step, quality_report
from .search import coarse_seeds, polish_front, run_nsga2
from .search.basin import prefer_near
from .search.checkpoint import Checkpoint, fingerprint
from .inputs import (LidarSteps, compensate_motion, lidar_settings_key, locate_lidar,  # noqa: F401
                     resolve_init, sweep_rings, warn_rings, warn_unlocated, describe_inputs)
from .objective import get_evaluator
from .board import BoardStart, board_evidence, board_settings, board_start, has_board
from .wide import after_settings, photo_check, wanted, wide_start
from .objective.cost import CostModel, time_per_candidate
from .result import CalibrationResult, Front  # noqa: F401
from .stage import (DEFAULT_N_MIN, MIN_EDGE_PIXELS, Stage, check_scene, feature_counts,  # noqa: F401
                    holdout_score, log_features, n_range, prepare_features)
from .verdict import (MIN_POINTS_PER_FRAME, RELIABLE_MIN_FRAMES, gather_evidence,  # noqa: F401
                      reliability, verdict_text)

log = logging.getLogger(__name__)


def calibrate(source: str | Path | list[Frame], T_init: np.ndarray | None = None,
              settings: Settings | None = None, progress=None,
              checkpoint: Checkpoint | None = None,
              lidar: LidarSteps | None = None,
              dataset_options: bool = True) -> CalibrationResult:
    """Calibrate the camera-LiDAR extrinsic of a set of frames.

    Parameters
    ----------
    source : path or list of Frame
        A dataset folder (any layout of docs/conventions.md section 2) or frames already loaded.
    T_init : ndarray, shape (4, 4), optional
        Initial ``T_cam_lidar``; the dataset's own extrinsic when omitted.
    settings : Settings, optional
        What the dataset's calib.yaml states (``init_error``) replaces the defaults these
        leave (:func:`~paretocal.config.dataset_settings`), as on the command line: for a
        dataset folder, and for frames loaded from one (:func:`~paretocal.load_frames`; they
        carry it, :attr:`~paretocal.io.frame.Frame.options`), so that
        ``calibrate(load_frames(folder))`` is ``calibrate(folder)``.
    progress : callable, optional
        ``progress(stage, done, total)`` for ``stage`` in ``features`` (frames), ``search``
        (generations), ``polish`` (its passes: the first, and the one after re-selecting
        points), each from ``done = 0`` as it begins; and ``(phase, 0, 1)`` as each other
        phase of :data:`PHASES` begins, ``(phase, 1, 1)`` as it ends.
    checkpoint : Checkpoint, optional
        Save the search every few generations and resume from a saved state of the same run
        (see :mod:`paretocal.search.checkpoint`); an interrupt during the search raises
        :class:`~paretocal.search.checkpoint.SearchInterrupted`.
    lidar : LidarSteps, optional
        The LiDAR-only steps (:func:`~paretocal.inputs.prepare_lidar`) already done on these
        frames' clouds, for another camera of the rig: ``source`` must then be frames over the
        same clouds; they are not done again.
    dataset_options : bool
        False: the settings are final, also for a dataset folder or its frames (they state
        ``init_error`` even where it is the default).

    Returns
    -------
    CalibrationResult
        ``settings`` holds the settings used.
    """
    if dataset_options:
        settings = dataset_settings(settings, source_options(
            source if isinstance(source, (str, Path)) else list(source)))
    settings = (settings or Settings()).validate()
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    report = _reporter(progress)
    with _timed(timings, "load", progress):
        frames = _load(source, settings)
    check_population_memory(settings.search.pop, len(frames))
    given = T_init is not None or frames[0].T_ref is not None or not has_board(frames) or any(
        f.camera.mount is not None for f in frames)
    T_init, T_ref = resolve_init(frames, T_init) if given else (None, None)
    if lidar is not None:
        if lidar.settings_key != lidar_settings_key(settings):
            raise SettingsError("the LiDAR steps given were done with other feature, motion "
                                "or seed settings")
        frames = lidar.for_camera(frames)
        lidar_info, rings, motion_info = lidar.lidar_info, lidar.rings, lidar.motion_info
    else:
        with _timed(timings, "lidar_pose", progress):
            frames, lidar_info, first_rings = locate_lidar(frames, settings)
        with _timed(timings, "rings", progress):
            # Rings from the sweeps as recorded (each return on its laser's cone about the
            # sensor); everything else from the sweeps de-skewed to the image time.
            rings = sweep_rings(frames, settings, first_rings,
                                None if T_init is None else [(frames[0].camera, T_init)])
        with _timed(timings, "motion", progress):
            frames, motion_info = compensate_motion(frames, settings)
    board = None
    if has_board(frames) and any(f.camera.mount is not None for f in frames):
        log.warning("a joint calibration of several cameras does not use the board yet: "
                    "calibrate each camera alone (without --joint) to use it")
    elif has_board(frames):
        with _timed(timings, "board", progress):
            board = board_start(frames, settings, rings, T_given=T_init)
        timings.update({f"board_{k}": v for k, v in board.seconds.items()})
        T_init, settings = _board_applied(board, T_init, settings)
    if T_init is None:                  # resolve_init gave one unless the frames have a board
        raise InputError("no initial extrinsic: the source has no T_cam_lidar; pass --init")
    wide = None
    if (board is None or not board.applied) and wanted(settings):
        if any(f.camera.mount is not None for f in frames):
            raise SettingsError(
                "a joint calibration of several cameras does not take a wide start: calibrate "
                "one camera with the wide initial error first, then the rig from its result")
        with _timed(timings, "wide", progress):
            wide = wide_start(frames, T_init, settings, rings)
        if wide.T is not None:                    # applied
            # The usual calibration from the wide start, with the error it is good to.
            log.info("wide start: %.1f deg / %.0f cm from the start given",
                     *(float(pose_error(wide.T, T_init)[k])
                       for k in ("rotation_deg", "translation_cm")))
            T_init = wide.T
            settings = after_settings(settings)
        else:
            log.warning("the wide start could not apply: %s", "; ".join(wide.reasons))
    if progress is not None:
        progress("features", 0, len(frames))
    with _timed(timings, "features"):
        # A resumed run decides with the cost model the interrupted run measured.
        cost = None
        if checkpoint is not None:
            stored = checkpoint.stored_cost_model()
            if stored:
                cost = CostModel.from_dict(dict(stored, probe=dict(
                    stored["probe"], source=f"checkpoint {checkpoint.path}")))
        stage = Stage(frames, T_init, T_init, settings, report("features"), rings, cost=cost,
                      images=None if wide is None else wide.images,
                      board=None if board is None else board.scene)
        warn_unlocated(frames, lidar_info)
        warn_rings(frames, rings)
        log_features(stage.feats)
        _check_budget(stage, settings.decision)
    res, seeds = _search(stage, frames, T_init, settings, checkpoint, progress, timings)
    try:
        stage, X, F, basin, evaluations = _refine(stage, res, frames, rings, T_init, settings,
                                                  progress, timings, board)
        with _timed(timings, "decision", progress):
            T, columns, costs, best = front_columns(stage, X, F, T_init, T_ref, settings)
            d = settings.decision
            i, decision = decide(F, costs["ms"], columns["deviation_px"], d.rule, d.budget_ms,
                                 d.max_deviation_px)
            n_points = int(round(X[i, 6]))
            # The model decides (reproducibly); the time measured now is reported beside it.
            decision = decision.with_run(
                n_points=n_points, front_size=len(X), polished=d.polish,
                best_supported_n=int(round(X[best, 6])), basin=basin,
                measured_ms=time_per_candidate(
                    stage.scene, get_evaluator(settings.objective.evaluator), T[i], n_points))
            quality = quality_report(stage.objective, X[i],
                                     pixel_fd_step(stage.objective, at_every_point(
                                         stage.objective, X[i])))
        with _timed(timings, "verdict", progress):
            evidence = gather_evidence(stage.objective, settings, stage.n_min, stage.n_max,
                                       X[i], stage.sampling_px(),
                                       cameras=stage.camera_groups())
            if board is not None and getattr(stage.objective, "board", None) is not None:
                # The board's own evidence; its intervals are the result's (board.py).
                board.evidence = board_evidence(stage.objective, X[i], settings,
                                                stage.sampling_px())
                evidence = dataclasses.replace(evidence, intervals=board.evidence.intervals)
            if wide is not None:
                photo_check(wide, T[i])
                # Kept in the result for what it did; its maps are no longer needed.
                wide.images, wide.scene = None, None
    except Interrupted as exc:
        # The search is complete (and checkpointed): its front is what the run has to show.
        exc.X, exc.F, exc.generation = res.X, res.F, res.generations
        raise
    timings["total"] = wall = time.perf_counter() - t_start
    result = CalibrationResult(
        T_cam_lidar=T[i], T_init=T_init, T_ref=T_ref, chosen=i,
        front=Front(X=X, F=F, T=T, columns=columns), decision=decision,
        cost_model=stage.cost, settings=settings, evaluations=evaluations, wall_s=wall,
        timings=timings, frames=[f.name for f in frames],
        feature_counts=feature_counts(stage.feats), n_range=(stage.n_min, stage.n_max),
        history=res.history, nsga_front=(res.X, res.F), quality=quality,
        objective=stage.objective, seed_poses=seeds, motion=motion_info,
        inputs=describe_inputs(frames, lidar_info, rings), sweeps=frames, evidence=evidence,
        wide=wide, board=board)
    result.reliability = reliability(result)
    measured = None if wide is None else wide.recording
    kind = _motion_check(frames, settings, measured is not None, result.reliability.ok)
    if kind:
        # The recording's motion (the wide start's is reused). Both sensors' for a result
        # nothing else casts doubt on; for one flagged already, the LiDAR's alone (about half
        # the time), which still tells the user when the frames show one view.
        with _timed(timings, "verdict", progress):
            motion = measured or recording_motion(frames, settings.search.seed,
                                                  camera=kind == "both")
            result.evidence = dataclasses.replace(
                evidence, motion=motion_agreement(motion, T[i]))
            result.reliability = reliability(result)
        timings["total"] = result.wall_s = time.perf_counter() - t_start
    if not result.reliability.ok:
        log.warning("the result may be unreliable: %s", "; ".join(result.reliability.reasons))
    return result


def _board_applied(board: BoardStart, T_init: np.ndarray | None,
                   settings: Settings) -> tuple[np.ndarray, Settings]:
    """The start and settings after the board stage: the board's start with
    :func:`~paretocal.board.board_settings` when the board poses fix the extrinsic; else the
    start given, with a warning; an :class:`~paretocal.errors.InputError` when there is
    none."""
    if board.T is not None:
        if T_init is not None:
            e = pose_error(board.T, T_init)
            log.info("the board's start: %.2f deg / %.1f cm from the start given",
                     float(e["rotation_deg"]), float(e["translation_cm"]))
        return board.T, board_settings(settings)
    if T_init is None:
        raise InputError("no initial extrinsic: the source has no T_cam_lidar and the board "
                         "does not give one (" + "; ".join(board.reasons) + "); pass --init")
    log.warning("the board could not give the start: %s", "; ".join(board.reasons))
    return T_init, settings


def _motion_check(frames: list[Frame], settings: Settings, measured: bool, ok: bool) -> str:
    """How the verdict checks the result against the recording's motion
    (:mod:`paretocal.crosscheck`): ``"both"`` sensors' motion when the wide start measured it
    already (``measured``) or nothing else casts doubt on the result (``ok``), ``"lidar"``
    alone (whether the rig stands still) otherwise, and ``""`` not at all: with
    ``decision.motion_check`` off, fewer than :data:`~paretocal.crosscheck.MIN_FRAMES`
    frames, several cameras, or a board recording (its rig stands still by design)."""
    if (not settings.decision.motion_check or len(frames) < MIN_FRAMES
            or any(f.camera.mount is not None for f in frames) or has_board(frames)):
        return ""
    return "both" if ok or measured else "lidar"


#: What the run is doing during each timed phase, for the line an interrupt prints.
PHASES = {"load": "loading the frames", "lidar_pose": "locating the LiDAR",
          "rings": "recovering the LiDAR rings", "motion": "compensating the motion",
          "wide": "finding a wide start from the motion", "features": "extracting features",
          "board": "finding the board in the images and the sweeps",
          "seed_grid": "scoring the seed grid",
          "polish": "polishing the front", "reselect": "re-selecting the points at the estimate",
          "decision": "choosing the solution", "verdict": "gathering the verdict's evidence",
          "writing": "writing the results"}


@contextmanager
def _timed(timings: dict[str, float], name: str, progress=None):
    """Add the wall time of the block to ``timings[name]`` (s); an interrupt in the block
    becomes :class:`~paretocal.errors.Interrupted` naming the phase. ``progress``, when given,
    is told ``(name, 0, 1)`` as the block begins and ``(name, 1, 1)`` when it is done."""
    t0 = time.perf_counter()
    try:
        STOP.check()
        if progress is not None:
            progress(name, 0, 1)
        yield
        if progress is not None:
            progress(name, 1, 1)
        STOP.check()
    except KeyboardInterrupt:
        STOP.clear()                              # taken
        raise Interrupted(PHASES[name]) from None
    except Interrupted as exc:
        # Taken by a step of the phase that names itself (the verdict's restart is a search
        # of its own): the run stopped in this phase, and the front to show is the run's.
        if exc.phase == PHASES[name]:
            raise
        raise Interrupted(PHASES[name]) from None
    except SystemError:
        # A stop that lands while a compiled function is being dispatched comes out of the
        # call as SystemError ("... returned a result with an exception set"), the interrupt
        # inside it: still the user's stop.
        if not STOP.requested:
            raise
        STOP.clear()
        raise Interrupted(PHASES[name]) from None
    finally:
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - t0


def _reporter(progress):
    """``report(stage)``: a ``progress(done, total)`` callback for one stage, or None."""
    def report(stage):
        if progress is None:
            return None
        return lambda done, total, *a: progress(stage, done, total)
    return report


def _load(source, settings: Settings) -> list[Frame]:
    frames = (load_frames(source, settings.frames, settings.camera)
              if isinstance(source, (str, Path)) else list(source))
    if not frames:
        raise InputError("no frames to calibrate")
    return frames


def _check_budget(stage: Stage, d) -> None:
    """A budget below the cheapest evaluation cannot choose anything."""
    cheapest = float(stage.cost.time_ms(stage.cost.points_min))
    if d.rule == "budget" and d.budget_ms < cheapest:
        raise SettingsError(f"--budget-ms {d.budget_ms:g}: below the cheapest evaluation "
                            f"({cheapest:.4g} ms at n = {stage.n_min}); raise the budget or "
                            "lower --n-min")


def _search(stage: Stage, frames: list[Frame], T_init: np.ndarray, settings: Settings,
            checkpoint: Checkpoint | None, progress, timings: dict):
    """The seed grid and NSGA-II over the stage's objective: ``(SearchResult, seeds)``."""
    seeds = None
    if settings.search.seed_grid_deg:
        with _timed(timings, "seed_grid", progress):
            seeds = coarse_seeds(stage.feats, T_init, settings.search, settings.objective,
                                 settings.features.z_min, stage.cost, stage.n_max)
    if checkpoint is not None:
        # Everything the search depends on; the decision's settings are not (a checkpoint
        # stays valid when only --rule or --budget-ms change).
        searched = {k: v for k, v in settings.to_dict().items() if k != "decision"}
        checkpoint.cost_model = stage.cost.to_dict()
        checkpoint.key = fingerprint(
            searched, T_init, stage.n_min, stage.n_max,
            [(f.name, len(f.points), list(f.image.shape)) for f in frames],
            seeds if seeds is not None else np.zeros(0))
    if progress is not None:
        progress("search", 0, settings.search.gens)
    res = run_nsga2(stage.objective, settings.search, stage.n_min, stage.n_max,
                    _reporter(progress)("search"), seeds=seeds, checkpoint=checkpoint)
    timings["search"] = res.wall_s
    timings["search_objective"] = res.objective_s
    return res, seeds


def _refine(stage: Stage, res, frames: list[Frame], rings, T_init: np.ndarray,
            settings: Settings, progress, timings: dict, board: BoardStart | None = None):
    """Polish the front, test the near/far basins, and re-select the feature points at the
    estimate. Returns ``(stage, X, F, basin, evaluations)`` (the stage after re-selection)."""
    X, F, evaluations, basin = res.X, res.F, res.evaluations, None
    if not settings.decision.polish:
        return stage, X, F, basin, evaluations
    steps = 1 + int(settings.features.reselect)
    tick = (lambda k: progress("polish", k, steps)) if progress is not None else (lambda k: None)
    tick(0)
    with _timed(timings, "polish"):
        X, F, ev = polish_front(stage.objective, X, F, settings.search, stage.n_min,
                                stage.n_max, settings.decision.polish_iters)
        # A pose far from the start replaces the start's own basin only when the frames
        # clearly prefer it (search.basin).
        X, F, basin, ev2 = prefer_near(stage.objective, X, F, settings.search, stage.n_min,
                                       stage.n_max, settings.decision.polish_iters)
    evaluations += ev + ev2
    tick(1)
    if settings.features.reselect:
        # Choose the feature points again, by what is in view at the estimate rather than at
        # the initial guess: points the initial guess wrongly kept (or dropped) bias the
        # objective, and that bias grows with the initial error.
        with _timed(timings, "reselect"):
            T_est = stage.objective.transforms(X[np.argmin(F[:, 0])][None])[0]
            stage = Stage(frames, T_est, T_init, settings, rings=rings, cost=stage.cost,
                          view="after re-selecting points at the estimate",
                          images=stage.images, board=stage.board)
            X = X.copy()
            X[:, 6] = np.clip(X[:, 6], stage.n_min, stage.n_max)
            obj = stage.objective
            X, F, ev = polish_front(obj, X, obj.evaluate(X), settings.search, stage.n_min,
                                     stage.n_max, settings.decision.polish_iters)
        evaluations += ev + len(X)
        tick(2)
    return stage, X, F, basin, evaluations


def front_columns(stage: Stage, X: np.ndarray, F: np.ndarray, T_init: np.ndarray,
                  T_ref: np.ndarray | None, settings: Settings):
    """The front's extrinsics (k, 4, 4) and its per-solution columns (pareto.csv): cost
    figures, sampling error, share in view, per-group means, held-out score, deviation from the
    best-supported solution and, when known, the reference errors. Returns
    ``(T, columns, costs, best)``."""
    objective = stage.objective
    T = objective.transforms(X)
    parts = objective.chamfer(X)
    costs = objective.cost(X)
    columns = {"t_norm": costs["t_norm"], "m_norm": costs["m_norm"], "ms": costs["ms"],
               "bytes": costs["bytes"], "points": costs["points"],
               "sampling_se": parts["se"], "in_view": parts["in_view"]}
    short = {"depth_edge": "edge_px", "intensity_edge": "intensity_px", "smooth": "smooth_px"}
    for g, name in enumerate(GROUP_NAMES):
        columns[short[name]] = parts["mean"][:, g]
    if stage.holdout is not None:
        columns["chamfer_holdout"] = holdout_score(stage.holdout, T_init, settings.objective, X)
    # How far each solution's calibration moves projections from the best-supported one.
    best = int(np.argmin(F[:, 0]))
    check = stage.holdout if stage.holdout is not None else stage.scene
    columns["deviation_px"] = reprojection_deviation(
        T, T[best], [check.frame_xyz(f) for f in range(check.n_frames)],
        [f.camera for f in stage.feats], settings.features.z_min)
    if T_ref is not None:
        for k, v in pose_error(T, T_ref).items():
            columns[f"ref_{k}"] = v
    return T, columns, costs, best


