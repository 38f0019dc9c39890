"""The board stage: a recording with a checkerboard in view gives its start and its board terms.

For every frame, the board is found in the image (:mod:`paretocal.features.board`: corners,
pose, plane, outline) and in the sweep (:mod:`paretocal.lidar.board`: what moved, a planar
patch of the board's size). The patch seen at the image board's range and angle is taken as
the board (:func:`associate`), then the closed form from the frames' planes
(:mod:`paretocal.search.board`) gives the extrinsic with no initial guess; each frame's patch
is chosen again as the one that fits it, and frames that fit no patch are left out. The
returns on each board are then taken again at that extrinsic (near its plane, inside its
outline), with where each scan line enters and leaves it, and the board's residuals are
minimised (:func:`paretocal.search.board.refine`), twice. The result is the calibration's start
(:class:`BoardStart`, ``T``) and the board's terms of its objective (``scene``,
:class:`paretocal.objective.board.BoardScene`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from .config import Settings
from .features.board import BoardView, find_board
from .geometry import pose_error
from .io.board import Board
from .io.frame import Frame
from .lidar.board import (PLANE_SIGMAS, CloudBoard, SweepGeometry, board_candidates,
                          fit_plane, points_on_board, scan_line_ends, sensor_coords,
                          sweep_geometry)
from .objective.board import BoardScene, outline_residuals
from .search.board import Conditioning, closed_form, conditioning, misfit, refine
from .verdict import Intervals

log = logging.getLogger(__name__)

#: Rounds of choosing each frame's patch by the closed form's fit, then fitting again.
ASSOCIATION_ROUNDS = 3
#: Rounds of taking the returns on the boards at the extrinsic and refining it.
REFINE_ROUNDS = 2
#: Share of the search's generations after the board's start: the search there traces the
#: front near a start within a fraction of a degree, it does not look for the basin (on
#: walkway_a: 0.232 deg / 0.71 cm from the reference with 30 generations, 0.223 deg / 0.70 cm
#: with 120).
SEARCH_SHARE = 0.25
#: The fewest boards seen by both sensors for a closed form.
MIN_BOARDS = 3
#: Plane returns kept per board, evenly along its scan lines: the objective's board term is
#: their mean cost, whose spread over the returns is then at most a tenth (1 / sqrt(128)) of
#: one return's, and a population of 300 candidates costs a few milliseconds (29 boards of
#: 200-1300 returns each: 740 on average).
PLANE_POINTS = 128


@dataclass(frozen=True)
class BoardFrame:
    """One frame's board (:class:`BoardStart`).

    Attributes
    ----------
    name : str
    image : BoardView or None
        The board in the image; None when not found.
    candidates : int
        Planar patches of the board's size in the sweep's foreground.
    cloud : CloudBoard or None
        The patch taken as the board; None when none fits.
    points : int
        Returns on the board at the start found.
    ends : int
        Scan-line ends on its outline.
    used : bool
        Whether the frame's board is in the objective.
    """

    name: str
    image: BoardView | None
    candidates: int = 0
    cloud: CloudBoard | None = None
    points: int = 0
    ends: int = 0
    used: bool = False

    def to_dict(self) -> dict:
        return {"frame": self.name,
                "image": None if self.image is None else self.image.to_dict(),
                "candidates": self.candidates,
                "cloud": None if self.cloud is None else self.cloud.to_dict(),
                "points": self.points, "ends": self.ends, "used": self.used}


@dataclass
class BoardStart:
    """What the board stage found (:func:`board_start`).

    Attributes
    ----------
    board : Board
    frames : list of BoardFrame
    T : ndarray, shape (4, 4), or None
        The start from the board (the closed form refined by the board's residuals); None when
        the board poses do not fix the extrinsic.
    T_closed : ndarray, shape (4, 4), or None
        The closed form alone.
    T_given : ndarray, shape (4, 4), or None
        The start given (calib.yaml's T_cam_lidar or --init), when there was one.
    conditioning : Conditioning or None
    geometry : SweepGeometry or None
    scene : BoardScene or None
        The board's terms of the objective.
    reasons : list of str
        Why the board could not give the start, in words.
    seconds : dict
        Wall time of the image, the cloud and the fit (s).
    evidence : BoardEvidence or None
        The board's part of the verdict, at the result (:func:`board_evidence`).
    """

    board: Board
    frames: list = field(default_factory=list)
    T: np.ndarray | None = None
    T_closed: np.ndarray | None = None
    T_given: np.ndarray | None = None
    conditioning: Conditioning | None = None
    geometry: SweepGeometry | None = None
    scene: BoardScene | None = field(default=None, repr=False)
    reasons: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)
    evidence: "BoardEvidence | None" = None

    @property
    def applied(self) -> bool:
        return self.T is not None

    @property
    def found_in_images(self) -> int:
        return sum(f.image is not None for f in self.frames)

    @property
    def used(self) -> int:
        return sum(f.used for f in self.frames)

    def to_dict(self) -> dict:
        """For result.json's ``board``."""
        moved = None
        if self.T is not None and self.T_given is not None:
            moved = pose_error(self.T, self.T_given)
        return {"board": self.board.to_dict(), "applied": self.applied,
                "reasons": list(self.reasons),
                "found_in_images": self.found_in_images,
                "found_in_clouds": sum(f.cloud is not None for f in self.frames),
                "used": self.used, "frames_total": len(self.frames),
                "not_found_in_images": [f.name for f in self.frames if f.image is None],
                "T_closed_form": None if self.T_closed is None else self.T_closed.tolist(),
                "T_found": None if self.T is None else self.T.tolist(),
                "moved_deg": None if moved is None else round(float(moved["rotation_deg"]), 3),
                "moved_cm": None if moved is None else round(float(moved["translation_cm"]), 2),
                "conditioning": None if self.conditioning is None
                else self.conditioning.to_dict(),
                "sweeps": None if self.geometry is None else self.geometry.to_dict(),
                "noise": None if self.scene is None else {
                    "plane_cm": round(100 * self.scene.sigma_plane_m, 3),
                    "outline_cm": round(100 * self.scene.sigma_outline_m, 3)},
                "frames": [f.to_dict() for f in self.frames],
                "evidence": None if self.evidence is None else self.evidence.to_dict(),
                "seconds": {k: round(float(v), 2) for k, v in self.seconds.items()}}

    def summary_line(self) -> str:
        """What the board gave, in one line for the command line."""
        n = len(self.frames)
        line = (f"board: in {self.found_in_images} of {n} images and "
                f"{sum(f.cloud is not None for f in self.frames)} of {n} sweeps, {self.used} "
                "in the objective")
        if self.T is None:
            return line + "; no start from it: " + "; ".join(self.reasons)
        line += "; the start from its closed form"
        if self.T_given is not None:
            e = pose_error(self.T, self.T_given)
            line += (f", {float(e['rotation_deg']):.2f} deg / {float(e['translation_cm']):.1f} "
                     "cm from the start given")
        return line

    def verdict_reasons(self) -> list[str]:
        """The verdict's reasons from the board: why it gave no start (no board found, too few
        frames, board poses that leave an axis free), and its evidence's."""
        out = [f"{r}; {RECORD_ADVICE}" if "board poses" in r else r for r in self.reasons]
        if self.evidence is not None:
            out += self.evidence.reasons()
        return out


def board_settings(settings: Settings) -> Settings:
    """The settings of the calibration that follows the board's start: the stated error
    narrowed as after a wide start (:func:`paretocal.wide.after_settings`: the board's start
    is within a fraction of a degree and a few centimetres), without the seed grid (a coarse
    look at rotations over the box, made to find the basin from a start degrees off), without
    choosing the edge points again at the estimate (they are chosen at the board's start,
    which is that close to it), and without the motion check (the rig of a board recording
    stands still by design: the board moves); the search runs :data:`SEARCH_SHARE` of its
    generations."""
    from .wide import after_settings

    s = after_settings(settings)
    return s.replace(
        keep_none=True, features={"reselect": False}, decision={"motion_check": False},
        search={"seed_grid_deg": None,
                "gens": max(1, int(round(SEARCH_SHARE * s.search.gens)))})


def board_view(frames: list[Frame], settings: Settings, rings=None,
               T: np.ndarray | None = None) -> BoardStart | None:
    """The board stage for ``paretocal check`` and ``compare`` (None for frames without a
    board): its ``scene`` holds the board's terms, found from the board alone; ``T`` (the
    extrinsic judged) is recorded as the start given."""
    if not has_board(frames):
        return None
    return board_start(frames, settings, rings, T_given=T)


def board_summary(board: BoardStart, T: np.ndarray) -> dict:
    """What a check writes of the board: :meth:`BoardStart.to_dict` and how far the board's
    own optimum lies from ``T`` (``board_optimum_moved_deg``, ``_cm``; None when the board
    gave none)."""
    from .search.board import refine

    out = board.to_dict()
    moved = None
    if board.scene is not None and board.scene.n_boards >= MIN_BOARDS:
        moved = pose_error(refine(board.scene, np.asarray(T, dtype=np.float64)), T)
    out["board_optimum_moved_deg"] = (None if moved is None
                                      else round(float(moved["rotation_deg"]), 3))
    out["board_optimum_moved_cm"] = (None if moved is None
                                     else round(float(moved["translation_cm"]), 2))
    return out


def has_board(frames: list[Frame]) -> bool:
    """Whether the frames describe a board (calib.yaml's ``board:`` or a board.yaml)."""
    return any(f.board is not None for f in frames)


def _ring_arrays(frames: list[Frame], rings) -> list[np.ndarray]:
    out = []
    for f, r in zip(frames, rings):
        if r is not None:
            out.append(np.asarray(r.ring))
        elif f.ring is not None:
            out.append(np.asarray(f.ring, dtype=np.int64))
        else:
            out.append(np.full(len(f.points), -1, np.int64))
    return out


def _incidence(normal: np.ndarray, centre: np.ndarray) -> float:
    """The angle (rad) between a plane's normal and the ray to its centre."""
    c = centre / np.linalg.norm(centre)
    return float(np.arccos(np.clip(-normal @ c, -1.0, 1.0)))


def associate(view: BoardView, candidates: list[CloudBoard]) -> int | None:
    """The patch that is the image's board, with no extrinsic: the one whose range and angle
    of view agree best with the image board's (the two sensors see it from nearly one place;
    both figures are independent of the rotation between them), as metres: the range
    difference plus the angle difference times the range."""
    if not candidates:
        return None
    r_c = float(np.linalg.norm(view.centre_cam))
    inc = _incidence(view.normal, view.centre_cam)
    score = [abs(float(np.linalg.norm(c.centroid)) - r_c)
             + r_c * abs(_incidence(c.normal, c.centroid) - inc) for c in candidates]
    return int(np.argmin(score))


def _fit_choice(T: np.ndarray, view: BoardView, candidates: list[CloudBoard],
                board: Board) -> int | None:
    """The patch that best fits the image board at ``T`` (the distance misfit plus the normal
    misfit times the range, in metres), among those whose centroid lands on the image board:
    within half its diagonal of its centre. None when no patch does (the frame's patch is
    another object, or the frame's image board is not the one the sweep shows)."""
    r = float(np.linalg.norm(view.centre_cam))
    reach = 0.5 * float(np.hypot(*board.size_m))
    best, cost = None, np.inf
    for k, c in enumerate(candidates):
        at = T[:3, :3] @ c.centroid + T[:3, 3]
        if np.linalg.norm(at - view.centre_cam) > reach:
            continue
        ang, dist = misfit(T, c.normal[None], np.array([c.distance_m]), view.normal[None],
                           np.array([view.distance_m]))
        m = abs(float(dist[0])) + r * np.radians(float(ang[0]))
        if m < cost:
            best, cost = k, m
    return best


def _planes(views, clouds, idx) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    n_l = np.array([clouds[k].normal for k in idx])
    d_l = np.array([clouds[k].distance_m for k in idx])
    n_c = np.array([views[k].normal for k in idx])
    d_c = np.array([views[k].distance_m for k in idx])
    return n_l, d_l, n_c, d_c


def board_start(frames: list[Frame], settings: Settings, rings=None,
                T_given: np.ndarray | None = None,
                truncation_px: float | None = None) -> BoardStart:
    """The board in every frame, the closed form and its refinement.

    Parameters
    ----------
    frames : list of Frame
        The frames after the LiDAR steps (located), with their ``board``.
    settings : Settings
        ``search.seed`` seeds RANSAC; ``objective.truncation_px`` scales the board's cost.
    rings : list of Rings, optional
        Each sweep's rings (:func:`paretocal.inputs.sweep_rings`); the clouds' ring field (or
        none) otherwise.
    T_given : ndarray, shape (4, 4), optional
        The start given, recorded for comparison (the board does not use it).
    truncation_px : float, optional
        Overrides ``settings.objective.truncation_px``.

    Returns
    -------
    BoardStart
    """
    board = next(f.board for f in frames if f.board is not None)
    out = BoardStart(board=board, T_given=None if T_given is None else np.asarray(T_given))
    t0 = time.perf_counter()
    views = [find_board(f.image, f.camera, f.board) if f.board is not None else None
             for f in frames]
    out.seconds["image"] = time.perf_counter() - t0
    if all(v is None for v in views):
        out.frames = [BoardFrame(f.name, None) for f in frames]
        out.reasons.append(f"the board ({board.squares[0]} x {board.squares[1]} squares of "
                           f"{100 * board.square_m:g} cm) was found in no frame's image: check "
                           "board: in calib.yaml (the squares, not the inner corners)")
        return out
    t0 = time.perf_counter()
    ring = _ring_arrays(frames, rings if rings is not None else [None] * len(frames))
    coords = [sensor_coords(f.points, f.sensor_pose) for f in frames]
    geo, M = sweep_geometry(coords, ring)
    out.geometry = geo
    cands = [board_candidates(k, coords, ring, f.points, board, geo, M, settings.search.seed)
             if views[k] is not None else [] for k, f in enumerate(frames)]
    out.seconds["cloud"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    choice: dict[int, int] = {}
    for k, (v, c) in enumerate(zip(views, cands)):
        got = None if v is None else associate(v, c)
        if got is not None:
            choice[k] = got
    T = _closed_form_rounds(views, cands, choice, out)
    used = sorted(choice)
    if T is not None:
        T, scene, used = _refined(frames, views, coords, ring, geo, T, used,
                                  truncation_px or settings.objective.truncation_px)
        out.scene = scene
    out.seconds["fit"] = time.perf_counter() - t0
    out.frames = [BoardFrame(f.name, views[k], len(cands[k]),
                             cands[k][choice[k]] if k in choice else None,
                             *(_counts(out.scene, f.name)), used=k in used)
                  for k, f in enumerate(frames)]
    unused = [f.name for f in out.frames if not f.used]
    if unused:
        log.warning("the board is not in the objective for frame(s) %s (not found in the image "
                    "or the sweep, or off the others' fit); they serve the edges alone",
                    ", ".join(unused))
    if T is not None and out.conditioning is not None and out.conditioning.ok:
        out.T = T
    elif T is not None:
        out.reasons += list(out.conditioning.notes if out.conditioning else ())
    return out


def _counts(scene: BoardScene | None, name: str) -> tuple[int, int]:
    if scene is None or name not in scene.names:
        return 0, 0
    j = scene.names.index(name)
    return (int(scene.point_start[j + 1] - scene.point_start[j]),
            int(scene.end_start[j + 1] - scene.end_start[j]))


def _closed_form_rounds(views, cands, choice: dict, out: BoardStart) -> np.ndarray | None:
    """The closed form, each frame's patch chosen again by its fit, frames whose patches all
    miss the image board left out (``choice`` is updated); None with a reason when fewer than
    :data:`MIN_BOARDS` frames are left."""
    T = None
    board = out.board
    for _ in range(ASSOCIATION_ROUNDS):
        idx = sorted(choice)
        if len(idx) < MIN_BOARDS:
            break
        T = closed_form(*_planes(views, {k: cands[k][choice[k]] for k in idx}, idx))
        fits = {k: _fit_choice(T, views[k], cands[k], board) for k in idx}
        keep = {k: c for k, c in fits.items() if c is not None}
        if keep == choice:
            break
        choice.clear()
        choice.update(keep)
    idx = sorted(choice)
    if len(idx) < MIN_BOARDS:
        out.reasons.append(f"the board is seen by both sensors in {len(idx)} frame(s); the "
                           f"closed form needs {MIN_BOARDS} with the board turned differently")
        return None
    n_l, d_l, n_c, d_c = _planes(views, {k: cands[k][choice[k]] for k in idx}, idx)
    T = closed_form(n_l, d_l, n_c, d_c)
    out.T_closed = T
    out.conditioning = conditioning(T, n_l, d_l, n_c, d_c, min_boards=MIN_BOARDS)
    return T


def _refined(frames, views, coords, ring, geo: SweepGeometry, T: np.ndarray, used: list,
             truncation_px: float):
    """The returns on each board at ``T`` and the board's residuals minimised from it, twice:
    ``(T, scene, frames used)``."""
    scene = None
    for _ in range(REFINE_ROUNDS):
        scene = _board_scene(frames, views, coords, ring, geo, T, used, truncation_px)
        used = [int(k) for k in scene.frames]
        if len(used) < MIN_BOARDS:
            break
        T = refine(scene, T)
    if scene is not None:
        scene = _with_outline_noise(_board_scene(frames, views, coords, ring, geo, T, used,
                                                 truncation_px), T,
                                    np.radians(geo.azimuth_step_deg))
    return T, scene, used


def _board_scene(frames, views, coords, ring, geo: SweepGeometry, T: np.ndarray, used: list,
                 truncation_px: float) -> BoardScene:
    """The board's observations at ``T``: each frame's returns within :data:`PLANE_SIGMAS`
    noise sigmas of the image board's plane and inside its outline grown by a footprint, the
    scan lines' ends, the plane noise (the median over the frames of their own plane fits'
    RMS) and a first outline noise (the plane noise and the azimuth step's spread)."""
    R, t = T[:3, :3], T[:3, 3]
    board = next(f.board for f in frames if f.board is not None)
    half = np.array(board.size_m) / 2.0
    step = np.radians(geo.azimuth_step_deg)
    pts, ends, keep, fits, names = [], [], [], [], []
    for k in used:
        v = views[k]
        B = v.T_cam_board
        normal = R.T @ B[:3, 2]
        centre = R.T @ (B[:3, 3] - t)
        axes = (R.T @ B[:3, :2]).T
        r = float(np.linalg.norm(centre))
        idx = points_on_board(frames[k].points, normal, centre, axes, half,
                              PLANE_SIGMAS * geo.sigma_m, r * step)
        if len(idx) < 3 or len(np.unique(ring[k][idx])) < 2:
            continue
        e = scan_line_ends(idx, coords[k], ring[k], step, geo.sigma_m)
        inner = np.setdiff1d(idx, e)
        p = np.asarray(frames[k].points, dtype=np.float64)[inner, :3]
        fits.append(fit_plane(p)[2])
        pts.append(p[_evenly(inner, ring[k], coords[k][1], PLANE_POINTS)])
        ends.append(np.asarray(frames[k].points, dtype=np.float64)[e, :3])
        keep.append(k)
        names.append(frames[k].name)
    sigma_plane = float(np.median(fits)) if fits else geo.sigma_m
    r_med = float(np.median([np.linalg.norm(views[k].centre_cam) for k in keep])) if keep else 1.0
    sigma_outline = float(np.hypot(sigma_plane, r_med * step / np.sqrt(12.0)))
    return BoardScene(
        frames=np.array(keep, dtype=np.int64), names=tuple(names),
        normal=np.array([views[k].normal for k in keep]).reshape(-1, 3),
        distance=np.array([views[k].distance_m for k in keep]),
        T_cam_board=np.array([views[k].T_cam_board for k in keep]).reshape(-1, 4, 4),
        half_size=half,
        points=np.vstack(pts) if pts else np.zeros((0, 3)),
        point_start=np.r_[0, np.cumsum([len(p) for p in pts])].astype(np.int64),
        ends=np.vstack(ends) if ends else np.zeros((0, 3)),
        end_start=np.r_[0, np.cumsum([len(e) for e in ends])].astype(np.int64),
        sigma_plane_m=sigma_plane, sigma_outline_m=sigma_outline,
        truncation_px=float(truncation_px))


def _evenly(index: np.ndarray, ring: np.ndarray, azimuth: np.ndarray, most: int) -> np.ndarray:
    """Positions into ``index`` of at most ``most`` of its returns, evenly along the scan lines:
    every k-th in ring-then-azimuth order."""
    order = np.lexsort((azimuth[index], ring[index]))
    if len(order) <= most:
        return order
    return order[np.linspace(0, len(order) - 1, most).round().astype(np.int64)]


def _with_outline_noise(scene: BoardScene, T: np.ndarray, step_rad: float) -> BoardScene:
    """The scene with its outline noise measured at ``T``: 1.4826 times the median absolute
    outline residual (a robust RMS about the outline), never below the spread of an edge
    that lies anywhere within one azimuth step (the step at the boards' median range over
    the square root of 12)."""
    import dataclasses

    r = outline_residuals(scene, T[None])[0]
    if len(r) < MIN_BOARDS:
        return scene
    ranges = np.linalg.norm(scene.T_cam_board[:, :3, 3], axis=1)
    floor = float(np.median(ranges)) * step_rad / np.sqrt(12.0)
    s = max(1.4826 * float(np.median(np.abs(r))), floor)
    return dataclasses.replace(scene, sigma_outline_m=s)


#: What to record for a board recording the evidence cannot settle (the verdict's advice in
#: place of the driving rig's "frames taken at other places").
RECORD_ADVICE = ("record more board poses: the board tilted several ways (left, right, up, "
                 "down), nearer the image's corners and at several distances")


@dataclass(frozen=True)
class BoardEvidence:
    """The board's part of the verdict (:func:`board_evidence`): the boards' residuals at the
    result, their leave-one-board-out spread, and the board and the scene's edges as two
    independent views of the extrinsic.

    All corrections are on the intervals' axes at the result (``T = T_result @ D(d)``; m and
    deg).

    Attributes
    ----------
    per_frame : tuple of dict
        Each board frame's ``frame``, plane and outline RMS residuals (cm) at the result and
        how far leaving it out moves the board's optimum (deg, cm).
    lobo_se : ndarray, shape (6,)
        The boards' jackknife standard error of the board's optimum (leave one board out).
    floor : ndarray, shape (6,)
        The board's bias floor (:func:`range_bias_floor`).
    board : ndarray, shape (6,)
        The board's own optimum (its terms alone).
    edges : ndarray, shape (6,)
        The edges' own local optimum (their terms alone).
    edges_half : ndarray, shape (6,)
        The edges' own 95 % half-widths (their jackknife and their bias floor,
        :func:`paretocal.verdict.intervals`); NaN where they do not determine an axis.
    edges_prefer : dict
        The edges' frame-by-frame preference of their optimum over the board's
        (:func:`paretocal.search.basin.paired_preference`: ``mean_px``, ``t``, ``p``, ...).
    disagree : tuple of str
        The axes on which the views disagree: the edges clearly prefer their optimum (p below
        :data:`paretocal.search.basin.CLEAR_P`) and it lies beyond a usable calibration's
        tolerance and the board's own spread and floor.
    intervals : Intervals
        The result's intervals: per axis the larger of the two views' offsets from the result
        combined with their own half-widths (``jackknife_se`` is the boards', ``bias`` the
        rest).
    """

    per_frame: tuple
    lobo_se: np.ndarray
    floor: np.ndarray
    board: np.ndarray
    edges: np.ndarray
    edges_half: np.ndarray
    edges_prefer: dict
    disagree: tuple
    intervals: Intervals

    def reasons(self) -> list[str]:
        """The verdict's reasons from the board's evidence."""
        if not self.disagree:
            return []
        from .quality import AXES, TO_REPORT, UNITS

        units = dict(zip(AXES, UNITS))
        k = [AXES.index(a) for a in self.disagree]
        diff = (self.board - self.edges) * TO_REPORT
        what = ", ".join(f"{AXES[i]} {diff[i]:+.2g} {units[AXES[i]]}" for i in k)
        p = self.edges_prefer
        return [f"the board and the scene's edges disagree ({what}, board minus edges: the "
                f"edges prefer their own pose in {p['frames_far_better']} of {p['frames']} "
                f"frames, p = {p['p']:.2g}, beyond what a usable calibration allows and the "
                "board's own spread and floor): a bias one of them carries: "
                "check the camera's intrinsics, the board's description in calib.yaml (its "
                "square size) and the image-cloud pairing; " + RECORD_ADVICE]

    def to_dict(self) -> dict:
        from .quality import AXES, TO_REPORT

        def axes(v):
            return {a: (None if not np.isfinite(x) else round(float(x), 4))
                    for a, x in zip(AXES, np.asarray(v, dtype=np.float64) * TO_REPORT)}

        return {"per_frame": list(self.per_frame), "lobo_se": axes(self.lobo_se),
                "floor": axes(self.floor), "board_optimum": axes(self.board),
                "edges_optimum": axes(self.edges),
                "edges_half_width": axes(self.edges_half),
                "edges_prefer": {k: (round(float(v), 4) if isinstance(v, float) else v)
                                 for k, v in self.edges_prefer.items()},
                "disagree": list(self.disagree),
                "units": "cm, deg; corrections at the result, LiDAR frame"}


def range_bias_floor(scene: BoardScene, T: np.ndarray) -> np.ndarray:
    """How far the board's optimum moves (m, deg, on the intervals' axes; absolute, (6,)) when
    every return on the boards is taken ``sigma_plane_m`` farther along its ray: a ranging
    bias the LiDAR may carry on one target (its reflectivity) moves every board along its
    normal at once, which no board's residuals show and the boards' spread does not either.
    Boards that all lean one way turn it into a translation along their least fixed
    direction."""
    import dataclasses

    from .quality import correction_between
    from .search.board import refine

    def farther(p):
        r = np.linalg.norm(p, axis=1, keepdims=True)
        return p * (1.0 + scene.sigma_plane_m / np.maximum(r, 1e-9))

    shifted = dataclasses.replace(scene, points=farther(scene.points), ends=farther(scene.ends))
    return np.abs(correction_between(refine(scene, T), refine(shifted, T)))


def board_evidence(objective, x: np.ndarray, settings: Settings,
                   sampling: np.ndarray | None = None) -> BoardEvidence:
    """The board's evidence at the result ``x`` (7,) of a :class:`~paretocal.objective.board.
    BoardObjective`.

    The board's optimum (its terms alone, :func:`~paretocal.search.board.refine` from the
    result), its leave-one-board-out spread and its floor, :func:`range_bias_floor`; the
    edges' local optimum (their terms alone) and their own 95 % half-widths, as the verdict
    measures them for any recording; and the result's intervals. The board and the edges share
    no measurement (corners and returns on a plane; image edges and depth discontinuities), so
    the truth lies within its own 95 % interval of whichever view is unbiased: per axis, the
    half-width is the larger of ``sqrt(d_board^2 + h_board^2)`` and ``sqrt(d_edges^2 +
    h_edges^2)``, ``d`` each view's optimum's offset from the result and ``h`` its own
    half-width: the board's ``sqrt((1.96 se)^2 + f^2)`` (``se`` the boards' jackknife standard
    error, ``f`` its floor), the edges' as the verdict measures it for any recording (an axis
    the edges do not determine counts the board's alone). The frames' agreement cannot show a
    bias they all share; the other view can. The views disagree on an axis when their
    difference lies beyond what a usable calibration may be off (:data:`paretocal.search.basin.
    USABLE_DEG`, :data:`~paretocal.search.basin.USABLE_M`: within that, the difference widens
    the intervals instead) and beyond the board's own half-width (``sqrt((1.96 se)^2 +
    f^2)``), and the edges themselves clearly prefer their optimum to the board's, frame by
    frame (a paired test at :data:`paretocal.search.basin.CLEAR_P`): where they cannot tell
    the two apart, the difference is the edges' own noise. The edges of a sparse LiDAR carry
    a bias of their own (on walkway_a, 16 beams: their optimum 0.54 deg from the board's,
    preferred by 27 of 29 frames, where the board's lies 0.19 deg from the reference).
    """
    from .quality import (correction_between, local_optimum, pixel_fd_step,
                          quality_report)
    from .search.basin import CLEAR_P, USABLE_DEG, USABLE_M, paired_preference
    from .search.board import leave_one_out, refine
    from .verdict import (Z95, alignment_px, bias_tolerance_px, intervals, pose_per_px)
    from .objective.board import outline_residuals, plane_residuals

    scene: BoardScene = objective.board
    edges = objective.edges
    T = objective.transforms(np.atleast_2d(x))[0]
    T_board = refine(scene, T)
    d_board = correction_between(T, T_board)
    lobo = leave_one_out(scene, T_board)
    J = len(lobo)
    se = np.sqrt((J - 1) / J * np.sum((lobo - lobo.mean(axis=0)) ** 2, axis=0)) if J > 1 \
        else np.full(6, np.nan)
    floor = range_bias_floor(scene, T_board)
    x_e = local_optimum(edges, x)
    d_edges = correction_between(T, edges.transforms(x_e[None])[0])
    q = quality_report(edges, x_e, pixel_fd_step(edges, x_e))
    align = alignment_px(edges, x_e)
    per_px = pose_per_px(edges, x_e)
    bias = bias_tolerance_px(align, sampling) * per_px
    edges_half = np.sqrt((Z95 * q.jackknife_se) ** 2 + bias ** 2)
    diff = d_board - d_edges
    board_half = np.sqrt((Z95 * se) ** 2 + floor ** 2)
    # Do the edges themselves tell the two optima apart? Frame by frame (a paired test), at
    # every edge point: where they do not, the difference is the edges' noise.
    x_b = np.r_[correction_between(edges.T_init, T_board), x_e[6]]
    pref = paired_preference(edges, x_b, x_e)
    from .quality import AXES

    usable = np.r_[[USABLE_M] * 3, [USABLE_DEG] * 3]
    disagree = () if not pref["p"] < CLEAR_P else tuple(
        a for a, v, w, u in zip(AXES, diff, board_half, usable)
        if np.isfinite(w) and abs(v) > max(w, u))
    # The truth lies within its own 95 % interval of whichever view is unbiased: per axis, the
    # larger of the two views' offsets from the result combined with their half-widths.
    half = np.fmax(np.hypot(d_board, board_half), np.hypot(d_edges, edges_half))
    iv = intervals(se, per_px, align, settings.search, sampling_px=sampling,
                   bias=np.sqrt(np.maximum(half ** 2 - (Z95 * se) ** 2, 0.0)))
    p = plane_residuals(scene, T[None])[0]
    o = outline_residuals(scene, T[None])[0]
    rows = []
    for j, name in enumerate(scene.names):
        a, b = scene.point_start[j], scene.point_start[j + 1]
        c, e = scene.end_start[j], scene.end_start[j + 1]
        shift = lobo[j]
        rows.append({"frame": name,
                     "plane_rms_cm": round(100 * float(np.sqrt(np.mean(p[a:b] ** 2))), 3),
                     "outline_rms_cm": (round(100 * float(np.sqrt(np.mean(o[c:e] ** 2))), 3)
                                        if e > c else None),
                     "left_out_moves_deg": round(float(np.max(np.abs(shift[3:]))), 4),
                     "left_out_moves_cm": round(100 * float(np.max(np.abs(shift[:3]))), 3)})
    return BoardEvidence(per_frame=tuple(rows), lobo_se=se, floor=floor, board=d_board,
                         edges=d_edges, edges_half=edges_half, edges_prefer=pref,
                         disagree=disagree, intervals=iv)
