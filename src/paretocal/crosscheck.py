"""The motion a recording contains, and what it says about a result.

A rig that moves shows its motion to both sensors: the LiDAR's odometry and the camera's visual
odometry see the same trip, and the camera's direction of travel is the LiDAR's turned by the
extrinsic's rotation, whatever the translation and whatever the scene's edges
(:func:`paretocal.egomotion.rotation_from_motion`). That is evidence which shares nothing with
the edge objective, so it catches what every frame's edges agree on and the other checks cannot
see (the restart finds the same wrong optimum, the jackknife's frames all lean the same way):

* :func:`recording_motion` measures the motion of both sensors once per run (the wide start
  and the verdict read the same);
* :func:`motion_agreement` compares a result's rotation with the one the motion gives, about
  the axes the motion observes (two on a straight drive, three when it turns), against the
  tolerance the motion's own pairs support (:func:`motion_tolerance_deg`);
* a rig that stands still over its frames shows one view however many frames it records: the
  check says so, and the verdict does not count such frames as independent scenes.

Both need at least :data:`MIN_FRAMES` frames of one camera (a joint calibration of several
cameras is checked camera by camera, by each camera's own run).
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .egomotion import (LidarOdometry, camera_odometry, image_features,
                        lidar_odometry, rotation_from_motion)
from .io.frame import Frame
from .search.basin import USABLE_M

#: Points per sweep of the LiDAR odometry: directions of travel need no more (the
#: calibration's own ICP default is for de-skewing), and no fewer: with 4,000 the motion's
#: rotation on the KITTI drive decimated to 16 beams lay 1.13 deg from the reference (0.17
#: with 8,000, 0.18 with 12,000), and the wide start found the truth from 8 of 10 starts
#: instead of 10 (its photo map is placed by these poses).
ODOMETRY_POINTS = 8000
#: Fewest frames: odometry needs pairs, and the direction of travel a baseline.
MIN_FRAMES = 3
#: The camera pairs compared: each frame with the first one far enough for this share of
#: the image width in parallax at the scene's median range (about 4 m, 10 frames, on the
#: KITTI drive: the direction of travel from pairs 4 frames apart agreed 1.3 deg RMS, from
#: 10 apart 0.6 deg) ...
PARALLAX_SHARE = 0.25
#: ... and the least travel over the whole recording that gives a direction at all; a rig that
#: travels less shows the scene from one place.
MIN_PARALLAX_SHARE = 0.05
#: How far the motion's rotation may be from the truth: this many times the pairs' RMS
#: disagreement with the fit, at least :data:`MIN_BAND_DEG` (the disagreement of one pair
#: bounds what the fit of several can be off by; KITTI: 0.6 deg with pairs 10 frames apart,
#: 1.3 deg with 4; the motion's rotation lay 0.17-0.66 deg from the reference on the KITTI
#: drive with 64 and 16 beams).
BAND_RESIDUALS = 2.0
MIN_BAND_DEG = 1.5
#: Fewest vectors (directions of travel and turn axes) for a check: with fewer, their RMS
#: disagreement with the fit measures nothing (one vector fits itself exactly).
MIN_VECTORS = 3


def baseline_m(width: int, focal_px: float, median_range_m: float, share: float) -> float:
    """The baseline (m) that shows ``share`` of the image width in parallax at the scene's
    median range."""
    return share * width * median_range_m / focal_px


def camera_pairs(lidar_steps_m: np.ndarray, baseline: float,
                 min_baseline: float) -> list[tuple[int, int]]:
    """Image pairs a baseline apart.

    Parameters
    ----------
    lidar_steps_m : ndarray, shape (K-1,)
        The LiDAR's travel between consecutive frames (m; 0 for a standing pair, NaN unknown).
    baseline, min_baseline : float
        The travel (m) a pair should span, and the least it may.

    Returns
    -------
    list of (int, int)
        Each frame with the first later one ``baseline`` of travel away; when the whole
        recording travels less, each frame at least ``min_baseline`` from the last one with
        the last one.
    """
    cum = np.r_[0.0, np.cumsum(np.nan_to_num(np.asarray(lidar_steps_m, dtype=np.float64)))]
    K = len(cum)
    pairs = []
    for i in range(K - 1):
        j = int(np.searchsorted(cum, cum[i] + baseline, side="left"))
        if j < K:
            pairs.append((i, j))
    if not pairs:
        pairs = [(i, K - 1) for i in range(K - 1) if cum[-1] - cum[i] >= min_baseline]
    return pairs


def motion_tolerance_deg(residual_deg: float) -> float:
    """How far the motion's rotation may lie from the truth (deg), from its pairs' RMS
    disagreement with the fit (:data:`BAND_RESIDUALS`, :data:`MIN_BAND_DEG`)."""
    r = residual_deg if np.isfinite(residual_deg) else 0.0
    return float(max(BAND_RESIDUALS * r, MIN_BAND_DEG))


@dataclass
class RecordingMotion:
    """The motion of both sensors over a recording (:func:`recording_motion`).

    Attributes
    ----------
    lidar : LidarOdometry
        The LiDAR's odometry over every frame.
    pairs : list of (int, int)
        The camera pairs compared (frame indices); empty when the rig barely moves.
    camera : list of CameraPair
        The camera's motion over each pair.
    travel_m : float
        The LiDAR's travel over the frames (m; the pairs it resolves from standing).
    need_m : float
        The least travel that gives a direction (m; :data:`MIN_PARALLAX_SHARE` of the image's
        width in parallax at the scene's median range).
    range_m : float
        The first sweep's median range (m).
    failed : int
        Consecutive pairs whose registration failed.
    seconds : float
        Wall time (s).
    camera_measured : bool
        Whether the camera's motion was measured (False: the LiDAR's alone, which tells a rig
        standing still but gives no rotation to compare with).
    """

    lidar: LidarOdometry
    pairs: list = field(default_factory=list)
    camera: list = field(default_factory=list)
    travel_m: float = 0.0
    need_m: float = 0.0
    range_m: float = 0.0
    failed: int = 0
    seconds: float = 0.0
    camera_measured: bool = True

    @property
    def moves(self) -> bool:
        """The rig travels far enough for a direction of travel."""
        return self.travel_m >= self.need_m

    @property
    def standing(self) -> bool:
        """The rig stands still over the frames: most pairs registered, and together they
        travel less than :attr:`need_m`."""
        return not self.moves and 2 * self.failed < len(self.lidar.pair_poses)

    @property
    def still_text(self) -> str:
        """Why the motion gives no direction, in words ("" when the rig moves)."""
        if self.moves:
            return ""
        if not self.standing:
            return (f"the LiDAR's odometry failed on {self.failed} of "
                    f"{len(self.lidar.pair_poses)} pairs of consecutive frames")
        return (f"the rig barely moves: the LiDAR travels {self.travel_m:.2f} m over the "
                f"frames, and a direction of travel needs about {self.need_m:.1f} m "
                f"({100 * MIN_PARALLAX_SHARE:.0f} % of the image's width in parallax at the "
                f"scene's median range, {self.range_m:.0f} m)")


def _steps_m(lo: LidarOdometry) -> np.ndarray:
    """The LiDAR's travel between consecutive frames (K-1,), m: 0 for a standing pair, NaN
    for a failed one."""
    return np.where(lo.standing, 0.0, lo.translation_m)


def recording_motion(frames: list[Frame], seed: int = 0, *,
                     points: int = ODOMETRY_POINTS, camera: bool = True) -> RecordingMotion:
    """The motion of the LiDAR and of the camera over ``frames``.

    Parameters
    ----------
    frames : list of Frame
        At least :data:`MIN_FRAMES` frames of one camera, in time order, after the LiDAR
        steps (located, de-skewed).
    seed : int
        Seeds the odometry's subsampling and the visual odometry's bootstrap.
    points : int
        Points per sweep of the LiDAR's odometry.
    camera : bool
        Measure the camera's motion too (False: the LiDAR's alone, about half the time on the
        KITTI drive, 1.5 of 2.9 s, enough to tell a rig standing still).

    Returns
    -------
    RecordingMotion
        Without camera pairs when the rig barely moves or ``camera`` is False.
    """
    if len(frames) < MIN_FRAMES:
        raise ValueError(f"recording_motion needs at least {MIN_FRAMES} frames, "
                         f"got {len(frames)}")
    t0 = time.perf_counter()
    clouds = [f.points[:, :3] for f in frames]
    cam = frames[0].camera
    images = [f.image for f in frames]
    rng_m = float(np.median(np.linalg.norm(clouds[0], axis=1)))
    focal = float(cam.K[0, 0])

    def lidar() -> RecordingMotion:
        lo = lidar_odometry(clouds, points=points, seed=seed)
        return RecordingMotion(lo, travel_m=float(np.nansum(_steps_m(lo))),
                               need_m=baseline_m(cam.width, focal, rng_m, MIN_PARALLAX_SHARE),
                               range_m=rng_m, failed=int(np.sum(~np.isfinite(lo.translation_m))),
                               camera_measured=camera)

    if not camera:
        out = lidar()
        out.seconds = time.perf_counter() - t0
        return out
    # The images' features do not depend on the LiDAR's odometry: extracted beside it
    # (OpenCV and the registration's numpy and scipy work release the interpreter), and
    # stopped once the LiDAR shows a rig standing still, which needs none of them.
    stop = threading.Event()
    with ThreadPoolExecutor(max_workers=1) as pool:
        pending = pool.submit(image_features, images, cam, stop=stop)
        out = lidar()
        if not out.moves:
            stop.set()
        feats = pending.result()
    if out.moves:
        out.pairs = camera_pairs(_steps_m(out.lidar),
                                 baseline_m(cam.width, focal, rng_m, PARALLAX_SHARE), out.need_m)
        out.camera = camera_odometry(images, cam, pairs=out.pairs, bootstrap=20, seed=seed,
                                     image_feats=feats)
    out.seconds = time.perf_counter() - t0
    return out


@dataclass(frozen=True)
class MotionAgreement:
    """Whether a result's rotation agrees with the motion both sensors see
    (:func:`motion_agreement`).

    Attributes
    ----------
    applied : bool
        The motion gave a rotation to compare with.
    reason : str
        Why not, in words ("" when applied).
    standing : bool
        The rig stands still over the frames: they show one view.
    travel_m, need_m : float
        The LiDAR's travel over the frames and the least that gives a direction (m).
    directions, turns : int
        Directions of travel and turn axes the motion's rotation was fitted to.
    residual_deg : float
        Their RMS disagreement with the fit (deg; NaN when not applied).
    change_deg : float
        The angle between the motion's rotation and the result's about the axes the motion
        observes (deg; NaN when not applied).
    tolerance_deg : float
        How far apart they may be (:func:`motion_tolerance_deg`; NaN when not applied).
    seconds : float
        Wall time of the motion (s).
    """

    applied: bool
    reason: str = ""
    standing: bool = False
    travel_m: float = np.nan
    need_m: float = np.nan
    directions: int = 0
    turns: int = 0
    residual_deg: float = np.nan
    change_deg: float = np.nan
    tolerance_deg: float = np.nan
    seconds: float = 0.0

    @property
    def agree(self) -> bool:
        """Not applied, or within the tolerance."""
        return not self.applied or bool(self.change_deg <= self.tolerance_deg)

    @property
    def spread_deg(self) -> float:
        """How far :attr:`change_deg` itself may be off from the vectors' own scatter (95 %,
        deg; NaN when not applied): each of the k vectors (directions of travel, turn axes)
        disagrees with the fit by :attr:`residual_deg` RMS over its two components, so each
        axis the fit observes (two on a straight drive, three with turns: p) is known to
        ``residual / sqrt(2 k - p)``, and the angle over those axes to ``sqrt(chi2_p(0.95))``
        times that. Three directions that disagree by 0.56 deg: +-0.68 deg; nine by 0.62 deg:
        +-0.38 deg (the KITTI drive, 5 and 20 frames)."""
        from scipy.stats import chi2

        k, p = self.directions + self.turns, 3 if self.turns else 2
        if not self.applied or 2 * k <= p or not np.isfinite(self.residual_deg):
            return float("nan")
        return float(np.sqrt(chi2.ppf(0.95, p)) * self.residual_deg / np.sqrt(2 * k - p))

    def one_view(self, n_frames: int) -> str:
        """The standing rig in words, for a verdict or a check to say what follows from it:
        "the rig stands still over the N frames (...): they show the scene from one place,
        whose biases"."""
        return (f"the rig stands still over the {n_frames} frames (the LiDAR travels "
                f"{self.travel_m:.2g} m; the view changes with about {self.need_m:.2g} m): "
                "they show the scene from one place, whose biases")

    def to_dict(self) -> dict[str, Any]:
        """As ``result.json`` writes it (m, deg, s; unknown values null)."""
        def num(v: float, digits: int) -> float | None:
            return round(float(v), digits) if np.isfinite(v) else None

        return {"applied": self.applied, "agree": self.agree, "reason": self.reason,
                "standing": self.standing, "travel_m": num(self.travel_m, 3),
                "need_m": num(self.need_m, 3), "directions": self.directions,
                "turns": self.turns, "residual_deg": num(self.residual_deg, 3),
                "change_deg": num(self.change_deg, 3),
                "tolerance_deg": num(self.tolerance_deg, 3), "seconds": num(self.seconds, 3)}

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "MotionAgreement":
        """Read back from :meth:`to_dict`'s form.

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form.
        """
        def num(key: str) -> float:
            v = doc.get(key)
            return np.nan if v is None else float(v)

        return cls(applied=bool(doc.get("applied")), reason=str(doc.get("reason", "")),
                   standing=bool(doc.get("standing")), travel_m=num("travel_m"),
                   need_m=num("need_m"), directions=int(doc.get("directions", 0)),
                   turns=int(doc.get("turns", 0)), residual_deg=num("residual_deg"),
                   change_deg=num("change_deg"), tolerance_deg=num("tolerance_deg"),
                   seconds=float(doc.get("seconds") or 0.0))


def motion_agreement(motion: RecordingMotion, T_result: np.ndarray) -> MotionAgreement:
    """Compare ``T_result``'s rotation with the one the recording's motion gives.

    The motion's rotation is fitted with the result as its prior (which only fills the angle
    the motion leaves open, and its translation the lever arm of the turns, known to
    :data:`~paretocal.search.basin.USABLE_M`); the angle between the two rotations about the
    axes the motion observes is compared with :func:`motion_tolerance_deg` of the pairs' RMS
    disagreement. Needs :data:`MIN_VECTORS` vectors.

    Parameters
    ----------
    motion : RecordingMotion
    T_result : ndarray, shape (4, 4)
        The result (``T_cam_lidar``).

    Returns
    -------
    MotionAgreement
    """
    T = np.asarray(T_result, dtype=np.float64)
    seen = MotionAgreement(False, travel_m=motion.travel_m, need_m=motion.need_m,
                           seconds=motion.seconds)
    if not motion.moves:
        return replace(seen, reason=motion.still_text, standing=motion.standing)
    if not motion.camera_measured:
        return replace(seen, reason="the rig moves, but only the LiDAR's motion was measured "
                                    "(a result other checks flag already is only looked at "
                                    "for a rig standing still)")
    mr = rotation_from_motion(motion.lidar, motion.camera, T[:3, :3], T[:3, 3],
                              t_sigma_m=USABLE_M)
    seen = replace(seen, directions=mr.directions, turns=mr.turns)
    vectors = mr.directions + mr.turns
    if vectors < MIN_VECTORS:
        return replace(seen, reason=f"the motion gives {vectors} direction(s) of travel or "
                                    f"turn(s) both sensors resolve (of {len(motion.pairs)} "
                                    f"camera pairs); a check needs {MIN_VECTORS}")
    from scipy.spatial.transform import Rotation

    rv = Rotation.from_matrix(mr.R @ T[:3, :3].T).as_rotvec()
    if mr.free_axis is not None:                  # the motion leaves that angle to the prior
        a = np.asarray(mr.free_axis, dtype=np.float64)
        rv = rv - (rv @ a) * a
    return replace(seen, applied=True, residual_deg=float(mr.residual_deg),
                   change_deg=float(np.degrees(np.linalg.norm(rv))),
                   tolerance_deg=motion_tolerance_deg(mr.residual_deg))

__all__ = ["MIN_FRAMES", "MotionAgreement", "RecordingMotion",
           "baseline_m", "camera_pairs", "motion_agreement", "motion_tolerance_deg",
           "recording_motion"]
