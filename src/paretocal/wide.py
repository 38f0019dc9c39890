"""The wide start: the rotation from the motion both sensors see, then the edge objective over
what the motion leaves open.

From a start off by tens of degrees and more than a metre, the edge objective's best pose over
the whole box is often not the truth (a camera moved metres along its optical axis and turned a
little scores nearly as well), and no amount of search fixes that. Motion does not share that
failure: the camera's direction of travel (visual odometry) is the LiDAR's (LiDAR odometry)
turned by the extrinsic's rotation, whatever the translation, so a recording that moves gives two
of the three angles to a fraction of a degree (:func:`paretocal.egomotion.rotation_from_motion`;
all three when it turns). With those two angles held near the motion's, the edge objective
is searched over what is left: the angle about the direction of travel and the camera's
position within the stated error. Its basin there is narrow along the camera's optical axis,
where a wrong pose metres along that axis has a wide one, so the search is stratified along the
optical axis: a differential evolution (scipy) in each slice of :data:`STRATUM_SHARE` of the
stated translation error, over the free angle, the two lateral offsets, the slice's depth and
the two motion angles within their disagreement. The best slices are polished in all six
degrees of freedom. Photo-consistency across the frames (:mod:`paretocal.objective.photo`, an
objective that shares no feature with the edges) chooses between polished poses in distinct
basins, which the edges can confuse and it does not; the edge objective chooses within one.

The points a search compares are chosen at its start, and from a start metres off they are not
those the truth sees: scored with points chosen at each pose's own view, the truth wins by a wide
margin where, with the start's points, a wrong pose can win. So the search runs in rounds, each
from the pose the last one kept, until two agree (at most :data:`ROUNDS`). The pose kept starts
the usual calibration, with a narrower stated error (:data:`AFTER_DEG`, :data:`AFTER_M`).

The stage applies only when the stated initial error is wide (:func:`wanted`: beyond
:data:`WIDE_DEG` or :data:`WIDE_M`, the box the search alone has been measured in) and the
recording moves; otherwise it says why it could not (a static rig, too few frames, no direction
of travel both sensors resolve), and the calibration goes on from the start as given.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from .config import Settings
from .crosscheck import MIN_FRAMES, RecordingMotion, motion_tolerance_deg, recording_motion
from .egomotion import rotation_from_motion
from .geometry import correction_params, invert, pose_error
from .io.frame import Frame
from .objective.photo import UNSEEN_COST, PhotoScene, build_photo_scene, photo_cost
from .quality import local_optimum
from .search.basin import AMBIGUOUS_P, CLEAR_P, USABLE_DEG, USABLE_M, paired_preference
from .stage import Stage


#: The stage runs (``search.wide = "auto"``) when the stated initial error exceeds these (deg,
#: m): the box the search alone reaches the truth from (20 of 20 KITTI starts from +-10 deg /
#: 0.25 m; 4 of 20 from +-20 deg / 1.5 m).
WIDE_DEG = 10.0
WIDE_M = 0.3
#: The stated error of the calibration that follows a wide start (deg, m): the wide start
#: lands within a few tenths of a degree and a few cm when it finds the truth's basin.
AFTER_DEG = 3.0
AFTER_M = 0.15
#: Depth slices of the stratified search, as a share of the stated translation error.
STRATUM_SHARE = 1.0 / 3.0
#: Differential evolution in each slice: population per dimension and generations.
DE_POPSIZE = 10
DE_GENERATIONS = 40
#: scipy's relative convergence tolerance of a slice's differential evolution (0: every
#: slice runs all its generations).
DE_TOL = 0.0
#: Share of the view's points the slices' search compares (the polish compares every one).
#: KITTI drive, 10 starts from +-20 deg / 1.5 m: with every point 10 of 10 found the truth,
#: with half of them 10 of 10 in half the search time, with a quarter 8 of 10 (288 cm off).
SEARCH_SHARE = 0.5
#: Slices whose best pose is polished in six degrees of freedom.
POLISHED = 5
#: Rounds of the search at most: each from the pose the last one kept, until two agree
#: within :data:`AFTER_DEG` / :data:`AFTER_M`.
ROUNDS = 3
#: Map points of the photo-consistency check.
PHOTO_POINTS = 30_000
#: Poses farther apart than this (m, deg) are distinct basins for photo-consistency, which
#: does not resolve poses a few decimetres apart (KITTI: poses 34 and 37 cm from the reference
#: scored within 0.006 of it) but told every basin a metre or more away from the truth's.
PHOTO_DISTINCT_M = 0.5
PHOTO_DISTINCT_DEG = 2.0
#: The photo-consistency check's paired bootstrap resamples the map in blocks of this size (m):
#: neighbouring points read the same image patch, so they are not independent evidence.
PHOTO_BLOCK_M = 2.0
PHOTO_RESAMPLES = 400


@dataclass(frozen=True)
class PhotoCheck:
    """Whether photo-consistency agrees with the calibration that followed a wide start
    (:func:`photo_check`).

    Attributes
    ----------
    agree : bool
        False when a pose in a distinct basin is clearly more photo-consistent than the result.
    result : float
        The result's photo-consistency cost.
    rival : float or None
        The most photo-consistent distinct pose's cost (None: no distinct pose was tried).
    separation_deg : float or None
        Its rotation from the result (deg).
    separation_m : float or None
        Its translation from the result (m).
    p : float or None
        The share of the paired bootstrap's resamples in which it is not better.
    """

    agree: bool
    result: float
    rival: float | None = None
    separation_deg: float | None = None
    separation_m: float | None = None
    p: float | None = None

    def to_dict(self) -> dict:
        """As ``result.json``'s ``wide_start.photo_check`` (cm, rounded)."""
        return {"agree": bool(self.agree), "result": round(float(self.result), 4),
                "rival": None if self.rival is None else round(float(self.rival), 4),
                "separation_deg": (None if self.separation_deg is None
                                   else round(float(self.separation_deg), 2)),
                "separation_cm": (None if self.separation_m is None
                                  else round(100.0 * float(self.separation_m), 1)),
                "p": None if self.p is None else round(float(self.p), 4)}


@dataclass
class WideStart:
    """What the wide start did (:func:`wide_start`).

    Attributes
    ----------
    T : ndarray, shape (4, 4), or None
        The start found (``T_cam_lidar``), None when the stage could not apply.
    T_given : ndarray, shape (4, 4)
        The start given.
    reasons : list of str
        Why the stage could not apply, or what the motion leaves open, in words.
    motion : dict
        Directions and turns used, reversed pairs, the free axis (LiDAR frame), the motion
        rotation's change from the start (deg) and its residual (deg), the pairs' stride.
    basins : list of dict
        The polished poses, the one kept first: ``f`` (the edge objective, px), ``photo``
        (the photo-consistency cost), ``separation_deg`` and ``separation_cm`` from the one
        kept, ``T``.
    disagreement : str or None
        In words, when the last round's edge objective and photo-consistency preferred poses
        in distinct basins (:data:`PHOTO_DISTINCT_M`, :data:`PHOTO_DISTINCT_DEG`): the
        photo-consistent one is kept.
    ambiguity : str or None
        In words, when the last round's pose kept and a distinct runner-up (more than 1 deg
        or 10 cm apart) are not told apart by the frames (paired test, p >= 0.05): the
        verdict's reason.
    evaluations : int
        Objective evaluations of the search and the polish.
    seconds : dict
        Wall time of the odometry, the search and the polish (s).
    images : list or None
        The frames' image features (:attr:`paretocal.stage.Stage.images`), which do not
        depend on the pose: each round and the calibration that follows reuse them.
    photo : PhotoCheck or None
        The photo-consistency check of the calibration that followed (:func:`photo_check`).
    scene : PhotoScene or None
        The photo-consistency map (kept for :func:`photo_check`; not written).
    tried : list of ndarray
        Every round's polished poses (4, 4) (kept for :func:`photo_check`; not written).
    seed : int
        The search's seed (:func:`photo_check`'s bootstrap).
    recording : RecordingMotion or None
        The motion of both sensors (the verdict's motion check reads it; not written).
    """

    T: np.ndarray | None
    T_given: np.ndarray
    reasons: list = field(default_factory=list)
    motion: dict = field(default_factory=dict)
    basins: list = field(default_factory=list)
    disagreement: str | None = None
    ambiguity: str | None = None
    comparison: dict | None = None
    evaluations: int = 0
    seconds: dict = field(default_factory=dict)
    rounds: list = field(default_factory=list)
    images: list | None = field(default=None, repr=False)
    photo: PhotoCheck | None = None
    scene: PhotoScene | None = field(default=None, repr=False)
    seed: int = 0
    tried: list = field(default_factory=list, repr=False)
    recording: RecordingMotion | None = field(default=None, repr=False)

    @property
    def applied(self) -> bool:
        return self.T is not None

    @property
    def disagree(self) -> bool:
        return self.disagreement is not None

    @property
    def ambiguous(self) -> bool:
        return self.ambiguity is not None

    def to_dict(self) -> dict:
        """For result.json: plain numbers and lists."""
        moved = pose_error(self.T, self.T_given) if self.T is not None else None
        found = [r for r in (self.disagreement, self.ambiguity) if r]
        return {"applied": self.applied, "reasons": list(self.reasons) + found,
                "T_given": np.asarray(self.T_given).tolist(),
                "T_found": None if self.T is None else np.asarray(self.T).tolist(),
                "moved_deg": None if moved is None else round(float(moved["rotation_deg"]), 3),
                "moved_cm": None if moved is None else round(float(moved["translation_cm"]), 2),
                "motion": self.motion, "basins": self.basins, "ambiguous": self.ambiguous,
                "ambiguity": self.ambiguity, "disagree": self.disagree, "rounds": self.rounds,
                "comparison": self.comparison,
                "photo_check": None if self.photo is None else self.photo.to_dict(),
                "evaluations": int(self.evaluations),
                "seconds": {k: round(float(v), 2) for k, v in self.seconds.items()}}


def wanted(settings: Settings) -> bool:
    """Whether the settings ask for the wide start: ``search.wide`` "on", or "auto" with a
    stated initial error beyond :data:`WIDE_DEG` or :data:`WIDE_M`."""
    s = settings.search
    if s.wide == "on":
        return True
    return s.wide == "auto" and (s.init_error_deg > WIDE_DEG or s.init_error_m > WIDE_M)


def after_settings(settings: Settings) -> Settings:
    """The settings of the calibration that follows a wide start: the stated error narrowed to
    :data:`AFTER_DEG` / :data:`AFTER_M` (never wider than stated)."""
    s = settings.search
    return settings.replace(search={"init_error_deg": min(AFTER_DEG, s.init_error_deg),
                                    "init_error_m": min(AFTER_M, s.init_error_m),
                                    "bound_t_m": None, "bound_r_deg": None})


def wide_start(frames: list[Frame], T_init: np.ndarray, settings: Settings,
               rings=None, progress=None) -> WideStart:
    """A start within a few tenths of a degree of the truth from one tens of degrees off.

    Parameters
    ----------
    frames : list of Frame
        The frames after the LiDAR steps (located, de-skewed), in time order.
    T_init : ndarray, shape (4, 4)
        The start given (``T_cam_lidar``).
    settings : Settings
        ``search.init_error_deg`` and ``init_error_m`` bound the search; ``search.seed`` seeds
        it; the objective's settings are the calibration's.
    rings : list, optional
        The sweeps' rings (:func:`paretocal.inputs.sweep_rings`).
    progress : callable, optional
        ``progress(done, total)`` over the search's slices.

    Returns
    -------
    WideStart
        ``T`` None, with reasons, when the stage cannot apply.
    """
    T0 = np.asarray(T_init, dtype=np.float64)
    out = WideStart(None, T0.copy())
    if len(frames) < MIN_FRAMES:
        out.reasons.append(f"a wide start needs the rig to move over at least {MIN_FRAMES} "
                           f"frames; there are {len(frames)}")
        return out
    s = settings.search
    motion = recording_motion(frames, s.seed)
    out.recording = motion
    out.seconds["odometry"] = motion.seconds
    lo, pairs, pairs_out = motion.lidar, motion.pairs, motion.camera
    if not motion.moves:
        out.reasons.append(f"{motion.still_text}; a static rig gives no direction of travel: "
                           f"give a start within {WIDE_DEG:g} deg / {WIDE_M:g} m, or frames "
                           "taken while moving")
        return out
    t0 = time.perf_counter()
    mr = rotation_from_motion(lo, pairs_out, T0[:3, :3], T0[:3, 3], t_sigma_m=s.init_error_m)
    out.seconds["odometry"] += time.perf_counter() - t0
    free_lidar = None if mr.free_axis is None else (mr.R.T @ mr.free_axis)
    out.motion = {"lidar_odometry": lo.method, "pairs": len(pairs),
                  "stride": int(np.median([j - i for i, j in pairs])) if pairs else None,
                  "travel_m": round(motion.travel_m, 3),
                  "directions": mr.directions, "turns": mr.turns, "reversed": mr.reversed,
                  "free_axis_lidar": None if free_lidar is None
                  else [round(float(v), 4) for v in free_lidar],
                  "change_deg": round(float(mr.change_deg), 3),
                  "residual_deg": None if not np.isfinite(mr.residual_deg)
                  else round(float(mr.residual_deg), 3),
                  "standing_pairs": int(np.sum(lo.standing))}
    if not mr.usable:
        out.reasons += list(mr.reasons)
        why = Counter(p.reason.split(":")[0].split(" (")[0] for p in pairs_out if p.reason)
        if why:
            out.reasons.append(f"camera pairs {len(pairs_out)} (frames {pairs[0][1] - pairs[0][0]}"
                               " or more apart), none with a direction of travel: "
                               + ", ".join(f"{k} x{n}" for k, n in why.most_common()))
        out.reasons.append("the motion gives no rotation: give a start within "
                           f"{WIDE_DEG:g} deg / {WIDE_M:g} m")
        return out
    out.reasons += [r for r in mr.reasons if "not observed" in r]

    # The photo-consistency map, from a seeded sample of each sweep (projecting every return
    # of every sweep into every frame to choose the map would cost seconds). It is built in a
    # thread beside the first round (numpy and OpenCV work, no parallel kernel): the rounds
    # read it only after their search.
    out.seconds["photo"] = 0.0                      # the thread sets it (key order kept)
    maps = ThreadPoolExecutor(max_workers=1)
    try:
        photo_map = maps.submit(_photo_map, frames, lo.poses, _motion_start(mr, T0), s.seed,
                                out)
        _rounds(frames, rings, settings, T0, lo, pairs_out, mr, photo_map, out, progress)
    finally:
        maps.shutdown(wait=True)
    return out


def _photo_map(frames: list[Frame], poses: np.ndarray, view: np.ndarray, seed: int,
               out: WideStart) -> PhotoScene:
    """The photo-consistency map of :data:`PHOTO_POINTS` points seen from ``view``; stored in
    ``out`` with its wall time."""
    t3 = time.perf_counter()
    rng = np.random.default_rng(seed)
    per = 4 * PHOTO_POINTS // len(frames)
    sample = [f.points if len(f.points) <= per
              else f.points[np.sort(rng.choice(len(f.points), per, replace=False))]
              for f in frames]
    scene = build_photo_scene(sample, poses, [f.image for f in frames],
                              [f.camera for f in frames], view=view,
                              max_points=PHOTO_POINTS, rng=seed)
    out.seconds["photo"] = time.perf_counter() - t3
    out.scene, out.seed = scene, int(seed)
    return scene


def _rounds(frames, rings, settings: Settings, T0: np.ndarray, lo, pairs_out, mr,  # noqa: PLR0913
            scene: Future[PhotoScene], out: WideStart, progress) -> None:
    """The search's rounds (:func:`wide_start`); the pose kept in ``out.T``."""
    s = settings.search
    # Rounds: the search from the start, then again from the pose it kept (the points are
    # chosen at the motion's rotation with the start's camera centre, so a start metres off
    # sees other points than the truth does: a second look from the first answer sees what
    # the truth sees). Photo-consistency is scored on one map for every round.
    T_start, previous = T0, None
    for r in range(ROUNDS):
        mr_r = mr if r == 0 else rotation_from_motion(lo, pairs_out, T_start[:3, :3],
                                                      T_start[:3, 3],
                                                      t_sigma_m=s.init_error_m)
        Tm = _motion_start(mr_r, T_start)
        found = _search_round(frames, rings, settings, Tm, mr_r, T_start, scene, out,
                              progress)
        out.rounds.append({"start_deg": round(float(pose_error(T_start, T0)["rotation_deg"]),
                                              3),
                           "kept": found["kept"]})
        T_start = found["T"][0]
        if previous is not None:
            e = pose_error(T_start, previous)
            if e["rotation_deg"] <= AFTER_DEG and e["translation_cm"] <= 100 * AFTER_M:
                break
        previous = T_start
    out.T = T_start


def _motion_start(mr, T_start: np.ndarray) -> np.ndarray:
    """The motion's rotation with the camera centre where ``T_start`` puts it, (4, 4)."""
    c0 = -T_start[:3, :3].T @ T_start[:3, 3]
    Tm = np.eye(4)
    Tm[:3, :3] = mr.R
    Tm[:3, 3] = -mr.R @ c0
    return Tm


def _search_round(frames, rings, settings: Settings, Tm: np.ndarray, mr, T_start: np.ndarray,
                  scene: Future[PhotoScene], out: WideStart, progress) -> dict:
    """One round of the stratified search about ``Tm`` (the box about ``T_start``'s camera
    centre); the polished poses ``T`` (k, 4, 4), the one kept first, and what was kept.
    Sets ``out``'s basins, comparison, disagreement and ambiguity to the round's and adds to
    its counters."""
    from scipy.optimize import differential_evolution
    from scipy.spatial.transform import Rotation

    s = settings.search
    c0 = -T_start[:3, :3].T @ T_start[:3, 3]
    t1 = time.perf_counter()
    stage = Stage(frames, Tm, Tm, settings, rings=rings, view="the motion's rotation",
                  images=out.images, sampling=False)
    out.images = stage.images
    obj = stage.objective
    n = max(1, round(SEARCH_SHARE * stage.n_max))
    axes = _search_axes(mr)
    band = min(motion_tolerance_deg(mr.residual_deg), s.init_error_deg)
    Rc = mr.R                                        # camera axes (rows), LiDAR frame
    half = s.init_error_m * np.abs(Rc).sum(axis=1)  # the box seen along the camera's axes
    Minv = invert(Tm)

    def corrections(P: np.ndarray) -> np.ndarray:
        """(C, 7) corrections of ``Tm`` for search points P (C, 6): three angles (deg)
        about ``axes`` and the camera's offset along its own x, y, z (m)."""
        R = Rotation.from_rotvec(np.radians(P[:, :3]) @ axes).as_matrix() @ Tm[:3, :3]
        c = c0 + P[:, 3:] @ Rc
        T = np.tile(np.eye(4), (len(P), 1, 1))
        T[:, :3, :3] = R
        T[:, :3, 3] = -np.einsum("nij,nj->ni", R, c)
        return np.column_stack([correction_params(Minv[None] @ T), np.full(len(P), n)])

    def fun(P: np.ndarray) -> np.ndarray:           # scipy's vectorised form: P (6, C)
        P = np.atleast_2d(P.T)
        inside = np.all(np.abs(P[:, 3:] @ Rc) <= s.init_error_m, axis=1)
        f = np.full(len(P), 1e6)
        if inside.any():
            f[inside] = obj.chamfer(corrections(P[inside]), ucb_k=0.0)["f1"]
            out.evaluations += int(inside.sum())
        return f

    # About the free axis the start's whole rotation error may lie: each axis off by up to
    # the stated error is a turn of up to sqrt(3) times it.
    first = min(math.sqrt(3.0) * s.init_error_deg, 180.0) if mr.free_axis is not None else band
    step = STRATUM_SHARE * s.init_error_m
    depths = np.arange(-half[2] + step / 2, half[2], step)
    best = []
    for k, dz in enumerate(depths):
        bounds = [(-first, first), (-band, band), (-band, band), (-half[0], half[0]),
                  (-half[1], half[1]), (dz - step / 2, dz + step / 2)]
        res = differential_evolution(fun, bounds, popsize=DE_POPSIZE, maxiter=DE_GENERATIONS,
                                     vectorized=True, updating="deferred", polish=False,
                                     tol=DE_TOL, seed=s.seed + k)
        best.append((float(res.fun), res.x))
        if progress is not None:
            progress(k + 1, len(depths))
    out.seconds["search"] = out.seconds.get("search", 0.0) + time.perf_counter() - t1
    t2 = time.perf_counter()
    best.sort(key=lambda b: b[0])
    Z = local_optimum(obj, corrections(np.array([b[1] for b in best[:POLISHED]])))
    f = obj.chamfer(Z, ucb_k=0.0)["f1"]
    out.evaluations += len(Z)
    order = np.argsort(f)
    Z, f = Z[order], f[order]
    T = obj.transforms(Z)
    pc = photo_cost(scene.result(), T)["cost"]
    out.tried += list(T)
    out.seconds["polish"] = out.seconds.get("polish", 0.0) + time.perf_counter() - t2
    # Photo-consistency tells far basins apart where the edges can be fooled (a camera
    # metres along its optical axis), though not poses a few decimetres apart.
    sep = [pose_error(Tk, T[0]) for Tk in T]
    far = [k for k, e in enumerate(sep) if e["translation_cm"] > 100 * PHOTO_DISTINCT_M
           or e["rotation_deg"] > PHOTO_DISTINCT_DEG]
    pick = min(far, key=lambda k: pc[k]) if far else 0
    disagree = bool(far and pc[pick] < pc[0])
    if disagree:
        reorder = np.array([pick] + [k for k in range(len(T)) if k != pick])
        Z, f, T, pc = Z[reorder], f[reorder], T[reorder], pc[reorder]
    out.basins = []
    for Tk, fk, ck in zip(T, f, pc):
        e = pose_error(Tk, T[0])
        out.basins.append({"f": round(float(fk), 4), "photo": round(float(ck), 4),
                           "separation_deg": round(float(e["rotation_deg"]), 3),
                           "separation_cm": round(float(e["translation_cm"]), 2),
                           "T": np.round(Tk, 6).tolist()})
    out.disagreement = out.ambiguity = out.comparison = None
    if disagree:
        e, k = out.basins[1], out.basins[0]
        out.disagreement = (
            f"the edge objective and photo-consistency prefer poses {e['separation_deg']:.1f} "
            f"deg / {e['separation_cm']:.0f} cm apart; the photo-consistent one is kept "
            f"(photo {k['photo']:.3f} against {e['photo']:.3f})")
    rival = next((k for k, b in enumerate(out.basins)
                  if b["separation_deg"] > USABLE_DEG or b["separation_cm"] > 100 * USABLE_M),
                 None)
    if rival is not None:
        cmp = paired_preference(obj, Z[rival], Z[0])
        out.comparison = {k: (round(float(v), 5) if isinstance(v, float) else v)
                          for k, v in cmp.items()}
        p = cmp["p"]
        if not (np.isfinite(p) and p < AMBIGUOUS_P):
            b = out.basins[rival]
            out.ambiguity = (
                f"the wide search found two poses {b['separation_deg']:.1f} deg / "
                f"{b['separation_cm']:.0f} cm apart that the frames do not tell apart "
                f"({cmp['frames_far_better']} of {cmp['frames']} frames prefer the one kept): "
                "give a better start, or frames with structure at several distances")
    return {"T": T, "kept": {"f": out.basins[0]["f"], "photo": out.basins[0]["photo"],
                             "by": "photo" if disagree else "edges"}}


def photo_check(wide: WideStart, T_result: np.ndarray) -> PhotoCheck | None:
    """Whether photo-consistency agrees with the calibration that followed a wide start.

    The edge objective and photo-consistency share no feature, so a bias that every frame's
    edges share (a wrong basin the edges prefer) shows as a pose photo-consistency prefers
    elsewhere. The result is compared with every pose the wide start polished in any round and
    with the start given, those in a distinct basin (farther than :data:`PHOTO_DISTINCT_M` or
    :data:`PHOTO_DISTINCT_DEG`: photo-consistency does not resolve poses a few decimetres
    apart); the check fails when the most photo-consistent of them is clearly more so than
    the result: in all but :data:`~paretocal.search.basin.CLEAR_P` of a paired bootstrap over
    the map (blocks of :data:`PHOTO_BLOCK_M`, seeded; two poses of one basin a few decimetres
    apart differ by less than that noise).

    Parameters
    ----------
    wide : WideStart
        An applied wide start (its map and the poses it tried).
    T_result : ndarray, shape (4, 4)
        The calibration's result (``T_cam_lidar``).

    Returns
    -------
    PhotoCheck or None
        None when the wide start did not apply. Also stored as ``wide.photo``.
    """
    if not wide.applied or wide.scene is None:
        return None
    T_result = np.asarray(T_result, dtype=np.float64)
    others = []
    for T in list(wide.tried) + [wide.T_given]:
        e = pose_error(T, T_result)
        if e["translation_cm"] > 100 * PHOTO_DISTINCT_M or e["rotation_deg"] > PHOTO_DISTINCT_DEG:
            others.append((T, e))
    pc = photo_cost(wide.scene, np.array([T_result] + [T for T, _ in others]))
    cost = pc["cost"]
    out = PhotoCheck(agree=True, result=float(cost[0]))
    if others:
        k = 1 + int(np.argmin(cost[1:]))
        e = others[k - 1][1]
        p = _photo_p(wide.scene.xyz, pc["point_weight"][[0, k]], pc["point_variance"][[0, k]],
                     float(pc["prior"]), wide.seed)
        out = PhotoCheck(agree=bool(p >= CLEAR_P), result=float(cost[0]), rival=float(cost[k]),
                         separation_deg=float(e["rotation_deg"]),
                         separation_m=float(e["translation_cm"]) / 100.0, p=p)
    wide.photo = out
    return out


def _photo_p(xyz: np.ndarray, wt: np.ndarray, var: np.ndarray, prior: float,
             seed: int) -> float:
    """The share of a paired Poisson bootstrap over the map's blocks in which the second pose
    is not more photo-consistent than the first (``wt``, ``var``: (2, N) per-point weights and
    variances, :func:`~paretocal.objective.photo.photo_cost`)."""
    _, block = np.unique(np.floor(xyz / PHOTO_BLOCK_M).astype(np.int64), axis=0,
                         return_inverse=True)
    block = block.ravel()
    nb = int(block.max()) + 1
    num = np.array([np.bincount(block, wt[i] * var[i], nb) for i in range(2)])   # (2, B)
    den = np.array([np.bincount(block, wt[i], nb) for i in range(2)])
    w = np.random.default_rng(seed).poisson(1.0, (PHOTO_RESAMPLES, nb)).astype(np.float64)
    cost = (w @ num.T + prior * UNSEEN_COST) / (w @ den.T + prior)             # (R, 2)
    return float(np.mean(cost[:, 1] >= cost[:, 0]))


def _search_axes(mr) -> np.ndarray:
    """(3, 3) rotation axes (rows, camera frame) of the search's three angles: the motion's
    free axis first (the mean direction of travel; the optical axis when every angle is
    observed), then two across it."""
    a = mr.free_axis if mr.free_axis is not None else np.array([0.0, 0.0, 1.0])
    a = np.asarray(a, dtype=np.float64) / np.linalg.norm(a)
    e = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    e /= np.linalg.norm(e)
    return np.vstack([a, e, np.cross(a, e)])


__all__ = ["AFTER_DEG", "AFTER_M", "WIDE_DEG", "WIDE_M", "PhotoCheck", "WideStart",
           "after_settings", "photo_check", "wanted", "wide_start"]
