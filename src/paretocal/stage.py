"""The objective set up from the frames: features of every frame as seen from a pose, checks of
the scene, the range of ``n``, the measured cost model, and :class:`Stage` holding them."""

from __future__ import annotations

import dataclasses
import json
import logging
import os
from pathlib import Path

import numpy as np

from .config import ObjectiveSettings, SearchSettings, Settings
from .errors import DegenerateSceneError, ParetocalError, SettingsError
from .features.lidar import GROUP_NAMES
from .features.prepare import FrameFeatures, prepare_frame
from .lidar.rings import Rings
from .inputs import RingBrief, joint_camera
from .io.atomic import atomic_write_text
from .io.frame import Frame
from .io.text import load_json
from .objective import CalibrationObjective, build_scene, get_evaluator, measure_cost_model
from .objective.cost import CostModel
from .search.checkpoint import fingerprint
from .verdict import MIN_POINTS_PER_FRAME

log = logging.getLogger(__name__)


#: A frame with fewer Canny edge pixels is blank for the objective: a real photograph has
#: thousands (a KITTI frame about 30 000); a flat or black image gives none, or a few dozen
#: from noise and compression, which no LiDAR edge could be aligned with.
MIN_EDGE_PIXELS = 100


DEFAULT_N_MIN = 20


def prepare_features(frames: list[Frame], T_init: np.ndarray, settings: Settings,
                     progress=None, rings: list[Rings] | None = None,
                     images: list | None = None, sampling: bool = True) -> list[FrameFeatures]:
    """Features of every frame, each with its own seeded stream (independent of frame count).

    ``rings`` (from :func:`sweep_rings`) saves recovering each sweep's rings again, ``images``
    (the frames' ``FrameFeatures.image`` from an earlier stage with the same settings)
    extracting the image features again; ``sampling``: :func:`prepare_frame`'s.
    """
    seq = np.random.SeedSequence(settings.search.seed)
    out = []
    for k, (frame, child) in enumerate(zip(frames, seq.spawn(len(frames)))):
        out.append(prepare_frame(frame, T_init, settings.features, settings.objective,
                                 np.random.default_rng(child),
                                 rings=None if rings is None else rings[k],
                                 image=None if images is None else images[k],
                                 sampling=sampling))
        if progress is not None:
            progress(k + 1, len(frames))
    return out


def check_scene(feats: list[FrameFeatures], frames: list[Frame] | None = None,
                T_view: np.ndarray | None = None, z_min: float = 0.1,
                view: str | None = None) -> None:
    """Refuse scenes that cannot constrain the extrinsic, saying which frames and why.

    Raises :class:`DegenerateSceneError` when a frame's image has no edges, or when no frame
    has :data:`MIN_POINTS_PER_FRAME` LiDAR feature points in view at ``T_view``; the message
    then says whether the points lie behind the camera, outside the image or are simply too
    few, and whether the inverse or a half-turned extrinsic would see them. Frames with too
    few points among good ones are only reported (a warning): they add little, but no harm.

    ``view`` names the pose ``T_view`` in the messages when it is not the initial extrinsic
    (the pose the search reached, e.g. "after re-selecting points at the estimate (19.5 deg,
    31 cm from the initial extrinsic)"). Such a check is a later pass over the same frames:
    its sparse frames are logged at INFO only, since the frames were reported at the initial
    extrinsic and the verdict counts the frames that contribute (one warning per problem).
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
        cause = "; " + _view_diagnosis([frames[k] for k in few], T_view, z_min,
                                       initial=view is None)
    where = view or "at the initial extrinsic"
    if len(few) == len(feats):
        raise DegenerateSceneError(
            f"too few LiDAR feature points in view {where} (fewer than "
            f"{MIN_POINTS_PER_FRAME} per frame: {listed}){cause}")
    log.log(logging.INFO if view else logging.WARNING,
            "frame(s) %s: fewer than %d LiDAR feature points in view %s%s; they add little to "
            "the calibration", listed, MIN_POINTS_PER_FRAME, where, cause)


def _names(items: list[str], most: int = 5) -> str:
    more = f" and {len(items) - most} more" if len(items) > most else ""
    return ", ".join(items[:most]) + more


def _view_diagnosis(frames: list[Frame], T: np.ndarray, z_min: float,
                    initial: bool = True) -> str:
    """Why few points are in view at ``T``: a short clause for an error message.

    At the initial extrinsic (``initial``) it also tries the classic mistakes of an --init
    file; at a pose the search reached, those would blame the wrong thing."""
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
    if not initial:
        return why + ("; the search moved the extrinsic away from where the frames' points "
                      "are in view: check --init, or narrow the search box (--init-error, "
                      "--bound-r, --bound-t) to how far off the initial extrinsic may be")
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


class Stage:
    """The objective built from the frames' features as seen from ``T_view``.

    Parameters: the frames, ``T_view`` (the pose the feature points are chosen at: those in
    view, plus a margin), ``T_init`` (the objective's corrections are relative to it), the
    settings, an optional ``progress(done, total)``, the sweeps' rings (from
    :func:`paretocal.inputs.sweep_rings`), an optional cost model whose time line is reused (a
    checkpoint's, or the first stage's when the points are chosen again; without one the line
    comes from :func:`cost_model`) and ``view``: what ``T_view`` is, for messages, when it is
    not the initial extrinsic (the stage and its distance from ``T_init`` are then named, see
    :func:`check_scene`).

    ``images``: the image features of an earlier stage of the same frames and settings
    (:attr:`images`), which do not depend on the pose. ``sampling``: measure the LiDAR's
    sampling step in the image (:meth:`sampling_px`; a stage that only searches skips it).
    ``board``: the board's observations (:class:`paretocal.objective.board.BoardScene`, from
    :func:`paretocal.board.board_start`): the objective then adds the board's terms to the
    frames that show it (:class:`~paretocal.objective.board.BoardObjective`).

    Attributes: ``feats`` (search part of each frame's features), ``images`` (each frame's
    image features), ``scene``, ``holdout`` (held-out scene or None), ``n_min``, ``n_max``,
    ``cost`` (the measured cost model) and ``objective`` (corrections relative to ``T_init``).
    """

    def __init__(self, frames: list[Frame], T_view: np.ndarray,  # noqa: PLR0913
                 T_init: np.ndarray, settings: Settings, progress=None,
                 rings: list[Rings] | None = None, cost: CostModel | None = None,
                 view: str | None = None, images: list | None = None, sampling: bool = True,
                 board=None):
        feats_all = prepare_features(frames, T_view, settings, progress, rings, images, sampling)
        self.images = [f.image for f in feats_all]
        if view is not None:
            from .geometry import pose_error

            e = pose_error(T_view, T_init)
            view += (f" ({float(e['rotation_deg']):.1f} deg, {float(e['translation_cm']):.0f} "
                     "cm from the initial extrinsic)")
        check_scene(feats_all, frames, T_view, settings.features.z_min, view)
        o, z_min = settings.objective, settings.features.z_min
        parts = [f.split(o.holdout) for f in feats_all]
        self.feats = [p[0] for p in parts]
        self.scene = build_scene(self.feats, z_min, o.outside)
        self.holdout = (build_scene([p[1] for p in parts], z_min, o.outside)
                        if o.holdout > 0 else None)
        self.n_min, self.n_max = n_range(settings.search, self.scene.points_per_frame)
        self.cost = (cost.for_scene(self.scene, self.n_min, self.n_max) if cost is not None
                     else cost_model(self.scene, o.evaluator, T_view, self.n_min, self.n_max))
        self.objective = CalibrationObjective(self.scene, T_init, o, self.cost,
                                              [f.image.edge_uv for f in self.feats],
                                              ucb_k=settings.ucb_k)
        self.board = board
        if board is not None and board.n_boards:
            from .objective.board import BoardObjective

            self.objective = BoardObjective(self.objective, board)

    def sampling_px(self, frames=None) -> np.ndarray | None:
        """The LiDAR's sampling step in the image, (2,) px along a ring and between rings:
        the median over the frames (or the frames of index ``frames``) that measured it (None
        when none did)."""
        feats = self.feats if frames is None else [self.feats[k] for k in frames]
        got = [f.sampling_px for f in feats if f.sampling_px is not None]
        return np.median(np.array(got), axis=0) if got else None

    def camera_groups(self) -> dict | None:
        """The cameras of a joint calibration (frames seen through a mount, named
        ``CAMERA/FRAME`` by :func:`paretocal.inputs.joint_frames`): by camera name, the indices
        of its frames and its :meth:`sampling_px`; None for one camera."""
        if all(f.camera.mount is None for f in self.feats):
            return None
        groups: dict[str, list[int]] = {}
        for k, f in enumerate(self.feats):
            groups.setdefault(joint_camera(f.name), []).append(k)
        return {name: (idx, self.sampling_px(idx)) for name, idx in groups.items()}


def cost_model(scene, evaluator: str, T_view: np.ndarray, n_min: int, n_max: int) -> CostModel:
    """The cost model of ``scene`` on this machine: measured once, then read from a cache.

    Timing varies with the machine's load, and the budget rule chooses by the modelled time, so
    a model measured afresh on every run would make ``--budget-ms`` choose differently from run
    to run. The first measurement of a scene (same frames, view and ``n`` range) with an
    evaluator on a machine is therefore kept in ``cost-<key>.json`` under
    :func:`cache_dir` and used by later runs; ``probe["source"]`` records which it was.
    """
    evaluate = get_evaluator(evaluator)
    folder = cache_dir()
    key = fingerprint(_machine(evaluate), np.round(T_view, 6), scene.n_frames,
                      scene.nbytes_static, n_min, n_max,
                      [int(scene.points_used(n)) for n in
                       np.unique(np.linspace(n_min, n_max, 5).round().astype(np.int64))])
    path = folder / f"cost-{key[:20]}.json" if folder is not None else None
    if path is not None and path.is_file():
        try:
            line = CostModel.from_dict(load_json(path.read_text(encoding="utf-8"), path))
            return line.for_scene(scene, n_min, n_max, source=f"cache {path}")
        except (OSError, ValueError, TypeError, ParetocalError) as exc:
            log.info("%s: unreadable cost model (%s); measuring again", path, exc)
    cost = measure_cost_model(scene, evaluate, T_view, n_min, n_max)
    if cost.ms_per_point <= 1e-9:
        # The fit found no time per point (it was clamped): the measurement failed, so it is
        # not kept for later runs.
        log.warning("the evaluation time did not grow with the number of points (%s ms at %s "
                    "points): the cost model is unreliable on this machine now",
                    cost.probe["ms"], cost.probe["points"])
    elif path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(path, json.dumps(cost.to_dict()) + "\n")
        except OSError as exc:  # a read-only home: the run goes on with its measurement
            log.info("%s: cannot keep the cost model (%s)", path, exc)
    return cost


def cache_dir() -> Path | None:
    """Where measured cost models are kept: ``$PARETOCAL_CACHE_DIR`` (empty: nowhere, every
    run measures), else ``$XDG_CACHE_HOME/paretocal``, else ``~/.cache/paretocal``."""
    given = os.environ.get("PARETOCAL_CACHE_DIR")
    if given is not None:
        return Path(given) if given.strip() else None
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "paretocal"


def _machine(evaluate) -> dict:
    """What the time of an evaluation depends on besides the scene."""
    import platform

    from . import __version__

    cpu = platform.processor()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            cpu = next((ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")),
                       cpu)
    except OSError:
        pass
    threads = None
    try:
        import numba

        threads = numba.get_num_threads()
    except Exception:  # noqa: BLE001 - no numba: the numpy evaluator
        pass
    return {"version": __version__, "evaluator": f"{evaluate.__module__}.{evaluate.__name__}",
            "node": platform.node(), "cpu": cpu, "cpus": os.cpu_count(), "threads": threads}


def n_range(search: SearchSettings, points_per_frame: np.ndarray) -> tuple[int, int]:
    """The search's range of points per frame, validated against what the frames hold."""
    most = int(points_per_frame.max())
    s = search
    n_max = most if s.n_max is None else int(s.n_max)
    n_min = min(DEFAULT_N_MIN, n_max) if s.n_min is None else int(s.n_min)
    if n_max > most:
        raise SettingsError(f"--n-max {n_max}: the frames hold at most {most} feature points "
                            "per frame")
    if n_min > n_max:
        raise SettingsError(f"--n-min {n_min} is larger than the largest n ({n_max})")
    return n_min, n_max


def holdout_score(scene, T_init: np.ndarray, objective: ObjectiveSettings,
                  X: np.ndarray) -> np.ndarray:
    """Each solution's pose scored on every held-out point (no sampling-error term), shape (k,)."""
    dummy = CostModel(0.0, 1.0, 0.0, 1.0, 0, 1, {})
    obj = CalibrationObjective(scene, T_init, objective, dummy, ucb_k=0.0)
    Xa = np.array(X, dtype=np.float64, copy=True)
    Xa[:, 6] = int(scene.points_per_frame.max())
    return obj.chamfer(Xa)["f1"]


@dataclasses.dataclass(frozen=True)
class RingRecovery:
    """How the laser rings were recovered over the frames (:class:`FeatureCounts`).

    Attributes
    ----------
    methods : tuple of str
        The methods that recovered them, sorted, each once (:attr:`RingBrief.method`).
    min_purity : float
        The lowest purity over the frames (0 to 1): the share of the returns near the view
        that lie on their ring's cone.
    spacing_deg_median : float or None
        The first frame's median elevation gap between neighbouring rings (deg); None when
        it has fewer than two rings.
    """

    methods: tuple[str, ...]
    min_purity: float
    spacing_deg_median: float | None = None

    def to_dict(self) -> dict:
        """``{"methods", "min_purity", "spacing_deg_median"}``, as result.json writes it."""
        return {"methods": list(self.methods), "min_purity": self.min_purity,
                "spacing_deg_median": self.spacing_deg_median}

    @classmethod
    def from_dict(cls, doc: dict) -> "RingRecovery":
        """The summary read back from its :meth:`to_dict` form; a purity it lacks reads as 1
        (nothing to doubt), a spacing as None."""
        return cls(methods=tuple(str(m) for m in doc.get("methods") or ()),
                   min_purity=float(doc.get("min_purity", 1.0)),
                   spacing_deg_median=doc.get("spacing_deg_median"))


@dataclasses.dataclass(frozen=True)
class FrameCounts:
    """One frame's LiDAR feature points in view, per group (:class:`FeatureCounts`).

    Attributes
    ----------
    frame : str
        The frame's name.
    depth_edge, intensity_edge, smooth : int
        Its feature points of each group (:data:`~paretocal.features.lidar.GROUP_NAMES`).
    rings : RingBrief or None
        Its sweep's rings; None when none were recovered.
    """

    frame: str
    depth_edge: int
    intensity_edge: int
    smooth: int
    rings: RingBrief | None = None

    @property
    def edges(self) -> int:
        """Its edge points: depth and intensity edges."""
        return self.depth_edge + self.intensity_edge

    def to_dict(self) -> dict:
        """``{"frame", "depth_edge", "intensity_edge", "smooth", "rings"}``."""
        return {"frame": self.frame, "depth_edge": self.depth_edge,
                "intensity_edge": self.intensity_edge, "smooth": self.smooth,
                "rings": None if self.rings is None else self.rings.to_dict()}

    @classmethod
    def from_dict(cls, doc: dict) -> "FrameCounts":
        """The row read back from its :meth:`to_dict` form; a count it lacks reads as 0, a
        name as ``"?"``."""
        rings = doc.get("rings")
        return cls(frame=str(doc.get("frame", "?")), depth_edge=int(doc.get("depth_edge", 0)),
                   intensity_edge=int(doc.get("intensity_edge", 0)),
                   smooth=int(doc.get("smooth", 0)),
                   rings=RingBrief.from_dict(rings) if rings else None)


@dataclasses.dataclass(frozen=True)
class NoiseNote:
    """A frame whose depth edges are likely noise, and why (:func:`depth_edges_doubtful`).

    Attributes
    ----------
    frame : str
        The frame's name.
    reason : str
        Why, in words.
    """

    frame: str
    reason: str

    def to_dict(self) -> dict:
        """``{"frame", "reason"}``."""
        return {"frame": self.frame, "reason": self.reason}


@dataclasses.dataclass(frozen=True)
class FeatureCounts:
    """What the objective compares (:func:`feature_counts`; result.json ``features``, the
    ``features`` of ``paretocal check``).

    Attributes
    ----------
    per_frame_mean : dict of str to float
        Per feature group (:data:`~paretocal.features.lidar.GROUP_NAMES`), the mean number of
        feature points in view per frame (to 1 decimal).
    total : dict of str to int
        Per feature group, the feature points in view over all frames.
    rings : tuple of int
        The frames' ring counts, sorted, each once.
    ring_recovery : RingRecovery or None
        How the rings were recovered; None when no frame's were.
    frames_contributing : int
        The frames with enough feature points in view to constrain anything (at least
        :data:`~paretocal.verdict.MIN_POINTS_PER_FRAME`).
    per_frame : tuple of FrameCounts, shape (F,)
        Each frame's counts and rings, in the frames' order.
    noise : tuple of NoiseNote
        The frames whose depth edges are likely noise, each with why.
    """

    per_frame_mean: dict[str, float]
    total: dict[str, int]
    rings: tuple[int, ...]
    ring_recovery: RingRecovery | None
    frames_contributing: int
    per_frame: tuple[FrameCounts, ...]
    noise: tuple[NoiseNote, ...] = ()

    def to_dict(self) -> dict:
        """As result.json's ``features`` writes it: the nested records as dicts, the tuples
        as lists."""
        return {"per_frame_mean": dict(self.per_frame_mean), "total": dict(self.total),
                "rings": list(self.rings),
                "ring_recovery": None if self.ring_recovery is None
                else self.ring_recovery.to_dict(),
                "frames_contributing": self.frames_contributing,
                "per_frame": [p.to_dict() for p in self.per_frame],
                "noise": [n.to_dict() for n in self.noise]}

    @classmethod
    def from_dict(cls, doc: dict) -> "FeatureCounts":
        """The counts read back from their :meth:`to_dict` form; a key it lacks reads as
        empty (no frames, no rings, none contributing).

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form.
        """
        rec = doc.get("ring_recovery")
        return cls(per_frame_mean={str(g): float(v)
                                   for g, v in (doc.get("per_frame_mean") or {}).items()},
                   total={str(g): int(v) for g, v in (doc.get("total") or {}).items()},
                   rings=tuple(int(r) for r in doc.get("rings") or ()),
                   ring_recovery=RingRecovery.from_dict(rec) if rec else None,
                   frames_contributing=int(doc.get("frames_contributing", 0)),
                   per_frame=tuple(FrameCounts.from_dict(p) for p in doc.get("per_frame") or ()),
                   noise=tuple(NoiseNote(frame=str(n["frame"]), reason=str(n["reason"]))
                               for n in doc.get("noise") or ()))


def feature_counts(feats: list[FrameFeatures]) -> FeatureCounts:
    """What the objective compares, for result.json and ``check``: the feature points per group
    (mean per frame, total, and ``per_frame`` with each frame's rings), the frames that
    contribute, and ``noise``: the frames whose depth edges are likely noise, each with why
    (their rings do not fit a spinning LiDAR, so "neighbours along a ring" mix lasers)."""
    per = [f.counts() for f in feats]
    total = {g: int(sum(p[g] for p in per)) for g in GROUP_NAMES}
    summaries = [f.rings for f in feats if f.rings]
    ring_info = None
    if summaries:
        ring_info = RingRecovery(methods=tuple(sorted({s["method"] for s in summaries})),
                                 min_purity=min(s["purity"] for s in summaries),
                                 spacing_deg_median=summaries[0]["spacing_deg_median"])
    return FeatureCounts(
        per_frame_mean={g: round(total[g] / len(feats), 1) for g in GROUP_NAMES},
        total=total, rings=tuple(sorted({f.n_rings for f in feats})),
        ring_recovery=ring_info,
        # Frames with enough feature points in view to constrain anything.
        frames_contributing=int(sum(len(f.xyz) >= MIN_POINTS_PER_FRAME for f in feats)),
        per_frame=tuple(FrameCounts(frame=f.name, depth_edge=c["depth_edge"],
                                    intensity_edge=c["intensity_edge"], smooth=c["smooth"],
                                    rings=RingBrief.from_dict(f.rings) if f.rings else None)
                        for f, c in zip(feats, per)),
        noise=tuple(NoiseNote(frame=f.name, reason=why) for f in feats
                    if (why := depth_edges_doubtful(f.rings))))


def log_features(feats: list[FrameFeatures]) -> None:
    """The run's log: each frame's feature points per group and its rings (INFO), and one
    warning naming the frames whose depth edges are likely noise (:func:`depth_edges_doubtful`)."""
    for f in feats:
        c, r = f.counts(), f.rings or {}
        log.info("frame %s: %d depth edges, %d intensity edges, %d smooth points in view; %s "
                 "rings (%s, purity %.3f)", f.name, c["depth_edge"], c["intensity_edge"],
                 c["smooth"], r.get("n_rings", "?"), r.get("method", "?"), r.get("purity", 0.0))
    doubtful = [(f.name, why) for f in feats if (why := depth_edges_doubtful(f.rings))]
    if doubtful:
        log.warning("the depth edges of %d of %d frames are likely noise (frame %s: %s); the "
                    "calibration leans on them: give the clouds' ring field or lidar_pose in "
                    "calib.yaml", len(doubtful), len(feats), doubtful[0][0], doubtful[0][1])


def depth_edges_doubtful(rings: dict | None) -> str | None:
    """Why a frame's depth edges are likely noise, or None: they are the near sides of range
    jumps between neighbours on a ring, so rings that are not the lasers' (too few, or points
    off their ring's cone: purity below MIN_PURITY) make neighbours of returns that are not."""
    from .lidar.rings import MIN_PURITY, MIN_RINGS

    if not rings:
        return None
    if rings["n_rings"] < MIN_RINGS:
        return (f"{rings['n_rings']} laser rings found (a spinning LiDAR has at least "
                f"{MIN_RINGS})")
    if rings["purity"] < MIN_PURITY:
        return (f"only {100 * rings['purity']:.0f} % of the returns near the view lie on their "
                "ring's cone")
    return None
