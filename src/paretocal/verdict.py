"""Whether to trust a calibration: the evidence, the per-axis intervals and the verdict.

A user calibrating their own rig has no ground truth, so the verdict of ``result.json`` is all
they have. It is built from what the run computed (frames that contribute, points in view,
search bounds, the stated initial error, the near/far basin test, motion, rings, the jackknife
agreement of the frames) and from two checks made for it after the calibration:

* **an independent restart** (:func:`restart_evidence`): a second, smaller search of the same
  box from another random population, without the initial extrinsic or the seed grid, polished
  to its local optimum. Frames that share one wrong basin agree with each other, so the jackknife
  cannot see it; a second search that ends elsewhere and fits the frames as well (a paired test
  over frames) can.
* **image-cloud agreement** (:func:`contrast_evidence`): the objective at the result against
  random poses within the stated initial error around it, frame by frame. A true alignment
  explains every frame's edges clearly better than poses far away; images paired with clouds of
  another scene, or a scene without structure, do not.
* **the cameras' agreement** (:func:`camera_evidence`, a joint calibration of several cameras
  only): each camera's own frames polished alone from the result. A bias every frame of one
  camera shares (or a camera-to-camera extrinsic that is not the rig's) is invisible to the
  restart and the jackknife, but it pulls that camera's own optimum away from the others'.

:func:`intervals` turns the jackknife standard errors, the image alignment the result reached
(:func:`alignment_px`) and how far each axis can move for a pixel of displacement
(:func:`pose_per_px`) into per-axis 95 % intervals, and names the axes the data do not
determine. They are measured at the result's local optimum, so they hold for the result only
with the way from it to that optimum added (:func:`polish_move`): what more search would still
move it. A result the local polish moves beyond the intervals the data give about the optimum
(a search too short, unpolished) is not where the frames put it, however well they agree.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .config import DecisionSettings, SearchSettings
from .crosscheck import MotionAgreement
from .camera import project
from .features.lidar import GROUP_NAMES, SMOOTH
from .lidar.rings import MIN_PURITY
from .geometry import pose_error
from .quality import (AXES, TO_REPORT, UNITS, at_every_point, axis_resolution, cm_written,
                      displacement_px, local_optimum, pixel_fd_step, quality_report)
from .search.basin import (SAME_BASIN_SHARE, USABLE_DEG, USABLE_M, departure,
                           paired_preference)

if TYPE_CHECKING:  # pragma: no cover
    from .result import CalibrationResult
    from .stage import FeatureCounts

#: A frame with fewer LiDAR feature points in view adds nothing the verdict can count on.
MIN_POINTS_PER_FRAME = 30
#: Fewer frames cannot average out one scene's biases (a single wall, a single pole), and the
#: jackknife standard errors need several frames to mean anything.
RELIABLE_MIN_FRAMES = 3
#: Feature points are chosen in view (plus a 60 px margin) at the initial extrinsic, so a sound
#: solution keeps most of them in the image (0.8-0.95 on KITTI); below this share the score is
#: mostly the out-of-view charge and says little about alignment.
RELIABLE_MIN_IN_VIEW = 0.6
#: A correction within this share of a search bound was stopped by the box, not by the data:
#: the optimum may lie outside it.
RELIABLE_BOUND_MARGIN = 0.01
#: Jackknife (leave-one-frame-out) standard errors above these mean the frames disagree about
#: the pose by more than a usable calibration allows (1 deg moves a point 20 m away by 35 cm).
RELIABLE_MAX_SE_DEG = 1.0
RELIABLE_MAX_SE_CM = 10.0
#: A 95 % interval wider than a usable calibration allows (the same limits: the accuracy a
#: result must reach to be called right) means the data cannot vouch for the result, however
#: well the frames agree.
RELIABLE_MAX_HALF_DEG = 1.0
RELIABLE_MAX_HALF_CM = 10.0
#: A sweep skewed by more than this (m) and not de-skewed misplaces points by up to half of
#: it: the same scale as the translation error a usable calibration allows.
MAX_UNCOMPENSATED_SKEW_M = 0.1


# --- evidence gathered after the calibration -----------------------------------------------
#: Random poses of the image-cloud agreement check.
CONTRAST_POSES = 64
#: A distinct restart optimum is dismissed only when the frames prefer the result by at least
#: one standard error of their paired differences (one-sided p below this; 0.16 is one sigma).
#: The conventional 0.05 also flagged a correct 16-beam result whose competitor fit 0.1 px
#: worse on average (benchmarks/trust.py); one sigma kept every wrong result flagged.
RESTART_P = 0.16
#: Image-cloud agreement: the result's advantage over the random poses of the check, in units
#: of their spread, must reach this. Measured (benchmarks/trust.py, README): correct KITTI
#: results 4.3-6.1 (16 to 64 beams, 2 to 20 frames), aiMotive night frames at the reference
#: 3.8; images of other frames 2.4-3.0, noise images 2.8, upside-down images 1.8, clouds
#: thinned to 3 % 1.6-2.0 (wrong results).
CONTRAST_MIN_Z = 3.0
#: ... and in at least this share of the frames the result must beat 95 % of the random poses.
CONTRAST_MIN_FRAMES_CLEAR = 0.5
#: 95 % two-sided normal quantile of the jackknife part of the per-axis intervals.
Z95 = 1.959964


# --- the evidence as typed records ----------------------------------------------------------
# Each record holds the figures result.json writes, in metres and degrees: a figure written in
# cm, rounded to k decimals, is held as that rounded figure / 100, and written back by
# cm_written (rounding again to k decimals recovers the written figure exactly).

def _cm_or_none(m: float, digits: int) -> float | None:
    """:func:`~paretocal.quality.cm_written`, None where not finite."""
    return cm_written(m, digits) if np.isfinite(m) else None


def _rounded_si(v_report, digits: int) -> np.ndarray:
    """Per-axis figures in report units (cm and deg) rounded to ``digits``, in m and deg (6,);
    NaN where not finite."""
    v = np.asarray(v_report, dtype=np.float64)
    return np.array([round(float(x), digits) if np.isfinite(x) else np.nan for x in v]) / TO_REPORT


def _per_axis(v_si: np.ndarray, digits: int) -> dict[str, float | None]:
    """Per-axis figures (6,) in m and deg by axis name in report units (cm and deg), rounded
    to ``digits``; None where not finite."""
    return {a: round(float(x * f), digits) if np.isfinite(x) else None
            for a, x, f in zip(AXES, np.asarray(v_si, dtype=np.float64), TO_REPORT)}


def _axes_si(doc: dict | None) -> np.ndarray:
    """Per-axis figures by name in report units (a key missing or None: NaN) in m and deg."""
    doc = doc or {}
    return np.array([np.nan if doc.get(a) is None else float(doc[a]) for a in AXES]) / TO_REPORT


def _or_none(v: float) -> float | None:
    """``v`` as written: None where not finite."""
    return float(v) if np.isfinite(v) else None


def _nan(v) -> float:
    """A figure read back: NaN for None."""
    return np.nan if v is None else float(v)


# A figure that is not finite (none measured, or one missing from a file read back) is written
# null, never as JSON's invalid NaN.


@dataclass(frozen=True)
class RestartRun:
    """One independent restart of the search and how it compares with the result
    (:func:`restart_evidence`).

    Attributes
    ----------
    separation_deg : float
        Rotation between the restart's local optimum and the result's (deg, 4 decimals).
    separation_m : float
        Translation between them (m; written in cm, 3 decimals).
    separation_px : float
        Mean displacement of the feature points between them (px).
    same_basin : bool
        Within the truncation share of one another: one basin.
    distinct : bool
        Farther apart than a usable calibration allows.
    mean_px : float
        The frames' mean preference for the restart's optimum (px; positive: it fits better).
    p_restart_better : float
        One-sided p of that preference; NaN without one (one frame; written null).
    frames_restart_better : int
    frames : int
    evaluations : int
        The restart's evaluations.
    correction : ndarray, shape (6,)
        The restart's best solution (m, deg).
    """

    separation_deg: float
    separation_m: float
    separation_px: float
    same_basin: bool
    distinct: bool
    mean_px: float
    p_restart_better: float
    frames_restart_better: int
    frames: int
    evaluations: int
    correction: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        """As ``result.json`` writes it (the separation in cm)."""
        return {"separation_deg": _or_none(self.separation_deg),
                "separation_cm": _cm_or_none(self.separation_m, 3),
                "separation_px": _or_none(self.separation_px),
                "same_basin": bool(self.same_basin), "distinct": bool(self.distinct),
                "mean_px": _or_none(self.mean_px),
                "p_restart_better": _or_none(self.p_restart_better),
                "frames_restart_better": int(self.frames_restart_better),
                "frames": int(self.frames), "evaluations": int(self.evaluations),
                "correction": [_or_none(v) for v in self.correction]}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "RestartRun":
        """Read back from :meth:`to_dict`'s form; a figure it lacks reads as NaN (0, False).

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (lengths in cm, angles in deg, as ``result.json`` writes
            them).
        """
        return cls(separation_deg=_nan(doc.get("separation_deg")),
                   separation_m=_nan(doc.get("separation_cm")) / 100.0,
                   separation_px=_nan(doc.get("separation_px")),
                   same_basin=bool(doc.get("same_basin", False)),
                   distinct=bool(doc.get("distinct", False)), mean_px=_nan(doc.get("mean_px")),
                   p_restart_better=_nan(doc.get("p_restart_better")),
                   frames_restart_better=int(doc.get("frames_restart_better", 0)),
                   frames=int(doc.get("frames", 0)), evaluations=int(doc.get("evaluations", 0)),
                   correction=np.array(doc.get("correction") or [np.nan] * 6, dtype=np.float64))


@dataclass(frozen=True)
class RestartCheck:
    """The independent restart(s) (:func:`restart_evidence`).

    Attributes
    ----------
    runs : tuple of RestartRun
    disagrees : bool
        A distinct restart optimum the frames do not clearly reject.
    evaluations : int
        Evaluations of every restart.
    result_optimum : ndarray, shape (7,), or None
        The result's local optimum at every point (m, deg, n), which the other checks start
        from; not written (None when read back).
    """

    runs: tuple[RestartRun, ...]
    disagrees: bool
    evaluations: int
    result_optimum: np.ndarray | None = None

    def to_dict(self) -> dict[str, Any]:
        """As ``result.json`` writes it (without ``result_optimum``)."""
        return {"runs": [r.to_dict() for r in self.runs], "disagrees": bool(self.disagrees),
                "evaluations": int(self.evaluations)}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "RestartCheck":
        """Read back from :meth:`to_dict`'s form.

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (lengths in cm, angles in deg, as ``result.json`` writes
            them).
        """
        return cls(runs=tuple(RestartRun.from_dict(r) for r in doc.get("runs") or []),
                   disagrees=bool(doc.get("disagrees", False)),
                   evaluations=int(doc.get("evaluations", 0)))


@dataclass(frozen=True)
class Contrast:
    """How clearly the frames prefer the result over random poses about it
    (:func:`contrast_evidence`).

    Attributes
    ----------
    poses : int
        Random poses compared.
    margin_px : float
        The median random pose's objective minus the result's, mean over frames (px).
    z : float
        That margin over the random poses' spread.
    frames_clear : float
        Share of the frames whose objective at the result beats 95 % of the random poses.
    beaten : float
        Share of the (pose, frame) pairs the result beats.
    group_ratio : ndarray, shape (G,)
        Per feature group (:data:`~paretocal.features.lidar.GROUP_NAMES`), the result's mean
        distance over the random poses' median (1 is chance); NaN where that median is not
        positive (written null).
    """

    poses: int
    margin_px: float
    z: float
    frames_clear: float
    beaten: float
    group_ratio: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        """As ``result.json`` writes it (the group ratios by group name)."""
        return {"poses": int(self.poses), "margin_px": _or_none(self.margin_px),
                "z": _or_none(self.z), "frames_clear": _or_none(self.frames_clear),
                "beaten": _or_none(self.beaten),
                "group_ratio": {g: _or_none(v) for g, v in zip(GROUP_NAMES, self.group_ratio)}}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "Contrast":
        """Read back from :meth:`to_dict`'s form; a figure it lacks reads as NaN.

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (lengths in cm, angles in deg, as ``result.json`` writes
            them).
        """
        ratio = doc.get("group_ratio") or {}
        return cls(poses=int(doc.get("poses", 0)), margin_px=_nan(doc.get("margin_px")),
                   z=_nan(doc.get("z")), frames_clear=_nan(doc.get("frames_clear")),
                   beaten=_nan(doc.get("beaten")),
                   group_ratio=np.array([_nan(ratio.get(g)) for g in GROUP_NAMES]))


@dataclass(frozen=True)
class StartComparison:
    """The initial extrinsic against the result, frame by frame (:func:`start_evidence`).

    Attributes
    ----------
    separation_deg : float
        Rotation from the start to the result (deg, 4 decimals).
    separation_m : float
        Translation from the start to the result (m; written in cm, 3 decimals).
    mean_px : float
        The start's mean advantage per frame (px; positive when it fits better).
    frames : int
    frames_start_better : int
    p_start_better : float
        One-sided p; NaN with one frame (written null).
    result_clearly_better : bool
        The frames prefer the result by at least one standard error of their paired
        differences.
    """

    separation_deg: float
    separation_m: float
    mean_px: float
    frames: int
    frames_start_better: int
    p_start_better: float
    result_clearly_better: bool

    def to_dict(self) -> dict[str, Any]:
        """As ``result.json`` writes it (the separation in cm)."""
        return {"separation_deg": _or_none(self.separation_deg),
                "separation_cm": _cm_or_none(self.separation_m, 3),
                "mean_px": _or_none(self.mean_px),
                "frames": int(self.frames), "frames_start_better": int(self.frames_start_better),
                "p_start_better": _or_none(self.p_start_better),
                "result_clearly_better": bool(self.result_clearly_better)}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "StartComparison":
        """Read back from :meth:`to_dict`'s form; a figure it lacks reads as NaN (0, False).

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (lengths in cm, angles in deg, as ``result.json`` writes
            them).
        """
        return cls(separation_deg=_nan(doc.get("separation_deg")),
                   separation_m=_nan(doc.get("separation_cm")) / 100.0,
                   mean_px=_nan(doc.get("mean_px")), frames=int(doc.get("frames", 0)),
                   frames_start_better=int(doc.get("frames_start_better", 0)),
                   p_start_better=_nan(doc.get("p_start_better")),
                   result_clearly_better=bool(doc.get("result_clearly_better", False)))


@dataclass(frozen=True)
class CameraCheck:
    """One camera of a joint calibration polished alone (:func:`camera_evidence`); the
    figures after ``checked`` are NaN (``agrees`` None) for a camera not checked.

    Attributes
    ----------
    name : str
    frames : int
        The camera's frames.
    checked : bool
        Whether it had frames enough to be checked.
    own_optimum_px : float
        How far its own optimum moves its feature points in its images (px).
    tolerance_px : float
        The bias its edges can be trusted to (px).
    agrees : bool or None
        ``own_optimum_px <= tolerance_px``.
    separation_deg : float
        Rotation from the result to its own optimum (deg, 4 decimals).
    separation_m : float
        Translation from the result to its own optimum (m; written in cm, 3 decimals).
    d : ndarray, shape (6,)
        The correction from the result to its own optimum, LiDAR frame (m, deg; written in cm
        and deg, 4 decimals).
    """

    name: str
    frames: int
    checked: bool
    own_optimum_px: float = np.nan
    tolerance_px: float = np.nan
    agrees: bool | None = None
    separation_deg: float = np.nan
    separation_m: float = np.nan
    d: np.ndarray = dataclasses.field(default_factory=lambda: np.full(6, np.nan))

    def to_dict(self) -> dict[str, Any]:
        """As ``result.json`` writes it: the figures after ``checked`` only when checked."""
        out: dict[str, Any] = {"name": self.name, "frames": int(self.frames),
                               "checked": bool(self.checked)}
        if self.checked:
            out.update(own_optimum_px=_or_none(self.own_optimum_px),
                       tolerance_px=_or_none(self.tolerance_px), agrees=bool(self.agrees),
                       separation_deg=_or_none(self.separation_deg),
                       separation_cm=_cm_or_none(self.separation_m, 3), d=_per_axis(self.d, 4))
        return out

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "CameraCheck":
        """Read back from :meth:`to_dict`'s form; a figure it lacks reads as NaN.

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (lengths in cm, angles in deg, as ``result.json`` writes
            them).
        """
        agrees = doc.get("agrees")
        return cls(name=str(doc.get("name", "")), frames=int(doc.get("frames", 0)),
                   checked=bool(doc.get("checked", False)),
                   own_optimum_px=_nan(doc.get("own_optimum_px")),
                   tolerance_px=_nan(doc.get("tolerance_px")),
                   agrees=None if agrees is None else bool(agrees),
                   separation_deg=_nan(doc.get("separation_deg")),
                   separation_m=_nan(doc.get("separation_cm")) / 100.0, d=_axes_si(doc.get("d")))


@dataclass(frozen=True)
class CameraAgreement:
    """Whether the cameras of a joint calibration agree (:func:`camera_evidence`).

    Attributes
    ----------
    cameras : tuple of CameraCheck
    disagreeing : tuple of str
        The names of the cameras checked that do not agree.
    """

    cameras: tuple[CameraCheck, ...]
    disagreeing: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        """As ``result.json`` writes it."""
        return {"cameras": [c.to_dict() for c in self.cameras],
                "disagreeing": list(self.disagreeing)}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "CameraAgreement":
        """Read back from :meth:`to_dict`'s form.

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (lengths in cm, angles in deg, as ``result.json`` writes
            them).
        """
        return cls(cameras=tuple(CameraCheck.from_dict(c) for c in doc.get("cameras") or []),
                   disagreeing=tuple(str(n) for n in doc.get("disagreeing") or []))


@dataclass(frozen=True)
class PolishMove:
    """What a local polish from the result moves it (:func:`polish_move`): the way from the
    result to its local optimum at every feature point without the sampling-error charge,
    the pose the intervals are measured at. A search that ended short of its optimum (too few
    generations, the polish switched off) is moved by it; a polished result hardly at all.

    Attributes
    ----------
    d : ndarray, shape (6,)
        The correction from the result to its local optimum, on the correction's axes (the
        LiDAR frame; m and deg, held as written in cm and deg, 4 decimals).
    separation_deg : float
        Its rotation (deg, 4 decimals).
    separation_m : float
        Its translation (m; written in cm, 3 decimals).
    px : float
        Mean displacement of the feature points between the two (px, 3 decimals).
    polished : bool
        Whether the run polished its front (``decision.polish``).
    """

    d: np.ndarray
    separation_deg: float
    separation_m: float
    px: float
    polished: bool

    def to_dict(self) -> dict[str, Any]:
        """As ``result.json`` writes it (cm and deg)."""
        return {"d": _per_axis(self.d, 4), "separation_deg": _or_none(self.separation_deg),
                "separation_cm": _cm_or_none(self.separation_m, 3),
                "px": _or_none(self.px), "polished": bool(self.polished)}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "PolishMove":
        """Read back from :meth:`to_dict`'s form; a figure it lacks reads as NaN.

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (lengths in cm, angles in deg, as ``result.json`` writes
            them).
        """
        return cls(d=_axes_si(doc.get("d")), separation_deg=_nan(doc.get("separation_deg")),
                   separation_m=_nan(doc.get("separation_cm")) / 100.0,
                   px=_nan(doc.get("px")), polished=bool(doc.get("polished", True)))


@dataclass(frozen=True)
class Intervals:
    """Per-axis 95 % intervals of the correction (:func:`intervals`), on the correction's
    axes ``x, y, z, yaw, pitch, roll`` (the LiDAR frame; m and deg). Every per-axis figure
    is held as ``result.json`` writes it, rounded in cm and deg (``jackknife_se``,
    ``per_px``, ``bias`` and ``resolution_per_px`` to 5 decimals, ``half_width`` to 4), and
    is NaN where it is not finite (written null).

    Attributes
    ----------
    jackknife_se : ndarray, shape (6,)
        The frames' jackknife standard errors as used (m, deg).
    half_width : ndarray, shape (6,)
        The intervals' half-widths (m, deg); NaN where the axis is not determined.
    determined : ndarray, shape (6,), bool
        Whether the data determine each axis.
    alignment_px : float
        The image alignment the result reached (px, 4 decimals); NaN when no edge matched.
    sampling_px : ndarray, shape (2,), or None
        The LiDAR's sampling step in the image along u and v (px, 3 decimals).
    per_px : ndarray, shape (6,)
        Largest change of each axis per pixel rms, the others free (m, deg per px).
    bias : ndarray, shape (6,)
        The bound of a bias the frames share (m, deg).
    resolution_per_px : ndarray, shape (6,), or None
        Change of each axis alone per pixel (m, deg per px).
    move : ndarray, shape (6,), or None
        What a local polish moves the result by on each axis (m, deg; :class:`PolishMove`),
        included in ``half_width``; None: not measured (nothing added).
    """

    jackknife_se: np.ndarray
    half_width: np.ndarray
    determined: np.ndarray
    alignment_px: float
    sampling_px: np.ndarray | None
    per_px: np.ndarray
    bias: np.ndarray
    resolution_per_px: np.ndarray | None = None
    move: np.ndarray | None = None

    @property
    def undetermined(self) -> tuple[str, ...]:
        """The names of the axes the data do not determine."""
        return tuple(a for a, k in zip(AXES, self.determined) if not k)

    def half_width_report(self) -> dict[str, float | None]:
        """The half-widths by axis name in cm and deg, as written (None: not determined)."""
        return _per_axis(self.half_width, 4)

    def jackknife_se_report(self) -> dict[str, float | None]:
        """The jackknife standard errors by axis name in cm and deg, as written."""
        return _per_axis(self.jackknife_se, 5)

    def to_dict(self) -> dict[str, Any]:
        """As ``result.json`` writes it: ``frame`` ``"lidar"``, ``units``, the per-axis
        figures by axis name in cm and deg, ``undetermined`` (list of axis names)."""
        out: dict[str, Any] = {
            "frame": "lidar", "units": dict(zip(AXES, UNITS)),
            "jackknife_se": self.jackknife_se_report(),
            "half_width": self.half_width_report(),
            "determined": {a: bool(k) for a, k in zip(AXES, self.determined)},
            "undetermined": list(self.undetermined),
            "alignment_px": _or_none(self.alignment_px),
            "sampling_px": (None if self.sampling_px is None
                            else [_or_none(v) for v in self.sampling_px]),
            "per_px": _per_axis(self.per_px, 5), "bias": _per_axis(self.bias, 5)}
        if self.resolution_per_px is not None:
            out["resolution_per_px"] = _per_axis(self.resolution_per_px, 5)
        if self.move is not None:
            out["move"] = _per_axis(self.move, 5)
        return out

    def beyond_optimum(self) -> dict[str, tuple[float, float]]:
        """The axes on which the result's local optimum lies outside the interval the data
        give about it: ``{axis: (move, half-width about the optimum)}`` in cm and deg (the
        determined axes only; empty without a move)."""
        if self.move is None:
            return {}
        half, move = self.half_width_report(), _per_axis(np.abs(self.move), 5)
        out = {}
        for a in AXES:
            h, m = half[a], move[a]
            if h is not None and m is not None and m > h - m:
                out[a] = (m, round(h - m, 4))
        return out

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "Intervals":
        """Read back from :meth:`to_dict`'s form; a figure it lacks reads as NaN, an axis
        without ``determined`` as determined unless ``undetermined`` names it.

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (lengths in cm, angles in deg, as ``result.json`` writes
            them).
        """
        undetermined = set(doc.get("undetermined") or [])
        det = doc.get("determined") or {}
        samp, res = doc.get("sampling_px"), doc.get("resolution_per_px")
        move = doc.get("move")
        return cls(jackknife_se=_axes_si(doc.get("jackknife_se")),
                   half_width=_axes_si(doc.get("half_width")),
                   determined=np.array([bool(det.get(a, a not in undetermined)) for a in AXES]),
                   alignment_px=_nan(doc.get("alignment_px")),
                   sampling_px=None if samp is None else np.array([_nan(v) for v in samp]),
                   per_px=_axes_si(doc.get("per_px")), bias=_axes_si(doc.get("bias")),
                   resolution_per_px=None if res is None else _axes_si(res),
                   move=None if move is None else _axes_si(move))


@dataclass(frozen=True)
class Evidence:
    """What the verdict checks beyond the run itself (:func:`gather_evidence`); a part not
    gathered is None.

    Attributes
    ----------
    contrast : Contrast or None
        Image-cloud agreement (:func:`contrast_evidence`).
    start : StartComparison or None
        The initial extrinsic against the result (:func:`start_evidence`).
    intervals : Intervals or None
        Per-axis 95 % intervals (:func:`intervals`).
    restart : RestartCheck or None
        The independent restart(s) (:func:`restart_evidence`); None when switched off.
    cameras : CameraAgreement or None
        The cameras' agreement (:func:`camera_evidence`), a joint calibration only.
    motion : MotionAgreement or None
        The result's rotation against the recording's motion
        (:func:`paretocal.crosscheck.motion_agreement`); None when not checked (fewer than
        three frames, a joint calibration, or ``decision.motion_check`` off).
    move : PolishMove or None
        What a local polish from the result moves it (:func:`polish_move`).
    """

    contrast: Contrast | None = None
    start: StartComparison | None = None
    intervals: Intervals | None = None
    restart: RestartCheck | None = None
    cameras: CameraAgreement | None = None
    motion: MotionAgreement | None = None
    move: PolishMove | None = None

    def to_dict(self, intervals: bool = True) -> dict[str, Any]:
        """As ``result.json`` writes it, the parts gathered by name.

        Parameters
        ----------
        intervals : bool
            False: without the intervals, as the verdict's ``evidence`` writes it.

        Returns
        -------
        dict
        """
        parts = {"contrast": self.contrast, "start": self.start,
                 "intervals": self.intervals if intervals else None,
                 "restart": self.restart, "cameras": self.cameras, "motion": self.motion,
                 "move": self.move}
        return {k: v.to_dict() for k, v in parts.items() if v is not None}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "Evidence":
        """Read back from :meth:`to_dict`'s form (a part it lacks: None).

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (lengths in cm, angles in deg, as ``result.json`` writes
            them).
        """
        def part(key, kind):
            v = doc.get(key)
            return None if v is None else kind.from_dict(v)

        return cls(contrast=part("contrast", Contrast), start=part("start", StartComparison),
                   intervals=part("intervals", Intervals),
                   restart=part("restart", RestartCheck),
                   cameras=part("cameras", CameraAgreement),
                   motion=part("motion", MotionAgreement), move=part("move", PolishMove))


@dataclass(frozen=True)
class Reliability:
    """The verdict on a result (:func:`reliability`): whether to trust it, why not, and what
    it was judged from.

    Attributes
    ----------
    verdict : str
        ``"ok"`` or ``"unreliable"``.
    reasons : tuple of str
        What made it unreliable, for a person; empty when ok.
    evidence : Evidence or None
        The verdict's own checks (:func:`gather_evidence`), None without them; its intervals
        are :attr:`intervals` for a result judged ok, :attr:`intervals_not_trusted` else.
    frames : int
        Frames of the run.
    in_view : float
        Share of the feature points in view at the chosen extrinsic (4 decimals); NaN when
        not known (written null).
    at_bound : tuple of str
        The axes on which the correction sits at a search bound.
    max_jackknife_se_deg : float
        The largest rotation jackknife standard error the verdict read (deg, 4 decimals);
        NaN without one (written null).
    max_jackknife_se_m : float
        The largest translation jackknife standard error the verdict read (m; written in cm,
        3 decimals); NaN without one.
    """

    verdict: str
    reasons: tuple[str, ...] = ()
    evidence: Evidence | None = None
    frames: int = 0
    in_view: float = np.nan
    at_bound: tuple[str, ...] = ()
    max_jackknife_se_deg: float = np.nan
    max_jackknife_se_m: float = np.nan

    @property
    def ok(self) -> bool:
        """Whether the result is judged ok."""
        return self.verdict == "ok"

    @property
    def intervals(self) -> Intervals | None:
        """The per-axis 95 % intervals, only for a result judged ok: the errors that make a
        result unreliable are ones the intervals do not measure."""
        return None if self.reasons or self.evidence is None else self.evidence.intervals

    @property
    def intervals_not_trusted(self) -> Intervals | None:
        """The intervals of a result judged unreliable (not what they claim)."""
        return None if not self.reasons or self.evidence is None else self.evidence.intervals

    @property
    def start(self) -> StartComparison | None:
        """How the initial extrinsic compares, for a result judged unreliable (keep the
        start?); None for one judged ok."""
        return None if not self.reasons or self.evidence is None else self.evidence.start

    def to_dict(self) -> dict[str, Any]:
        """As ``result.json`` writes it (``reliability``): the intervals under ``intervals``
        or ``intervals_not_trusted``, the rest of the evidence under ``evidence``."""
        def written(part):
            return None if part is None else part.to_dict()

        ev = None if self.evidence is None else self.evidence.to_dict(intervals=False)
        return {
            "verdict": self.verdict,
            "reasons": list(self.reasons),
            "intervals": written(self.intervals),
            "intervals_not_trusted": written(self.intervals_not_trusted),
            "evidence": ev or None,
            "start": written(self.start),
            "frames": int(self.frames),
            "in_view": _or_none(self.in_view),
            "at_bound": list(self.at_bound),
            "max_jackknife_se_deg": _or_none(self.max_jackknife_se_deg),
            "max_jackknife_se_cm": _cm_or_none(self.max_jackknife_se_m, 3),
        }

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "Reliability":
        """Read back from :meth:`to_dict`'s form (``result.json``'s ``reliability``).

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (lengths in cm, angles in deg, as ``result.json`` writes
            them).
        """
        iv = doc.get("intervals") or doc.get("intervals_not_trusted")
        parts = dict(doc.get("evidence") or {})
        if iv is not None:
            parts["intervals"] = iv
        if doc.get("start") is not None:
            parts.setdefault("start", doc["start"])
        return cls(verdict=str(doc.get("verdict", "")),
                   reasons=tuple(str(r) for r in doc.get("reasons") or []),
                   evidence=Evidence.from_dict(parts) if parts else None,
                   frames=int(doc.get("frames", 0)), in_view=_nan(doc.get("in_view")),
                   at_bound=tuple(str(a) for a in doc.get("at_bound") or []),
                   max_jackknife_se_deg=_nan(doc.get("max_jackknife_se_deg")),
                   max_jackknife_se_m=_nan(doc.get("max_jackknife_se_cm")) / 100.0)


def restart_evidence(objective, search: SearchSettings, decision: DecisionSettings, n_min: int,
                     n_max: int, x: np.ndarray, x_opt: np.ndarray | None = None) -> RestartCheck:
    """An independent restart and how it compares with the result.

    Parameters
    ----------
    objective : CalibrationObjective
    search : SearchSettings
        The main search's settings.
    decision : DecisionSettings
        ``restarts`` searches with ``restart_share`` of the main search's evaluations each
        (population and generations scaled by its square root), seeds ``search.seed + 1, + 2,
        ...``; no initial extrinsic or seed grid in their populations.
    n_min, n_max : int
    x : ndarray, shape (7,)
        The result's correction.
    x_opt : ndarray, shape (7,), optional
        The result's local optimum at every point (computed when omitted).

    Returns
    -------
    RestartCheck
        Per restart its separation from the result's optimum, whether it is distinct
        (farther apart than a usable calibration allows), the paired comparison (positive
        ``mean_px``: the restart fits better); ``disagrees`` (a distinct restart optimum the
        frames do not clearly reject) and ``result_optimum`` (``x_opt``, or the one computed).
    """
    found, spent = restart_searches(objective, search, decision, n_min, n_max)
    # The restarts' local optima (and the result's, when not given) in one batch.
    starts = found if x_opt is not None else np.vstack([x, found])
    opt = local_optimum(objective, starts) if len(starts) else starts
    if x_opt is None:
        x_opt, opt = opt[0], opt[1:]
    T0 = objective.transforms(x_opt[None])[0]
    runs, evaluations = [], 0
    for y, ev in zip(opt, spent):
        e = pose_error(objective.transforms(y[None])[0], T0)
        sep_px = displacement_px(objective, x_opt, y)
        same = bool(sep_px <= SAME_BASIN_SHARE * objective.scene.truncation_px)
        distinct = bool(not same and (e["rotation_deg"] > USABLE_DEG
                                      or e["translation_cm"] > 100 * USABLE_M))
        cmp = paired_preference(objective, x_opt, y)
        runs.append(RestartRun(
            separation_deg=round(float(e["rotation_deg"]), 4),
            separation_m=round(float(e["translation_cm"]), 3) / 100.0,
            separation_px=round(float(sep_px), 3), same_basin=same, distinct=distinct,
            mean_px=round(cmp["mean_px"], 5),
            p_restart_better=round(cmp["p"], 5) if np.isfinite(cmp["p"]) else np.nan,
            frames_restart_better=cmp["frames_far_better"], frames=cmp["frames"],
            evaluations=ev, correction=np.array(y[:6], dtype=np.float64)))
        evaluations += ev

    def doubt(run: RestartRun) -> bool:
        # A distinct optimum is dismissed only when the frames clearly prefer the result.
        p = run.p_restart_better
        worse = bool(np.isfinite(p) and (1.0 - p) < RESTART_P)
        return run.distinct and not worse
    return RestartCheck(runs=tuple(runs), disagrees=bool(any(doubt(r) for r in runs)),
                        evaluations=evaluations, result_optimum=x_opt)


def restart_searches(objective, search: SearchSettings, decision: DecisionSettings,
                     n_min: int, n_max: int) -> tuple[np.ndarray, list[int]]:
    """The independent restarts of :func:`restart_evidence`: the best solution (7,) of each,
    stacked (restarts, 7), and the evaluations each spent.

    Parameters
    ----------
    objective : CalibrationObjective
        The run's objective.
    search : SearchSettings
        The main search's settings.
    decision : DecisionSettings
        ``restarts`` and ``restart_share`` (the share of the main search's evaluations each).
    n_min, n_max : int
        The range of points per frame.

    Returns
    -------
    best : ndarray, shape (restarts, 7)
        Each restart's best solution ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points).
    evaluations : list of int
        The evaluations each spent.
    """
    from .search import run_nsga2

    d, s = decision, search
    scale = math.sqrt(d.restart_share)
    found, spent = [], []
    for r in range(d.restarts):
        # Never larger than the main search, however small that was.
        rs = dataclasses.replace(s, pop=max(min(s.pop, 20), int(round(s.pop * scale))),
                                 gens=max(min(s.gens, 10), int(round(s.gens * scale))),
                                 seed=s.seed + 1 + r, include_init=False)
        res = run_nsga2(objective, rs, n_min, n_max)
        found.append(res.X[int(np.argmin(res.F[:, 0]))])
        spent.append(int(res.evaluations))
    return np.reshape(found, (-1, 7)), spent


def contrast_evidence(objective, search: SearchSettings, x_opt: np.ndarray, poses: int = CONTRAST_POSES,
                      rng: np.random.Generator | int | None = None) -> Contrast:
    """How clearly the frames prefer the result over random poses about it.

    Parameters
    ----------
    objective : CalibrationObjective
    search : SearchSettings
        The random poses are uniform within ``search.init_error_deg`` / ``init_error_m`` of the
        result on every axis.
    x_opt : ndarray, shape (7,)
    poses : int
    rng : Generator or int, optional
        Seed of the random poses (``search.seed`` when omitted).

    Returns
    -------
    Contrast
        ``margin_px`` (median random pose's objective minus the result's, mean over frames);
        ``z`` (that margin over the random poses' spread); ``frames_clear`` (share of frames
        whose objective at the result beats 95 % of the random poses); ``beaten`` (share of
        (pose, frame) pairs the result beats); ``group_ratio`` (per feature group, the
        result's mean distance over the random poses' median: 1 is chance).
    """
    s = search
    rng = np.random.default_rng(s.seed if rng is None else rng)
    half = np.r_[[s.init_error_m] * 3, [s.init_error_deg] * 3]
    P = np.tile(at_every_point(objective, x_opt), (poses + 1, 1))
    P[1:, :6] += rng.uniform(-1.0, 1.0, (poses, 6)) * half
    out = objective.chamfer(P, ucb_k=0.0)
    per = np.asarray(out["per_frame"], dtype=np.float64)
    groups = np.asarray(out["mean"], dtype=np.float64)                  # (poses + 1, G)
    f0, fr = per[0], per[1:]
    means = fr.mean(axis=1)
    spread = float(np.std(means)) or float("nan")
    beaten = (fr > f0[None, :])
    return Contrast(poses=int(poses),
                    margin_px=round(float(np.median(means) - f0.mean()), 4),
                    z=round(float((np.median(means) - f0.mean()) / spread), 3),
                    frames_clear=round(float((beaten.mean(axis=0) >= 0.95).mean()), 4),
                    beaten=round(float(beaten.mean()), 4),
                    group_ratio=np.array([
                        round(float(groups[0, i] / np.median(groups[1:, i])), 4)
                        if np.median(groups[1:, i]) > 0 else np.nan
                        for i in range(len(GROUP_NAMES))]))


def start_evidence(objective, x_opt: np.ndarray) -> StartComparison:
    """The initial extrinsic against the result, frame by frame (the paired test of the
    restart check), so that a user can tell whether to keep their start when the result is
    not trusted.

    Parameters
    ----------
    objective : CalibrationObjective
        Its corrections are relative to the initial extrinsic (the zero correction).
    x_opt : ndarray, shape (7,)
        The result's local optimum.

    Returns
    -------
    StartComparison
        The separation of the result from the start, ``mean_px`` (the start's mean advantage
        per frame, positive when it fits better), ``frames`` and ``frames_start_better``,
        ``p_start_better`` (one-sided; NaN with one frame) and ``result_clearly_better``: the
        frames prefer the result by at least one standard error of their paired differences
        (:data:`RESTART_P`).
    """
    x0 = at_every_point(objective, np.zeros(7))
    x_opt = at_every_point(objective, x_opt)
    cmp = paired_preference(objective, x_opt, x0)
    T = objective.transforms(np.vstack([x_opt, x0]))
    e = pose_error(T[0], T[1])
    p = cmp["p"] if np.isfinite(cmp["p"]) else None
    # One frame gives no spread to judge by: never "clearly".
    clearly = bool(cmp["mean_px"] < 0 and p is not None and (1.0 - p) < RESTART_P)
    return StartComparison(separation_deg=round(float(e["rotation_deg"]), 4),
                           separation_m=round(float(e["translation_cm"]), 3) / 100.0,
                           mean_px=round(float(cmp["mean_px"]), 5), frames=cmp["frames"],
                           frames_start_better=cmp["frames_far_better"],
                           p_start_better=np.nan if p is None else round(float(p), 5),
                           result_clearly_better=clearly)


def start_text(start: StartComparison) -> str:
    """How the initial extrinsic compares with a result that is not trusted, in words for the
    verdict line.

    Parameters
    ----------
    start : StartComparison
        From :func:`start_evidence`.

    Returns
    -------
    str
    """
    k, n = start.frames_start_better, start.frames
    if start.result_clearly_better:
        return (f"the frames do prefer the result to the initial extrinsic ({n - k} of {n} "
                f"frames, {-start.mean_px:.2g} px closer to the edges on average), but "
                "it may still be wrong")
    return (f"the frames do not clearly prefer the result to the initial extrinsic ({k} of {n} "
            f"frames fit the start better; the result is {start.separation_deg:.2g} deg / "
            f"{cm_written(start.separation_m, 3):.2g} cm from it): keep the initial extrinsic until a "
            "calibration is judged ok")


def alignment_px(objective, x_opt: np.ndarray, frames=None) -> float:
    """How closely the image edges and the LiDAR's edges agree at ``x_opt`` (7,): the median
    distance in pixels from the edge feature points (depth and intensity edges) in view to the
    nearest image edge, read from the distance transforms as the objective reads them
    (bilinear), over the points within the truncation (the others match no edge), of every
    frame or of ``frames`` (indices). NaN when no edge point matches.

    Parameters
    ----------
    objective : CalibrationObjective or FrameSubset
        The objective whose frames and feature points count.
    x_opt : ndarray, shape (7,)
        The pose ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
    frames : sequence of int, optional
        The frames' indices; every frame when omitted.

    Returns
    -------
    float
        Pixels.
    """
    sc = objective.scene
    T = objective.transforms(np.atleast_2d(x_opt))[0]
    found = []
    for f in range(sc.n_frames) if frames is None else frames:
        a, b = sc.point_start[f], sc.point_start[f + 1]
        edge = sc.group[a:b] != SMOOTH
        if not edge.any():
            continue
        uv, _, vis = project(sc.frame_xyz(f)[edge], sc.cameras[f], T, sc.z_min)
        uv = uv[vis]
        dt = sc.frame_dt(f)                                    # NaN on masked pixels
        h, w = dt.shape
        x0 = np.clip(uv[:, 0].astype(np.int64), 0, w - 2)
        y0 = np.clip(uv[:, 1].astype(np.int64), 0, h - 2)
        fx = np.clip(uv[:, 0] - x0, 0.0, 1.0)
        fy = np.clip(uv[:, 1] - y0, 0.0, 1.0)
        d = ((dt[y0, x0] * (1 - fx) + dt[y0, x0 + 1] * fx) * (1 - fy)
             + (dt[y0 + 1, x0] * (1 - fx) + dt[y0 + 1, x0 + 1] * fx) * fy)
        found.append(d[np.isfinite(d) & (d < sc.truncation_px)])
    d = np.concatenate(found) if found else np.empty(0)
    return float(np.median(d)) if len(d) else float("nan")


def pose_per_px(objective, x_opt: np.ndarray) -> np.ndarray:
    """Per axis (m, m, m, deg, deg, deg), the largest change of that axis among the pose
    changes at ``x_opt`` (7,) that move the feature points in view by one pixel rms, the other
    axes free to compensate: ``sqrt(diag(M^-1))`` with ``M`` the mean over the points of
    ``J_p^T J_p`` (``J_p``: the 2 x 6 pixel Jacobian of point p, by finite differences). It
    exceeds the one-axis :func:`~paretocal.quality.axis_resolution` where axes trade against
    each other (camera height against pitch); inf for an axis the points do not pin down.

    Parameters
    ----------
    objective : CalibrationObjective or FrameSubset
        The objective whose frames and feature points count.
    x_opt : ndarray, shape (7,)
        The pose ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).

    Returns
    -------
    ndarray, shape (6,)
        Metres and degrees per pixel.
    """
    sc = objective.scene
    eps = np.r_[[1e-4] * 3, [1e-3] * 3]                        # m, deg: far below a pixel
    X = np.tile(np.asarray(x_opt, dtype=np.float64), (7, 1))
    X[1:, :6] += np.diag(eps)
    T = objective.transforms(X)
    M, count = np.zeros((6, 6)), 0
    for f in range(sc.n_frames):
        pts = sc.frame_xyz(f)
        uv0, _, vis = project(pts, sc.cameras[f], T[0], sc.z_min)
        if not vis.any():
            continue
        uv, _, _ = project(pts[vis], sc.cameras[f], T[1:], sc.z_min)      # (6, m, 2)
        J = (uv - uv0[vis][None]) / eps[:, None, None]
        J = np.where(np.isfinite(J), J, 0.0)
        M += np.einsum("amk,bmk->ab", J, J)
        count += int(vis.sum())
    if count == 0:
        return np.full(6, np.inf)
    w, V = np.linalg.eigh(M / count)
    null = w <= 1e-12 * max(w.max(), 1e-300)
    with np.errstate(divide="ignore"):
        inv = np.where(null, np.inf, 1.0 / np.where(null, 1.0, w))
    var = np.where(V ** 2 > 1e-12, V ** 2 * inv[None, :], 0.0).sum(axis=1)
    return np.sqrt(var)


def camera_evidence(objective, x_opt: np.ndarray, cameras: dict) -> CameraAgreement:
    """Whether the cameras of a joint calibration agree (module docstring).

    Each camera's frames alone are polished from the result's local optimum ``x_opt`` (7,)
    (:class:`~paretocal.objective.FrameSubset`); the camera *agrees* when its own optimum moves
    its feature points, in its own images, by no more than the bias its edges can be trusted
    to (:func:`bias_tolerance_px` of its alignment at ``x_opt`` and its sampling step): the
    bound the intervals allow a bias every frame shares. A camera with fewer than
    :data:`RELIABLE_MIN_FRAMES` frames is not checked (its own optimum is mostly its frames'
    noise).

    Parameters
    ----------
    objective : CalibrationObjective
    x_opt : ndarray, shape (7,)
    cameras : dict
        By camera name: ``(frames, sampling)``, the indices of its frames in the objective's
        scene and its LiDAR sampling step in the image (2,) px, or None.

    Returns
    -------
    CameraAgreement
        ``cameras``: per camera its name, frames, whether it was checked, and when checked
        ``own_optimum_px`` (the displacement), ``tolerance_px``, ``agrees``, the separation
        and the correction ``d`` (LiDAR frame, m and deg) from the result to the camera's own
        optimum; ``disagreeing``: the names of those that do not agree.
    """
    from .objective import FrameSubset
    from .quality import correction_between

    T0 = objective.transforms(np.atleast_2d(x_opt))[0]
    out = []
    for name, (idx, sampling) in cameras.items():
        idx = np.asarray(idx, dtype=np.int64)
        rec = CameraCheck(name=name, frames=int(len(idx)),
                          checked=len(idx) >= RELIABLE_MIN_FRAMES)
        if rec.checked:
            xc = local_optimum(FrameSubset(objective, idx), x_opt)
            Tc = objective.transforms(xc[None])[0]
            px = displacement_px(objective, x_opt, xc, idx)
            tol = bias_tolerance_px(alignment_px(objective, x_opt, idx), sampling)
            e = pose_error(Tc, T0)
            d = correction_between(T0, Tc) * TO_REPORT
            rec = dataclasses.replace(
                rec, own_optimum_px=round(px, 3), tolerance_px=round(float(tol), 3),
                agrees=bool(px <= tol), separation_deg=round(float(e["rotation_deg"]), 4),
                separation_m=round(float(e["translation_cm"]), 3) / 100.0,
                d=_rounded_si(d, 4))
        out.append(rec)
    return CameraAgreement(cameras=tuple(out),
                           disagreeing=tuple(r.name for r in out if r.checked and not r.agrees))


def bias_tolerance_px(align_px: float, sampling: np.ndarray | None) -> float:
    """How far, in pixels, a bias that every frame shares may move the LiDAR's edges from the
    image's: the image alignment the result reached, ``align_px``, and no less than half the
    LiDAR's finest sampling step in the image (``min(sampling) / 2``,
    :func:`~paretocal.features.prepare.sampling_px`): an edge lies somewhere between two
    returns and every frame places it by the same rule, so no rig places its edges better
    than half its finest step. The finest, not each direction's own: edges of every
    orientation pin the pose together, and a sparse direction (16 beams, 1.7 deg between
    rings) is crossed by edges the dense one places (a floor per direction judged the KITTI
    drive decimated to 16 beams unreliable although its runs ended 0.3-0.4 deg / 2-5 cm off).

    Parameters
    ----------
    align_px : float
        The image alignment the result reached (px, :func:`alignment_px`).
    sampling : ndarray, shape (2,), optional
        The LiDAR's sampling step in the image along u and v (px); None: unknown (no floor).

    Returns
    -------
    float
        Pixels.
    """
    if sampling is not None and np.all(np.isfinite(sampling)):
        return max(float(align_px), 0.5 * float(np.min(sampling)))
    return float(align_px)


def intervals(jackknife_se: np.ndarray, per_px: np.ndarray, align_px: float,  # noqa: PLR0913
              search: SearchSettings,
              res_per_px: np.ndarray | None = None, *, sampling_px: np.ndarray | None = None,
              bias: np.ndarray | None = None, move: np.ndarray | None = None) -> Intervals:
    """Per-axis 95 % intervals of the correction (computed in report units, cm and deg, and
    held in m and deg as written: :class:`Intervals`).

    Two parts, combined in quadrature: the frames' disagreement, ``Z95`` jackknife standard
    errors (``jackknife_se``); and what no agreement among frames can show, a bias
    they all share (the LiDAR's edges and the image's are not the same lines, a reference or
    intrinsics off by a constant image offset, the LiDAR placing every edge between its
    returns by one rule): the result is taken to be known to within the image alignment it
    reached, ``align_px`` (:func:`alignment_px`, measured at the result), and no better than
    half the LiDAR's finest sampling step in the image (:func:`bias_tolerance_px`), on
    any combination of axes. ``bias`` is that bound per axis (the tolerance times
    ``per_px``, the largest change of that axis among the poses that move the points by a
    pixel rms); without it, ``align_px * per_px``. half = sqrt((Z95 se)^2 + bias^2): about
    the pose they are measured at, the result's local optimum. About the result itself, the
    way to that optimum, ``move``, is added on each axis: half + |move|. An axis whose
    half-width exceeds the stated initial error, or that has no jackknife (one frame), is
    *not determined* by the data.

    Parameters
    ----------
    jackknife_se : ndarray, shape (6,)
        The frames' jackknife standard errors (m and deg;
        :attr:`~paretocal.quality.Quality.jackknife_se`), NaN where there is none.
    per_px : ndarray, shape (6,)
        :func:`pose_per_px` (m and deg per pixel).
    align_px : float
    search : SearchSettings
        Its stated initial error bounds a determined axis.
    res_per_px : ndarray, shape (6,), optional
        :func:`~paretocal.quality.axis_resolution`, reported beside.
    sampling_px : ndarray, shape (2,), optional
        The LiDAR's sampling step in the image (u, v), reported beside.
    bias : ndarray, shape (6,), optional
        The shared bias's bound per axis (m and deg).
    move : ndarray, shape (6,), optional
        The correction from the result to its local optimum (m and deg;
        :attr:`PolishMove.d`); none added when omitted.

    Returns
    -------
    Intervals
        On the correction's axes (the LiDAR frame): ``jackknife_se`` (as used), ``half_width``
        per axis (NaN when not determined), ``determined`` per axis, ``alignment_px``,
        ``sampling_px`` (u, v), ``per_px`` (per pixel rms), ``bias`` and
        ``resolution_per_px`` (per pixel, one axis moved). The true extrinsic lies, per axis,
        within ``T_cam_lidar @ D(d)`` for ``|d_axis| <= half_width``.
    """
    se = np.asarray(jackknife_se, dtype=np.float64) * TO_REPORT
    m = np.asarray(per_px, dtype=np.float64) * TO_REPORT
    b = (align_px * m if bias is None else np.asarray(bias, dtype=np.float64) * TO_REPORT)
    if not np.isfinite(align_px):
        b = np.full(6, np.nan)
    half = np.sqrt((Z95 * se) ** 2 + b ** 2)
    moved = None if move is None else _rounded_si(np.abs(np.asarray(move, float)) * TO_REPORT, 5)
    if moved is not None:
        half = half + np.nan_to_num(moved * TO_REPORT)
    s = search
    limit = np.r_[[100 * s.init_error_m] * 3, [s.init_error_deg] * 3]
    ok = np.isfinite(half) & (half <= limit)
    return Intervals(
        jackknife_se=_rounded_si(se, 5), half_width=_rounded_si(np.where(ok, half, np.nan), 4),
        determined=ok,
        alignment_px=round(float(align_px), 4) if np.isfinite(align_px) else np.nan,
        sampling_px=(None if sampling_px is None else
                     np.array([round(float(v), 3) if np.isfinite(v) else np.nan
                               for v in np.asarray(sampling_px, float)])),
        per_px=_rounded_si(m, 5), bias=_rounded_si(b, 5),
        resolution_per_px=(None if res_per_px is None else
                           _rounded_si(np.asarray(res_per_px, dtype=np.float64) * TO_REPORT, 5)),
        move=moved)


def polish_move(objective, x: np.ndarray, x_opt: np.ndarray, polished: bool) -> PolishMove:
    """What a local polish from the result ``x`` (7,) moves it: the way to its local optimum
    ``x_opt`` (7,) (:func:`~paretocal.quality.local_optimum`, which the evidence computes
    anyway: nothing is evaluated but the displacement).

    Parameters
    ----------
    objective : CalibrationObjective
        The run's objective.
    x : ndarray, shape (7,)
        The result ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
    x_opt : ndarray, shape (7,)
        Its local optimum at every point.
    polished : bool
        Whether the run polished its front.

    Returns
    -------
    PolishMove
    """
    from .quality import correction_between

    T = objective.transforms(np.vstack([x, x_opt]))
    e = pose_error(T[1], T[0])
    return PolishMove(d=_rounded_si(correction_between(T[0], T[1]) * TO_REPORT, 4),
                      separation_deg=round(float(e["rotation_deg"]), 4),
                      separation_m=round(float(e["translation_cm"]), 3) / 100.0,
                      px=round(float(displacement_px(objective, x, x_opt)), 3),
                      polished=bool(polished))


def gather_evidence(objective, settings, n_min: int, n_max: int, x: np.ndarray,
                    sampling: np.ndarray | None = None, cameras: dict | None = None) -> Evidence:
    """Everything :func:`reliability` needs beyond the run itself: the result's local optimum
    and the way to it, the restart(s), the image-cloud agreement and the intervals (see the
    module docstring).
    The intervals use their own jackknife, at the result's local optimum (not the run's
    quality report at the result). ``sampling`` (2,): the LiDAR's sampling step
    in the image, px along u and v (:func:`~paretocal.features.prepare.sampling_px`, the
    median over the frames), which bounds how well any frame can place an edge. ``cameras``
    (a joint calibration of several cameras): as for :func:`camera_evidence`.

    Parameters
    ----------
    objective : CalibrationObjective
        The run's objective.
    settings : Settings
        The run's settings (the search box, the stated initial error, the restarts).
    n_min, n_max : int
        The range of points per frame.
    x : ndarray, shape (7,)
        The result ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
    sampling : ndarray, shape (2,), optional
        The LiDAR's sampling step in the image along u and v (px).
    cameras : dict, optional
        By camera name, ``(frames, sampling)`` (:func:`camera_evidence`).

    Returns
    -------
    Evidence
    """
    restart = None
    if settings.decision.restarts > 0:
        restart = restart_evidence(objective, settings.search, settings.decision, n_min,
                                   n_max, x)
        x_opt = np.asarray(restart.result_optimum)
    else:
        x_opt = local_optimum(objective, x)
    # The frames' disagreement about the optimum, linearised where the objective's gradient
    # vanishes: from the result itself (up to a pixel or two away) each frame's Newton step
    # also carries its Hessian's differences times the remaining gradient.
    at_opt = quality_report(objective, x_opt, pixel_fd_step(objective, x_opt))
    align = alignment_px(objective, x_opt)
    per_px = pose_per_px(objective, x_opt)
    # The intervals are measured at the optimum; the result is where the search stopped.
    move = polish_move(objective, x, x_opt, settings.decision.polish)
    return Evidence(
        contrast=contrast_evidence(objective, settings.search, x_opt),
        start=start_evidence(objective, x_opt),
        intervals=intervals(at_opt.jackknife_se, per_px, align, settings.search,
                            axis_resolution(objective, x_opt), sampling_px=sampling,
                            bias=bias_tolerance_px(align, sampling) * per_px, move=move.d),
        restart=restart, move=move,
        cameras=(camera_evidence(objective, x_opt, cameras)
                 if cameras is not None and len(cameras) > 1 else None))


def _camera_reasons(cameras: "CameraAgreement | None") -> list[str]:
    """A reason for each camera of a joint calibration whose frames alone disagree."""
    if cameras is None:
        return []
    out = []
    for name in cameras.disagreeing:
        c = next(c for c in cameras.cameras if c.name == name)
        out.append(
            f"the cameras disagree: camera {name}'s frames alone prefer a pose "
            f"{c.separation_deg:.2g} deg / {cm_written(c.separation_m, 3):.2g} cm away, moving its "
            f"points {c.own_optimum_px:.2g} px (its edges are trusted to "
            f"{c.tolerance_px:.2g} px): a bias that camera's frames share, or calib.yaml's "
            "camera-to-camera extrinsics are not the rig's; calibrate the cameras one by one "
            "(without --joint) and compare")
    return out


def reliability(result: "CalibrationResult") -> Reliability:
    """A short verdict on whether to trust ``result``, from what the run already computed.

    ``verdict`` is ``"ok"`` or ``"unreliable"`` and ``reasons`` lists what made it
    unreliable: too few frames, few feature points in view at the chosen extrinsic, a
    correction stopped by a search bound (or a local optimum beyond it), or frames that
    disagree (jackknife standard errors, those of the intervals at the result's local optimum
    when the evidence has them), and the evidence's checks. Thresholds: the ``RELIABLE_*``
    constants.

    Parameters
    ----------
    result : CalibrationResult
        The run, with its evidence (:func:`gather_evidence`) when gathered.

    Returns
    -------
    Reliability
    """
    reasons = []
    n_frames = len(result.frames)
    # Frames passed are not frames that count: one with no feature points in view adds none.
    counts: FeatureCounts | None = result.feature_counts
    useful = n_frames if counts is None else counts.frames_contributing
    if n_frames < RELIABLE_MIN_FRAMES:
        reasons.append(f"only {n_frames} frame(s): too few to average out one scene's biases "
                       f"(use at least {RELIABLE_MIN_FRAMES})")
    elif useful < RELIABLE_MIN_FRAMES:
        reasons.append(f"only {useful} of the {n_frames} frames have LiDAR feature points in "
                       f"view (at least {MIN_POINTS_PER_FRAME} each): too few to average out "
                       f"one scene's biases; use at least {RELIABLE_MIN_FRAMES} frames whose "
                       "clouds and images overlap")
    in_view = result.objectives().get("in_view")
    if in_view is not None and in_view < RELIABLE_MIN_IN_VIEW:
        reasons.append(f"only {100 * in_view:.0f} % of the feature points project into the "
                       f"image at the chosen extrinsic (below {100 * RELIABLE_MIN_IN_VIEW:.0f} %)")
    wide = getattr(result, "wide", None)
    if wide is not None and wide.ambiguity:
        reasons.append(wide.ambiguity)
    s = result.settings.search
    bound = np.r_[[s.bound_t] * 3, [s.bound_r] * 3]
    x = np.asarray(result.front.X[result.chosen, :6], dtype=np.float64)
    at_bound = [a for a, v, b in zip(AXES, x, bound)
                if abs(v) >= (1.0 - RELIABLE_BOUND_MARGIN) * b]
    if at_bound:
        reasons.append(f"the correction sits at the search bound on {', '.join(at_bound)} "
                       f"(+-{s.bound_t:g} m, +-{s.bound_r:g} deg): the optimum may lie "
                       "outside; if the initial extrinsic may be further off, say so with "
                       "--init-error, or improve --init")
    err = np.r_[[s.init_error_m] * 3, [s.init_error_deg] * 3]
    beyond = [a for a, v, e in zip(AXES, x, err) if abs(v) > e and a not in at_bound]
    if beyond:
        beyond_units = ["cm" if a in ("x", "y", "z") else "deg" for a in beyond]
        scale = [100.0 if u == "cm" else 1.0 for u in beyond_units]
        moved = ", ".join(f"{a} {abs(x[AXES.index(a)]) * k:.3g} {u}"
                          for a, u, k in zip(beyond, beyond_units, scale))
        reasons.append(f"the correction lies beyond the stated initial error ({moved}; "
                       f"--init-error {s.init_error_deg:g},{s.init_error_m:g}): either the "
                       "start was worse than stated (say so with --init-error) or the frames "
                       "mislead the objective; check the overlays")
    q = result.quality
    if q is not None:
        target = x + q.step_to_local_optimum
        beyond = [a for a, t, b, v in zip(AXES, target, bound, x)
                  if abs(t) > b and a not in at_bound]
        if beyond:
            reasons.append(f"the objective still falls beyond the search bound on "
                           f"{', '.join(beyond)}: the optimum lies outside the box; widen "
                           "--bound-t / --bound-r")
    basin = None if result.decision is None else result.decision.basin
    if basin is not None and basin.ambiguous:
        alt = f"{basin.separation_deg:.2g} deg / {cm_written(basin.separation_m, 3):.2g} cm"
        p = _nan(basin.p) if basin.kept == "far" else 1.0 - _nan(basin.p)
        near_kept = basin.kept == "near"
        where = ("the result is the optimum next to the initial extrinsic, the other lies "
                 "beyond the stated --init-error" if near_kept else
                 "the result is the one that fits better")
        # A smaller stated error helps only when the result kept is the far pose: the near
        # one is the start's own, and a narrower box would keep it.
        narrower = ("" if near_kept else
                    ", or state a smaller --init-error if the start is known to be close")
        reasons.append(
            f"ambiguous: a pose {alt} away fits the frames about as well (paired test over "
            f"{basin.frames} frames: p = {p:.2g}); {where}; add frames with more varied "
            f"structure{narrower}")
    mo = result.motion
    if (mo is not None and not mo.compensated and mo.skew_m is not None
            and mo.skew_m > MAX_UNCOMPENSATED_SKEW_M):
        reasons.append(f"the LiDAR moved {mo.skew_m:.2g} m during a sweep and the motion "
                       f"could not be compensated ({mo.reason}): moving structure is "
                       "misplaced by up to half that")
    rings = None if counts is None else counts.ring_recovery
    if rings is not None and rings.min_purity < MIN_PURITY:
        reasons.append(f"the LiDAR's laser rings could not be recovered reliably (purity "
                       f"{rings.min_purity:.2f}): depth edges are noise; give the ring "
                       "field or the LiDAR's pose (lidar_pose) in calib.yaml")
    ev: Evidence = getattr(result, "evidence", None) or Evidence()
    # The frames' agreement as the intervals measure it, at the result's local optimum: at the
    # result itself, a pixel or two away along the objective's flattest direction, each
    # frame's gradient also carries its Hessian's difference from the mean times that offset
    # (z 13.6 cm for a KITTI result 2.2 cm off). The quality report's without the evidence.
    iv = ev.intervals
    own = {} if q is None else dict(zip(AXES, q.jackknife_se * TO_REPORT))
    se = {a: v for a, v in (own if iv is None else iv.jackknife_se_report()).items()
          if v is not None}
    units = dict(zip(AXES, UNITS))
    se_deg = max([v for a, v in se.items() if units.get(a) == "deg" and np.isfinite(v)],
                 default=None)
    se_cm = max([v for a, v in se.items() if units.get(a) == "cm" and np.isfinite(v)],
                default=None)
    loose = [f"{a} {v:.3g} {units[a]}" for a, v in se.items() if np.isfinite(v) and (
        (units.get(a) == "deg" and v > RELIABLE_MAX_SE_DEG)
        or (units.get(a) == "cm" and v > RELIABLE_MAX_SE_CM))]
    if loose:
        reasons.append(f"the frames disagree: jackknife standard error {', '.join(loose)} "
                       f"(limits {RELIABLE_MAX_SE_DEG:g} deg, {RELIABLE_MAX_SE_CM:g} cm)")
    rs = ev.restart
    if rs is not None and rs.disagrees:
        r = next(r for r in rs.runs if r.distinct)
        how = ("fits the frames better" if r.mean_px > 0 else
               "fits the frames about as well")
        reasons.append(f"an independent restart of the search ended {r.separation_deg:.2g} deg"
                       f" / {cm_written(r.separation_m, 3):.2g} cm away and {how} "
                       f"({r.frames_restart_better} of {r.frames} frames prefer it): the frames "
                       "do not single out one pose; add frames with more varied structure "
                       "(buildings, poles, cars at several distances)"
                       + _narrower_advice(x, r.correction, s.init_error_deg,
                                          s.init_error_m))
    reasons += _camera_reasons(ev.cameras)
    short = _short_of_optimum(ev)
    if short:
        reasons.append(short)
    reasons += _cross_reasons(ev.motion, None if wide is None else wide.photo, n_frames)
    board = getattr(result, "board", None)
    if board is not None:
        reasons += board.verdict_reasons()
    ct = ev.contrast
    # A z that is not a number (random poses that all score alike: no spread to compare
    # with) is no evidence of agreement either.
    weak_z = ct is not None and not ct.z >= CONTRAST_MIN_Z
    if ct is not None and (weak_z or ct.frames_clear < CONTRAST_MIN_FRAMES_CLEAR):
        what = ("every random pose within the stated initial error scores alike: the "
                "objective finds nothing in the images to align" if not np.isfinite(ct.z) else
                f"the result fits the image edges only {ct.z:.2g} spreads better than random "
                f"poses within the stated initial error (at least {CONTRAST_MIN_Z:g} expected)"
                if weak_z else
                f"in only {100 * ct.frames_clear:.0f} % of the frames does the result fit "
                "the image edges better than 95 % of random poses within the stated initial "
                f"error (at least {100 * CONTRAST_MIN_FRAMES_CLEAR:.0f} % expected)")
        reasons.append(f"images and clouds barely agree: {what}; check that each image "
                       "belongs to its cloud (same time, same camera), the intrinsics, and "
                       "that the scenes have edges both sensors see")
    if iv is not None and not reasons:
        wide = _imprecise(iv, board is not None)
        if wide:
            reasons.append(wide)
    few = _few_edges(counts)
    if reasons and few:
        reasons.append(few)
    # Intervals hold only where nothing else casts doubt on the result (Reliability.intervals):
    # a wrong basin, frames that disagree or a result at a bound are all errors the intervals
    # do not measure.
    return Reliability(
        verdict="unreliable" if reasons else "ok", reasons=tuple(reasons),
        evidence=getattr(result, "evidence", None), frames=n_frames,
        in_view=np.nan if in_view is None else round(float(in_view), 4),
        at_bound=tuple(at_bound),
        max_jackknife_se_deg=np.nan if se_deg is None else round(float(se_deg), 4),
        max_jackknife_se_m=np.nan if se_cm is None else round(float(se_cm), 3) / 100.0)


def _cross_reasons(mc: MotionAgreement | None, photo, n_frames: int) -> list[str]:
    """The verdict's reasons from evidence that shares nothing with the edges: the
    recording's motion (a rig standing still, a rotation the motion contradicts) and
    photo-consistency (a :class:`~paretocal.wide.PhotoCheck` after a wide start)."""
    reasons = []
    if photo is not None and not photo.agree:
        reasons.append(
            f"photo-consistency disagrees: the images agree clearly better at a pose "
            f"{photo.separation_deg:.1f} deg / {100 * (photo.separation_m or 0.0):.0f} cm from "
            f"the result (cost {photo.rival:.3f} against {photo.result:.3f}), a basin the edges "
            "missed or were fooled out of; give a better start, or frames with structure at "
            "several distances")
    if mc is not None and mc.standing and n_frames >= RELIABLE_MIN_FRAMES:
        reasons.append(f"{mc.one_view(n_frames)} do not average out however many frames "
                       "there are; add frames taken at other places (while driving)")
    if mc is not None and not mc.agree:
        reasons.append(
            f"the motion disagrees: the directions of travel both sensors see put the camera's "
            f"rotation {mc.change_deg:.2g} deg from the result's (they agree to "
            f"{mc.tolerance_deg:.2g} deg over {mc.directions + mc.turns} directions of travel "
            "and turns): the frames' "
            "edges all favour a wrong pose; give a better start, or frames with structure at "
            "several distances")
    return reasons


def _short_of_optimum(ev: Evidence) -> str | None:
    """The reason to distrust a result that a local polish moves beyond the intervals the data
    give about its local optimum (:meth:`Intervals.beyond_optimum`): the search stopped short
    of where the frames put it, so their agreement (the jackknife, the intervals) describes
    another pose. None otherwise."""
    iv, mv = ev.intervals, ev.move
    if iv is None or mv is None:
        return None
    beyond = iv.beyond_optimum()
    if not beyond:
        return None
    units = dict(zip(AXES, UNITS))
    axes = ", ".join(f"{a} {m:.2g} {units[a]} against +-{h:.2g}" for a, (m, h) in beyond.items())
    todo = ("run again with the polish (without --no-polish) or a longer search (larger --pop "
            "and --gens)" if not mv.polished else
            "run again with a longer search (larger --pop and --gens)")
    return (f"the search stopped short of the objective's optimum: a local polish from the "
            f"result moves it {mv.separation_deg:.2g} deg / {cm_written(mv.separation_m, 3):.2g}"
            f" cm ({mv.px:.2g} px), beyond the 95 % intervals the frames give about that "
            f"optimum ({axes}); {todo}")


def _narrower_advice(x: np.ndarray, rival: np.ndarray, init_error_deg: float,
                     init_error_m: float) -> str:
    """Advice to state a smaller initial error, when the evidence says it would help: the
    rival pose ``rival`` (6,) lies farther from the start than the result ``x`` (6,), in units
    of the stated error (:func:`~paretocal.search.basin.departure`), so a box that keeps the
    result can leave the rival out. Empty otherwise (a start inside the stated error is not
    told to change it)."""
    rival = np.asarray(rival, dtype=np.float64)[:6]
    if not np.all(np.isfinite(rival)):
        return ""
    d_x = departure(x, init_error_deg, init_error_m)
    d_r = departure(rival, init_error_deg, init_error_m)
    scale = math.sqrt(max(d_x, 1e-3) * d_r)          # between the two, geometrically
    if d_r <= d_x or scale >= 1.0:
        return ""
    return (f", or, if the start is known to be that close, state a smaller initial error "
            f"(--init-error {scale * init_error_deg:.2g},{scale * init_error_m:.2g} keeps the "
            "result inside the search box and the other pose outside)")


def _few_edges(feature_counts: FeatureCounts | None) -> str | None:
    """The frames whose scenes give the objective (almost) no edge to align: fewer than
    :data:`MIN_POINTS_PER_FRAME` LiDAR edge points (depth and intensity edges) in view. A
    reason to add to an unreliable verdict (alone, such frames only add nothing); None when
    every frame has edges."""
    per = () if feature_counts is None else feature_counts.per_frame
    few = [p.frame for p in per if p.edges < MIN_POINTS_PER_FRAME]
    if not few:
        return None
    more = f" and {len(few) - 3} more" if len(few) > 3 else ""
    return (f"few edges: {len(few)} of {len(per)} frames ({', '.join(map(str, few[:3]))}{more}) "
            f"have fewer than {MIN_POINTS_PER_FRAME} LiDAR edge points in view (depth or "
            "intensity edges): open road, sky or bare walls give the objective nothing to "
            "align; add frames with structure both sensors see (poles, building corners, "
            "parked cars)")


def _imprecise(iv: Intervals, board: bool = False) -> str | None:
    """The reason to distrust a result whose intervals are wider than a usable calibration
    allows (:data:`RELIABLE_MAX_HALF_CM`, :data:`RELIABLE_MAX_HALF_DEG`), or None; ``board``:
    the advice is a board recording's (:data:`paretocal.board.RECORD_ADVICE`)."""
    limit = {"cm": RELIABLE_MAX_HALF_CM, "deg": RELIABLE_MAX_HALF_DEG}
    units = dict(zip(AXES, UNITS))
    wide = [f"{a} +-{h:.2g} {units[a]}" for a, h in iv.half_width_report().items()
            if h is not None and h > limit[units[a]]]
    loose = wide + [f"{a} not at all" for a in iv.undetermined]
    if not loose:
        return None
    why = ""
    samp, align = iv.sampling_px, iv.alignment_px
    if (samp is not None and len(samp) and np.isfinite(align) and np.all(np.isfinite(samp))
            and 0.5 * min(samp) > align):
        why = (f"; the LiDAR samples this camera's view coarsely (neighbouring returns "
               f"{samp[0]:.2g} px apart along a ring and {samp[1]:.2g} px between rings), so "
               "no frame places an edge closer than half that")
    if board:
        from .board import RECORD_ADVICE

        advice = RECORD_ADVICE
    else:
        advice = ("add frames with structure near the rig and across the whole image (poles, "
                  "building corners, cars at several distances)")
    return (f"the data fix the result only to {', '.join(loose)} (95 %; a usable calibration "
            f"needs {RELIABLE_MAX_HALF_CM:g} cm and {RELIABLE_MAX_HALF_DEG:g} deg){why}: "
            f"{advice}, or keep the start if it was measured better")


def verdict_text(rel: Reliability) -> str:
    """The verdict of :func:`reliability` in one line for a person: ``"OK: ..."`` or
    ``"UNRELIABLE: <main reason> (and N more reasons in result.json)"``.

    Parameters
    ----------
    rel : Reliability
        The verdict.

    Returns
    -------
    str
    """
    reasons = rel.reasons
    if rel.ok or not reasons:
        mv = None if rel.evidence is None else rel.evidence.move
        # A run that did not polish says how far the polish would have moved the result.
        unpolished = ("" if mv is None or mv.polished else
                      f"; not polished: a local polish moves it {mv.separation_deg:.2g} deg / "
                      f"{cm_written(mv.separation_m, 3):.2g} cm, within the intervals")
        return (f"OK: nothing the run measured casts doubt on the result ({rel.frames} "
                f"frames{unpolished})")
    more = (f" (and {len(reasons) - 1} more reason{'s' if len(reasons) > 2 else ''} in "
            "result.json)" if len(reasons) > 1 else "")
    start = "" if rel.start is None else f"; {start_text(rel.start)}"
    return f"UNRELIABLE: {reasons[0]}{more}{start}"


def interval_text(rel: Reliability | None) -> str | None:
    """The per-axis 95 % intervals of :func:`reliability` in one line, or None without them
    (none, or a result judged unreliable):
    ``"x +-1.2 cm, ..., roll +-0.3 deg; not determined by the data: z"``.

    Parameters
    ----------
    rel : Reliability or None
        The verdict.

    Returns
    -------
    str or None
    """
    iv = None if rel is None else rel.intervals
    if iv is None:
        return None
    units = dict(zip(AXES, UNITS))
    parts = [f"{a} +-{h:.2g} {units[a]}" for a, h in iv.half_width_report().items()
             if h is not None]
    text = ", ".join(parts) if parts else "no axis"
    if iv.undetermined:
        text += "; not determined by the data: " + ", ".join(iv.undetermined)
    return text
