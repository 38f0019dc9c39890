"""Is a given extrinsic calibrated? A verdict without ground truth (``paretocal check``).

The extrinsic is scored against its 3^6 - 1 grid neighbours (Levinson & Thrun's test: a
correct calibration is a local minimum of the edge objective, so few neighbours score better),
and the objective is polished locally from it. A correct extrinsic stays put up to the
objective's own bias; a miscalibrated one moves towards the optimum. The verdict compares how far
it moves with tolerances halfway between that bias and the errors worth flagging: on the 20
KITTI frames the reference moves 0.15 deg / 1.7 cm (3.2 px), extrinsics perturbed by 1 deg or
10 cm on one axis move 4.7-16.0 px (all judged miscalibrated), so 0.5 deg / 5 cm are the
defaults (docs/trusting.md).

A wrong extrinsic can also sit in a wrong local optimum of the edges, which then does not move
it. On frames of a moving rig the check therefore also compares its rotation with the one the
recording's motion gives (:mod:`paretocal.crosscheck`, evidence that shares nothing with the
edges): a rotation the motion contradicts is miscalibrated whatever the edges say.

Both deciding figures are measured from the frames, and few frames measure them coarsely: the
local optimum is known to its jackknife over the frames, the motion's rotation to its
vectors' scatter (:attr:`~paretocal.crosscheck.MotionAgreement.spread_deg`). When the 95 %
spread of a figure that decides the verdict reaches the threshold it is compared with, the
frames are too few to judge (:attr:`CheckReport.too_few`, with a note saying which figure and
by how much): on the KITTI drive, 5 frames from 1 to 6 called the reference miscalibrated by
the motion, 1.51 deg against a tolerance of 1.5 known to +-0.68 deg; its 20 frames decide.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .config import Settings
from .crosscheck import MIN_FRAMES, MotionAgreement, motion_agreement, recording_motion
from .geometry import pose_error
from .io.frame import Frame
from .quality import (Quality, correction_between, displacement_px, local_optimum,
                      neighbour_fraction, pixel_fd_step, quality_report)
from .stage import FeatureCounts

NEIGHBOUR_STEP = np.array([0.05, 0.05, 0.05, 0.5, 0.5, 0.5])   # m and deg


def _finite(v: float, digits: int) -> float | None:
    """``v`` rounded as JSON holds it: None where not finite."""
    return round(float(v), digits) if np.isfinite(v) else None


def _nan(v) -> float:
    """A figure read back: NaN for None."""
    return np.nan if v is None else float(v)


def _given_cm(m: float) -> float:
    """A length given in cm (a tolerance, a step) and held in m, in cm again: the figure as
    given (to 12 significant digits, which ``m * 100`` alone can miss in the last bit)."""
    return float(f"{float(m) * 100.0:.12g}")


@dataclass(frozen=True)
class CheckReport:
    """The check of an extrinsic (:func:`check_extrinsic`), in metres and degrees.

    Attributes
    ----------
    verdict : str
        ``"calibrated"`` or ``"miscalibrated"``: miscalibrated when :attr:`score` exceeds 1
        or the recording's motion contradicts the rotation (:attr:`motion`).
    score : float
        The move to the local optimum relative to the tolerances (the larger of rotation over
        its tolerance and translation over its); above 1 is miscalibrated.
    notes : tuple of str
        What makes the check itself weak (fewer frames than a calibration needs to be
        trusted), with what to do; empty when it is not (:attr:`weak`).
    tolerance_deg : float
        Rotation tolerance (deg).
    tolerance_m : float
        Translation tolerance (m).
    moved_px : float
        How far the local optimum moves the feature points from the extrinsic checked (px,
        mean over the points).
    neighbour_fraction : float
        Share of the 3^6 - 1 grid neighbours of the extrinsic that score better.
    best_neighbour_gain_px : float
        The best neighbour's improvement (px).
    neighbour_step : ndarray, shape (6,)
        The grid's steps (m, deg).
    T_checked : ndarray, shape (4, 4)
        The extrinsic checked (``T_cam_lidar``).
    T_local_optimum : ndarray, shape (4, 4)
        The objective's local optimum from it.
    quality : Quality
        The quality report at the local optimum.
    frames : tuple of str
        The frames' names.
    features : FeatureCounts
        What the objective compared (:func:`paretocal.stage.feature_counts`).
    extrinsic_from : str or None
        Where the extrinsic checked came from (``paretocal check``: its file, or
        ``"dataset"``); written only when set.
    motion : MotionAgreement or None
        The rotation against the recording's motion (:func:`~paretocal.crosscheck.motion_agreement`);
        None when not looked at (fewer than :data:`~paretocal.crosscheck.MIN_FRAMES` frames,
        ``decision.motion_check`` off, or a board recording, whose rig stands still).
    board : dict or None
        For a recording with a board (its terms are then in the objective checked): what the
        board stage found (:meth:`paretocal.board.BoardStart.to_dict`) and ``moved_deg``,
        ``moved_cm``: how far the board's own optimum lies from the extrinsic checked. None
        without a board.
    too_few : bool
        The frames are too few to judge: a figure that decides the verdict is known, from the
        frames themselves, only to a 95 % spread that reaches its threshold (a note says
        which); also with fewer frames than a calibration needs to be trusted.
    spread_deg : float
        The 95 % spread of the local optimum's rotation over the frames (deg; NaN with one
        frame): ``1.96`` times the jackknife standard errors of yaw, pitch and roll combined.
    spread_m : float
        The same of its translation (m).
    """

    verdict: str
    score: float
    notes: tuple[str, ...]
    tolerance_deg: float
    tolerance_m: float
    moved_px: float
    neighbour_fraction: float
    best_neighbour_gain_px: float
    neighbour_step: np.ndarray
    T_checked: np.ndarray
    T_local_optimum: np.ndarray
    quality: Quality
    frames: tuple[str, ...]
    features: FeatureCounts
    extrinsic_from: str | None = None
    motion: MotionAgreement | None = None
    board: dict | None = None
    too_few: bool = False
    spread_deg: float = np.nan
    spread_m: float = np.nan

    #: The score in one phrase, for the line that shows it.
    SCORE = "the move to the local optimum over its tolerance; above 1: miscalibrated"

    @property
    def weak(self) -> bool:
        """Whether the check itself has too little to go on (:attr:`notes` say why)."""
        return bool(self.notes)

    def _moved(self) -> dict[str, np.ndarray]:
        return pose_error(self.T_local_optimum, self.T_checked)

    @property
    def moved_deg(self) -> float:
        """The rotation from the extrinsic checked to the local optimum (deg)."""
        return float(self._moved()["rotation_deg"])

    @property
    def moved_m(self) -> float:
        """The translation from the extrinsic checked to the local optimum (m)."""
        return float(self._moved()["translation_cm"]) / 100.0

    def to_dict(self) -> dict[str, Any]:
        """The report as ``paretocal check --out`` writes it: the tolerances, the move and
        the neighbours' step in cm and deg, the extrinsics as nested lists, the quality
        report in its :meth:`~paretocal.quality.Quality.to_dict` form."""
        moved = self._moved()
        out = {
            "weak": self.weak,
            "too_few": bool(self.too_few),
            "notes": list(self.notes),
            "verdict": self.verdict,
            "score": float(self.score),
            "spread": {"rotation_deg": _finite(self.spread_deg, 4),
                       "translation_cm": _finite(100.0 * self.spread_m, 4)},
            "tolerances": {"rotation_deg": float(self.tolerance_deg),
                           "translation_cm": _given_cm(self.tolerance_m)},
            "moved": {"rotation_deg": float(moved["rotation_deg"]),
                      "translation_cm": float(moved["translation_cm"]),
                      "pixels": float(self.moved_px)},
            "neighbour_fraction": float(self.neighbour_fraction),
            "best_neighbour_gain_px": float(self.best_neighbour_gain_px),
            "neighbour_step": {"translation_cm": _given_cm(self.neighbour_step[0]),
                               "rotation_deg": float(self.neighbour_step[3])},
            "T_checked": np.asarray(self.T_checked).tolist(),
            "T_local_optimum": np.asarray(self.T_local_optimum).tolist(),
            "quality": self.quality.to_dict(),
            "frames": list(self.frames),
            "features": self.features.to_dict(),
        }
        if self.extrinsic_from is not None:
            out["extrinsic_from"] = self.extrinsic_from
        if self.motion is not None:
            out["motion"] = self.motion.to_dict()
        if self.board is not None:
            out["board"] = self.board
        return out

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "CheckReport":
        """The report read back from its :meth:`to_dict` form.

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (lengths in cm, angles in deg, as ``result.json`` writes
            them).
        """
        tol, step, moved = doc["tolerances"], doc["neighbour_step"], doc["moved"]
        spread = doc.get("spread") or {}
        return cls(verdict=str(doc["verdict"]), score=float(doc["score"]),
                   too_few=bool(doc.get("too_few", False)),
                   spread_deg=_nan(spread.get("rotation_deg")),
                   spread_m=_nan(spread.get("translation_cm")) / 100.0,
                   notes=tuple(str(n) for n in doc.get("notes") or []),
                   tolerance_deg=float(tol["rotation_deg"]),
                   tolerance_m=float(tol["translation_cm"]) / 100.0,
                   moved_px=float(moved["pixels"]),
                   neighbour_fraction=float(doc["neighbour_fraction"]),
                   best_neighbour_gain_px=float(doc["best_neighbour_gain_px"]),
                   neighbour_step=np.r_[[float(step["translation_cm"]) / 100.0] * 3,
                                        [float(step["rotation_deg"])] * 3],
                   T_checked=np.array(doc["T_checked"], dtype=np.float64),
                   T_local_optimum=np.array(doc["T_local_optimum"], dtype=np.float64),
                   quality=Quality.from_dict(doc.get("quality") or {}),
                   frames=tuple(str(f) for f in doc.get("frames") or []),
                   features=FeatureCounts.from_dict(doc.get("features") or {}),
                   extrinsic_from=doc.get("extrinsic_from"),
                   motion=(MotionAgreement.from_dict(doc["motion"]) if doc.get("motion")
                           else None),
                   board=doc.get("board"))

    def with_source(self, extrinsic_from: str) -> "CheckReport":
        """The report naming where the extrinsic checked came from.

        Parameters
        ----------
        extrinsic_from : str
            Its file, or ``"dataset"``.

        Returns
        -------
        CheckReport
        """
        return dataclasses.replace(self, extrinsic_from=extrinsic_from)


def check_extrinsic(frames: list[Frame], T: np.ndarray, settings: Settings | None = None,
                    rot_tol_deg: float = 0.5, trans_tol_cm: float = 5.0,
                    progress=None) -> CheckReport:
    """Check ``T`` (4, 4) on ``frames``.

    Parameters
    ----------
    frames : list of Frame
        The frames (:func:`paretocal.load_frames`); at least 3 for a check that is not weak.
    T : ndarray, shape (4, 4)
        The extrinsic ``T_cam_lidar`` to check (m).
    settings : Settings, optional
        The settings of the objective (defaults when omitted).
    rot_tol_deg : float
        Rotation tolerance (deg) of the move to the local optimum.
    trans_tol_cm : float
        Translation tolerance (cm) of the move to the local optimum.
    progress : callable, optional
        ``progress(stage, done, total)``, told of the feature extraction per frame and of the
        steps after it (neighbours, local optimum, quality report, and the motion when it is
        looked at).

    Returns
    -------
    CheckReport
        ``verdict`` ("calibrated" or "miscalibrated"), ``score`` (the move to the local optimum
        relative to the tolerances; above 1 is miscalibrated), ``motion`` (the rotation
        against the recording's motion, which also makes it miscalibrated when they
        disagree; with at least :data:`~paretocal.crosscheck.MIN_FRAMES` frames and
        ``decision.motion_check`` on), the move (``moved_deg``,
        ``moved_m``, ``moved_px``), ``neighbour_fraction`` and ``best_neighbour_gain_px``,
        ``T_checked`` (``T``), ``T_local_optimum``, the ``quality`` report at the local
        optimum, and ``weak`` with ``notes``: True when the check itself has too little to go
        on (fewer frames than a calibration needs to be trusted), with what to do
        (:meth:`CheckReport.to_dict`: the JSON ``paretocal check --out`` writes).
    """
    from .board import board_summary, board_view
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
    board = board_view(lidar.frames, settings, lidar.rings, T)
    stage = Stage(lidar.frames, T, T, settings, lambda d, t: tick("features", d, t),
                  rings=lidar.rings, board=None if board is None else board.scene)
    obj = stage.objective
    x0 = np.zeros(7)
    x0[6] = stage.n_max
    with_motion = (settings.decision.motion_check and len(frames) >= MIN_FRAMES
                   and board is None)
    steps = 4 if with_motion else 3
    frac, gain = neighbour_fraction(obj, x0, NEIGHBOUR_STEP)
    tick("check", 1, steps)
    xo = local_optimum(obj, x0)
    tick("check", 2, steps)
    T_opt = obj.transforms(xo[None])[0]
    move = pose_error(T_opt, T)
    score = max(float(move["rotation_deg"]) / rot_tol_deg,
                float(move["translation_cm"]) / trans_tol_cm)
    quality = quality_report(obj, xo, pixel_fd_step(obj, xo))
    tick("check", 3, steps)
    motion = None
    if with_motion:
        motion = motion_agreement(recording_motion(lidar.frames, settings.search.seed), T)
        tick("check", 4, steps)
    from .pipeline import RELIABLE_MIN_FRAMES
    from .verdict import Z95

    notes = []
    if len(frames) < RELIABLE_MIN_FRAMES:
        notes.append(f"only {len(frames)} frame(s): the check itself is weak (one scene's "
                     "biases can move a correct extrinsic or hold a wrong one); check on at "
                     f"least {RELIABLE_MIN_FRAMES} frames of varied scenes")
    elif motion is not None and motion.standing:
        notes.append(f"{motion.one_view(len(frames))} can move a correct extrinsic or hold a "
                     "wrong one however many frames there are; check on frames taken while "
                     "moving")
    se = quality.jackknife_se
    spread_deg = float(Z95 * np.linalg.norm(se[3:]))
    spread_m = float(Z95 * np.linalg.norm(se[:3]))
    undecided = _undecided(float(move["rotation_deg"]), float(move["translation_cm"]) / 100.0,
                           spread_deg, spread_m, rot_tol_deg, trans_tol_cm / 100.0, motion)
    too_few = len(frames) < RELIABLE_MIN_FRAMES or bool(undecided)
    if undecided and len(frames) >= RELIABLE_MIN_FRAMES:
        notes.append(f"the frames are too few to judge: {'; '.join(undecided)}; check on more "
                     "frames" + (" of the rig moving" if motion is not None and any(
                         "motion" in u for u in undecided) else ""))
    wrong = score > 1.0 or (motion is not None and not motion.agree)
    return CheckReport(
        verdict="miscalibrated" if wrong else "calibrated", score=float(score),
        notes=tuple(notes), tolerance_deg=float(rot_tol_deg),
        tolerance_m=float(trans_tol_cm) / 100.0, moved_px=displacement_px(obj, x0, xo),
        neighbour_fraction=frac, best_neighbour_gain_px=gain,
        neighbour_step=NEIGHBOUR_STEP.copy(), T_checked=T, T_local_optimum=T_opt,
        quality=quality, frames=tuple(f.name for f in frames),
        features=feature_counts(stage.feats), motion=motion,
        board=None if board is None else board_summary(board, T), too_few=too_few,
        spread_deg=spread_deg, spread_m=spread_m)


def _undecided(moved_deg: float, moved_m: float, spread_deg: float, spread_m: float,
               tol_deg: float, tol_m: float, motion: MotionAgreement | None) -> list[str]:
    """The figures that decide the check but whose 95 % spread over the frames reaches the
    threshold they are compared with, in words (empty: the frames decide).

    The edges decide by the move to the local optimum against the tolerances (rotation and
    translation, each known to its spread); the motion by its angle against its tolerance
    (:attr:`~paretocal.crosscheck.MotionAgreement.spread_deg`). A check that calls the
    extrinsic miscalibrated is undecided when every figure that convicts it could lie within
    its threshold; one that calls it calibrated, when any figure could lie beyond.
    """
    edges = [(moved_deg, spread_deg, tol_deg), (moved_m, spread_m, tol_m)]
    edges_wrong = any(v > t for v, _, t in edges)
    if edges_wrong:
        edge_open = all(not (v - s > t) for v, s, t in edges if v > t)
    else:
        edge_open = any(not (v + s <= t) for v, s, t in edges)
    motion_wrong = motion_open = False
    if motion is not None and motion.applied:
        c, s, t = motion.change_deg, motion.spread_deg, motion.tolerance_deg
        motion_wrong = not motion.agree
        motion_open = not (c - s > t) if motion_wrong else not (c + s <= t)
    if edges_wrong or motion_wrong:
        # Miscalibrated: undecided only if no convicting figure is decided.
        if (edges_wrong and not edge_open) or (motion_wrong and not motion_open):
            return []
        edge_open, motion_open = edges_wrong and edge_open, motion_wrong and motion_open
    out = []
    if edge_open:
        out.append(f"the local optimum lies {moved_deg:.2g} deg / {100 * moved_m:.2g} cm "
                   f"away, itself known only to +-{spread_deg:.2g} deg / "
                   f"+-{100 * spread_m:.2g} cm over the frames (95 %, their jackknife), "
                   f"which reaches the tolerances {tol_deg:g} deg / {100 * tol_m:g} cm")
    if motion_open and motion is not None:
        out.append(f"the motion puts the rotation {motion.change_deg:.3g} deg from the "
                   f"extrinsic against a tolerance of {motion.tolerance_deg:.3g} deg, a figure "
                   f"known only to +-{motion.spread_deg:.2g} deg (95 %, from "
                   f"{motion.directions + motion.turns} directions of travel and turns that "
                   f"disagree by {motion.residual_deg:.2g} deg RMS)")
    return out



# ------------------------------------------------------------------------------- comparison


@dataclass(frozen=True)
class Preference:
    """The paired per-frame test of two extrinsics with the points one of them sees.

    Attributes
    ----------
    view : {"A", "B"}
        The extrinsic whose view chose the LiDAR feature points.
    mean_px : float
        Mean over the frames of B's advantage in the edge objective (px; positive: B aligns
        better).
    se_px : float
        Its standard error (px; NaN with one frame).
    p_b : float
        One-sided p that B is not better (NaN with one frame).
    p_a : float
        One-sided p that A is not better.
    frames : int
    frames_b_better : int
        Frames in which B scores lower.
    """

    view: str
    mean_px: float
    se_px: float
    p_b: float
    p_a: float
    frames: int
    frames_b_better: int

    def to_dict(self) -> dict:
        """The JSON form (``compare --out``), rounded."""
        return {"view": self.view, "mean_px": _num(self.mean_px, 4),
                "se_px": _num(self.se_px, 4), "p_b": _num(self.p_b, 6),
                "p_a": _num(self.p_a, 6), "frames": self.frames,
                "frames_b_better": self.frames_b_better}


@dataclass(frozen=True)
class Comparison:
    """Two extrinsics compared (:func:`compare_extrinsics`), in metres and degrees.

    Attributes
    ----------
    T_a, T_b : ndarray, shape (4, 4)
        The extrinsics (``T_cam_lidar``).
    correction : ndarray, shape (6,)
        ``D`` with ``T_b = T_a @ D``: x, y, z (m) and yaw, pitch, roll (deg, ZYX) in A's LiDAR
        frame, the search's own axes (what ``result.json``'s ``correction`` is between a
        calibration's start and its result).
    rotation_deg : float
        The angle between the two rotations.
    translation_m : float
        ``|t_b - t_a|``, the camera-frame translation difference.
    camera_m : ndarray, shape (3,)
        ``t_b - t_a`` in the camera frame (m).
    pixels : float or None
        Mean image distance between the feature points' projections under A and B, over the
        frames (px); None without frames.
    preferences : tuple of Preference
        The paired test with A's points and with B's; empty without frames.
    prefer : {"A", "B", "neither"} or None
        Which one the frames prefer: one whose advantage is clear (p below
        :data:`~paretocal.search.basin.CLEAR_P`, the verdict's level) with the points of
        either view; "neither" otherwise; None without frames.
    reason : str
        The preference in words.
    frames : tuple of str
        The frames compared on.
    frame_scores : ndarray, shape (2, F), or None
        The edge objective of each frame alone at A (row 0) and at B (row 1), with the points
        A sees (px, lower is better; NaN for a frame with none); None without frames.
    sweeps : tuple of Frame
        The frames as compared (de-skewed when the motion was compensated), for the page
        (:func:`paretocal.report.interactive.write_comparison`); not in JSON.
    """

    T_a: np.ndarray
    T_b: np.ndarray
    correction: np.ndarray
    rotation_deg: float
    translation_m: float
    camera_m: np.ndarray
    pixels: float | None = None
    preferences: tuple = ()
    prefer: str | None = None
    reason: str = ""
    frames: tuple = ()
    frame_scores: np.ndarray | None = None
    sweeps: tuple = field(default=(), repr=False, compare=False)

    def axes_text(self) -> str:
        """B relative to A (the correction ``D``, ``B = A @ D``) per axis, in words (cm, deg)."""
        d = self.to_dict()["correction"]
        return (f"x {d['x_cm']:+.2f} cm, y {d['y_cm']:+.2f} cm, z {d['z_cm']:+.2f} cm, yaw "
                f"{d['yaw_deg']:+.3f} deg, pitch {d['pitch_deg']:+.3f} deg, roll "
                f"{d['roll_deg']:+.3f} deg")

    def to_dict(self) -> dict:
        """The JSON form (``compare --out``): centimetres and degrees."""
        c = self.correction
        return {
            "correction": {"x_cm": _num(100 * c[0], 3), "y_cm": _num(100 * c[1], 3),
                           "z_cm": _num(100 * c[2], 3), "yaw_deg": _num(c[3], 4),
                           "pitch_deg": _num(c[4], 4), "roll_deg": _num(c[5], 4)},
            "rotation_deg": _num(self.rotation_deg, 4),
            "translation_cm": _num(100 * self.translation_m, 3),
            "camera_cm": [_num(100 * v, 3) for v in self.camera_m],
            "pixels": None if self.pixels is None else _num(self.pixels, 3),
            "prefer": self.prefer, "reason": self.reason,
            "preferences": [p.to_dict() for p in self.preferences],
            "frames": list(self.frames),
            "T_a": np.asarray(self.T_a).tolist(), "T_b": np.asarray(self.T_b).tolist(),
        }


def _num(v: float, digits: int) -> float | None:
    return round(float(v), digits) if np.isfinite(v) else None


def compare_extrinsics(T_a: np.ndarray, T_b: np.ndarray, frames: list[Frame] | None = None,
                       settings: Settings | None = None, progress=None) -> Comparison:
    """Compare two extrinsics, and with ``frames`` say which one the frames prefer.

    Parameters
    ----------
    T_a, T_b : ndarray, shape (4, 4)
        ``T_cam_lidar`` A (e.g. the factory's, yesterday's) and B.
    frames : list of Frame, optional
        Frames of the rig; the edge objective is then evaluated per frame at both, with the
        feature points each of them sees (points outside one's view would favour it), and a
        paired t-test over the frames (:func:`~paretocal.search.basin.paired_preference`,
        the verdict's test) says whether one is clearly better.
    settings : Settings, optional
        The features' and objective's settings (defaults otherwise).
    progress : callable, optional
        ``progress(stage, done, total)``.

    Returns
    -------
    Comparison
    """
    from .board import board_view
    from .inputs import prepare_lidar
    from .search.basin import CLEAR_P, paired_preference
    from .stage import Stage

    T_a = np.asarray(T_a, dtype=np.float64)
    T_b = np.asarray(T_b, dtype=np.float64)
    e = pose_error(T_b, T_a)
    base = dict(T_a=T_a, T_b=T_b, correction=correction_between(T_a, T_b),
                rotation_deg=float(e["rotation_deg"]),
                translation_m=float(e["translation_cm"]) / 100.0,
                camera_m=(T_b[:3, 3] - T_a[:3, 3]))
    if not frames:
        return Comparison(**base)
    settings = (settings or Settings()).validate()
    cam = frames[0].camera
    lidar = prepare_lidar(frames, settings, [(cam, T_a), (cam, T_b)])
    board = board_view(lidar.frames, settings, lidar.rings, T_a)
    prefs, pixels = [], []
    scores = np.full((2, len(frames)), np.nan)
    for name, T_view in (("A", T_a), ("B", T_b)):
        stage = Stage(lidar.frames, T_view, T_view, settings,
                      None if progress is None else
                      (lambda d, t, v=name: progress(f"features ({v}'s view)", d, t)),
                      rings=lidar.rings, sampling=False,
                      board=None if board is None else board.scene)
        obj = stage.objective
        x = np.zeros((2, 7))
        x[:, :6] = correction_between(T_view, np.stack([T_a, T_b]))
        x[:, 6] = stage.n_max
        # One-sided in B's favour; A's is its complement (the same t, reversed).
        ab = paired_preference(obj, x[0], x[1])
        prefs.append(Preference(name, ab["mean_px"], ab["se_px"], ab["p"], 1.0 - ab["p"],
                                ab["frames"], ab["frames_far_better"]))
        pixels.append(displacement_px(obj, x[0], x[1]))
        if name == "A":
            per = np.asarray(obj.chamfer(x, ucb_k=0.0)["per_frame"], dtype=np.float64)
            where = {n: k for k, n in enumerate(obj.scene.names)}
            for j, f in enumerate(frames):
                if f.name in where:
                    scores[:, j] = per[:, where[f.name]]
    p_b = max(p.p_b for p in prefs)
    p_a = max(p.p_a for p in prefs)
    k = prefs[0].frames
    if k < 2:
        prefer, reason = "neither", ("one frame: a paired test needs at least two; compare "
                                     "on more frames")
    elif p_b < CLEAR_P:
        prefer, reason = "B", _prefer_text("B", prefs, p_b)
    elif p_a < CLEAR_P:
        prefer, reason = "A", _prefer_text("A", prefs, p_a)
    else:
        prefer = "neither"
        reason = (f"the frames do not tell them apart (B's mean advantage "
                  f"{prefs[0].mean_px:+.3f} px with A's points, {prefs[1].mean_px:+.3f} px "
                  f"with B's; p {min(p_a, p_b):.3g}, clear below {CLEAR_P:g})")
    return Comparison(**base, pixels=float(np.mean(pixels)), preferences=tuple(prefs),
                      prefer=prefer, reason=reason, frames=tuple(f.name for f in frames),
                      frame_scores=scores, sweeps=tuple(lidar.frames))


def _prefer_text(who: str, prefs: list, p: float) -> str:
    sign = 1.0 if who == "B" else -1.0
    better = [p_.frames_b_better if who == "B" else p_.frames - p_.frames_b_better
              for p_ in prefs]
    return (f"the frames prefer {who}: it aligns better by {sign * prefs[0].mean_px:.3f} px "
            f"per frame with A's points and {sign * prefs[1].mean_px:.3f} px with B's "
            f"({better[0]} and {better[1]} of {prefs[0].frames} frames; p at most {p:.2g} with "
            "either view's points)")
