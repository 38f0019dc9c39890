"""Ego-motion of both sensors from a sequence of frames: LiDAR odometry, camera visual odometry,
and standstill, each pair with its uncertainty.

What it is for
--------------
A rig that moves gives two independent views of one motion. The LiDAR's relative pose between
consecutive sweeps (``T_k <- k+1``) and the camera's relative rotation and direction of travel
are related by the extrinsic ``X = T_cam_lidar``: the camera moves by ``X T X^-1``. The direction
of travel fixes two rotation angles of ``X`` without any image-to-cloud matching. Pairs taken
while standing give no direction; they are detected here and said so in words.

Conventions
-----------
* A LiDAR *pair pose* ``T_k <- k+1`` (4x4) maps coordinates in sweep ``k+1``'s frame into sweep
  ``k``'s frame: it is the pose of the later frame in the earlier one, its translation the
  displacement of the sensor's (cloud's) origin in metres.
* A camera pair gives ``R_c1_c2`` (the rotation of the later camera in the earlier camera's
  frame) and ``direction``: the unit vector from the earlier camera centre towards the later one,
  in the earlier camera's frame (x right, y down, z forward). OpenCV's ``recoverPose`` returns
  ``x2 = R x1 + t``; then ``R_c1_c2 = R^T`` and ``direction = -R^T t / |t|``.
* Covariances are 6x6, translation first (m^2), then rotation (rad^2), for a left perturbation in
  the earlier frame.

LiDAR odometry
--------------
Two registrations are available. ``"own"`` is :func:`paretocal.lidar.registration.register_pair` (the robust
point-to-plane ICP of :mod:`paretocal.lidar.registration`), scan to scan, each pair started from the
previous pair's motion. ``"kiss-icp"`` is the optional KISS-ICP package (scan to local map,
constant-velocity prediction, adaptive threshold); only its poses are used, never its de-skew
(it ends at the sweep's end, not the image time). For both, each pair's covariance is evaluated
by the own registration at the pair's pose: the cluster-robust sandwich over 4 m blocks of
correspondences (:class:`paretocal.lidar.registration.PairRegistration`).

Measured (``benchmarks/egomotion.py``, 2 shared cores): the own registration is the default.
On the KITTI drive its pair translations run smoothly from 0.236 to 0.196 m per 0.1 s while
KISS-ICP's (1 m voxel, scan to map) jump between 0.100 and 0.280 m; over the ten 10-frame
pairs the camera's direction of travel agrees with the own LiDAR odometry's within
0.12-1.23 deg (median 0.68), with KISS-ICP's within 0.37-1.73 (median 0.74), and the relative
rotations within 0.085 deg median against 0.134. On the aiMotive motorway both give 4.00-4.06 m
per 0.133 s pair (README speed: 4.03 m) and lie 2.2 cm apart (median). KISS-ICP is 2-10 times
faster per pair (0.16-0.43 s against 0.5-1.6 s); it stays an evaluator for the own poses.

Standstill
----------
A LiDAR pair is *standing* when its translation is not significantly different from zero under
its own covariance: ``t^T S^-1 t`` below the chi-square quantile with 3 degrees of freedom at
``significance`` (16.3 at 0.1 %). A camera pair gives no direction when the parallax left after
removing its rotation is not above the matching noise: with pure noise and no translation the
median de-rotated parallax is about 1.7 times the median epipolar residual (a 2-D Rayleigh median
against a 1-D half-normal one), so ``min_parallax_ratio = 3`` asks for parallax clearly above it;
or when fewer than ``min_inliers`` matches support the essential matrix, or when the
bootstrap spread of the direction exceeds ``max_direction_sigma_deg``. A pair without parallax
still gives its rotation, from a robust rotation-only fit of the matched rays.

The two tests answer different questions, and on PandaSet's "standing" frames 00-24 they
differ: its clouds are motion-compensated with the dataset's own poses, so the LiDAR resolves
the car's creep (0.3-6.5 cm per 0.2 s pair, with sub-millimetre standard deviations) and
does not call those pairs standing, while the camera resolves no direction in any of them
(too little parallax, or a bootstrap spread of 15-43 deg). A direction of travel is given
only where both sensors give one (:func:`compare_motion`).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.stats import chi2

from .camera import Camera
from .lidar.registration import (MIN_POINTS, prepare_cloud, register_pair,
                                 register_prepared)

log = logging.getLogger(__name__)

__all__ = [
    "LidarOdometry",
    "CameraPair",
    "MotionAgreement",
    "MotionRotation",
    "lidar_odometry",
    "rotation_from_motion",
    "camera_odometry",
    "compare_motion",
    "pose_from_rays",
    "in_camera",
    "rotation_angle_deg",
    "LIDAR_METHODS",
]

#: The LiDAR odometry methods :func:`lidar_odometry` accepts; ``"auto"`` is the default one
#: (``"own"``) and falls back to nothing.
LIDAR_METHODS = ("auto", "own", "kiss-icp")


# ----------------------------------------------------------------------------- helpers

def rotation_angle_deg(R: np.ndarray) -> float:
    """Rotation angle of a 3x3 rotation matrix in degrees (0 .. 180)."""
    c = (float(np.trace(R)) - 1.0) / 2.0
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def in_camera(T_pair: np.ndarray, T_cam_lidar: np.ndarray) -> np.ndarray:
    """A LiDAR pair pose expressed as the camera's: ``X T X^-1`` (4x4).

    Parameters
    ----------
    T_pair : ndarray, shape (4, 4)
        ``T_k <- k+1`` of the LiDAR (cloud) frame.
    T_cam_lidar : ndarray, shape (4, 4)
        The extrinsic ``X``: maps LiDAR coordinates into the camera frame.

    Returns
    -------
    ndarray, shape (4, 4)
        The later camera's pose in the earlier camera's frame; its translation is the camera
        centre's displacement (m), lever arm included.
    """
    X = np.asarray(T_cam_lidar, dtype=np.float64)
    return X @ np.asarray(T_pair, dtype=np.float64) @ np.linalg.inv(X)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if not (na > 0 and nb > 0) or not (np.isfinite(a).all() and np.isfinite(b).all()):
        return float("nan")
    return math.degrees(math.acos(float(np.clip(a @ b / (na * nb), -1.0, 1.0))))


# ----------------------------------------------------------------------------- LiDAR odometry

@dataclass
class LidarOdometry:
    """Relative poses of consecutive sweeps with their uncertainty (:func:`lidar_odometry`).

    Attributes
    ----------
    method : str
        ``"own"`` or ``"kiss-icp"``: the registration that gave the poses.
    pair_poses : ndarray, shape (K-1, 4, 4)
        ``T_k <- k+1``; NaN for a pair whose registration failed.
    poses : ndarray, shape (K, 4, 4)
        ``T_0 <- k``: each sweep's pose in the first sweep's frame (the pair poses chained).
    covariance : ndarray, shape (K-1, 6, 6)
        Covariance of each pair pose (m^2, rad^2; translation first), cluster-robust sandwich
        of the own registration at that pose.
    translation_m : ndarray, shape (K-1,)
        ``|t|`` of each pair pose (m).
    translation_sigma_m : ndarray, shape (K-1,)
        Standard deviation of the translation along its own direction (m).
    direction_sigma_deg : ndarray, shape (K-1,)
        Standard deviation of the direction of travel: the larger across-direction standard
        deviation over ``|t|``, in degrees (inf for a standing pair).
    mahalanobis : ndarray, shape (K-1,)
        ``t^T S^-1 t`` with ``S`` the translation block of ``covariance``.
    standing : ndarray, shape (K-1,), bool
        The translation is not significantly different from zero.
    reasons : list of str, length K-1
        Why a pair gives no direction, in words ("" when it gives one).
    seconds : ndarray, shape (K-1,)
        Wall time of each pair's registration (s; for KISS-ICP its ``register_frame`` call,
        without the covariance evaluation).
    note : str
        How the method was chosen (a fallback and its reason), "" otherwise.
    """

    method: str
    pair_poses: np.ndarray
    poses: np.ndarray
    covariance: np.ndarray
    translation_m: np.ndarray
    translation_sigma_m: np.ndarray
    direction_sigma_deg: np.ndarray
    mahalanobis: np.ndarray
    standing: np.ndarray
    reasons: list[str]
    seconds: np.ndarray
    note: str = ""
    significance: float = 1e-3

    def relative(self, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        """Pose ``T_i <- j`` (4x4) of sweep ``j`` in sweep ``i``'s frame (``i < j``) and its
        covariance (6x6): the pair covariances carried along the chain by the adjoint,
        taken as independent."""
        if not 0 <= i < j < len(self.poses):
            raise ValueError(f"need 0 <= i < j < {len(self.poses)}, got {i}, {j}")
        T = self.pair_poses[i].copy()
        C = self.covariance[i].copy()
        for m in range(i + 1, j):
            A = _adjoint(T)
            C = C + A @ self.covariance[m] @ A.T
            T = T @ self.pair_poses[m]
        return T, C

    def judge(self, i: int, j: int) -> tuple[np.ndarray, str]:
        """Direction of travel (unit, in sweep ``i``'s frame; NaN when none) from sweep ``i`` to
        ``j`` and, when there is none, the reason in words ("" otherwise)."""
        T, C = self.relative(i, j)
        t = T[:3, 3]
        *_, standing, reason = _judge(t, C[:3, :3], self.significance)
        if reason:
            return np.full(3, np.nan), reason
        return t / np.linalg.norm(t), ""

    @property
    def directions(self) -> np.ndarray:
        """Unit direction of travel of each pair in the earlier sweep's frame, shape (K-1, 3);
        NaN where the pair gives none (standing or failed)."""
        t = self.pair_poses[:, :3, 3]
        with np.errstate(invalid="ignore", divide="ignore"):
            d = t / np.linalg.norm(t, axis=1, keepdims=True)
        d[np.array([bool(r) for r in self.reasons])] = np.nan
        return d


def _kiss_poses(clouds: Sequence[np.ndarray], voxel: float | None, max_range: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """KISS-ICP's sweep poses ``T_0 <- k`` (K, 4, 4) and the time of each registration (K,) s;
    its de-skew is off (the clouds are taken as rigid)."""
    from kiss_icp.config import KISSConfig
    from kiss_icp.kiss_icp import KissICP

    cfg = KISSConfig()
    cfg.data.deskew = False
    cfg.data.max_range = float(max_range)
    cfg.data.min_range = 0.0
    cfg.mapping.voxel_size = float(voxel) if voxel else float(max_range) / 100.0
    cfg.registration.max_num_threads = 1
    icp = KissICP(cfg)
    poses, secs = [], []
    for pts in clouds:
        t0 = time.perf_counter()
        icp.register_frame(np.ascontiguousarray(pts, dtype=np.float64), np.zeros(0))
        secs.append(time.perf_counter() - t0)
        poses.append(icp.last_pose.copy())
    P = np.asarray(poses)
    return np.linalg.inv(P[0]) @ P, np.asarray(secs)


def _kiss_available() -> str:
    """"" when KISS-ICP can be imported, else the reason it cannot."""
    try:
        import kiss_icp.kiss_icp  # noqa: F401
    except ImportError as exc:
        return f"kiss-icp is not installed ({exc}); pip install 'paretocal[odometry]'"
    return ""


def lidar_odometry(clouds: Sequence[np.ndarray], *, method: str = "auto",  # noqa: PLR0913
                   points: int = 15000, max_translation: float = 5.0, voxel: float | None = None,
                   max_range: float = 100.0, significance: float = 1e-3, block: float = 4.0,
                   seed: int = 0) -> LidarOdometry:
    """Relative poses of consecutive sweeps, each with a covariance, and the standing pairs.

    Parameters
    ----------
    clouds : sequence of ndarray, shape (N_k, 3)
        Rigid sweeps in time order (de-skewed already when the sensor moved during them), each
        in its own cloud frame, metres. Extra columns (intensity) are ignored.
    method : {"auto", "own", "kiss-icp"}
        ``"own"``: :func:`paretocal.lidar.registration.register_pair`, scan to scan. ``"kiss-icp"``: the
        optional KISS-ICP package; when it is missing the own registration is used and
        :attr:`LidarOdometry.note` (and the log) say why. ``"auto"``: the default, ``"own"``.
    points : int
        Points per cloud of the own registration (voxel subsample).
    max_translation : float
        Radius (m) of the first pair's coarse translation search (own registration).
    voxel : float, optional
        KISS-ICP's voxel edge (m); default ``max_range / 100``, its own default.
    max_range : float
        KISS-ICP's range limit (m).
    significance : float
        Probability that a standing pair's noise alone exceeds the threshold (chi-square,
        3 degrees of freedom).
    block : float
        Block edge (m) of the sandwich covariance.
    seed : int
        Randomness of the voxel subsampling.

    Returns
    -------
    LidarOdometry
    """
    if method not in LIDAR_METHODS:
        raise ValueError(f"method must be one of {LIDAR_METHODS}, got {method!r}")
    clouds = [np.asarray(c, dtype=np.float64)[:, :3] for c in clouds]
    K = len(clouds)
    if K < 2:
        raise ValueError("odometry needs at least two sweeps")
    note = ""
    if method == "kiss-icp":
        why = _kiss_available()
        if why:
            note = f"{why}: the own registration is used instead"
            log.warning("LiDAR odometry: %s", note)
            method = "own"
    elif method == "auto":
        method = "own"
    pair = np.full((K - 1, 4, 4), np.nan)
    cov = np.full((K - 1, 6, 6), np.inf)
    secs = np.zeros(K - 1)
    if method == "kiss-icp":
        P, s = _kiss_poses(clouds, voxel, max_range)
        secs[:] = s[1:]
        for k in range(K - 1):
            pair[k] = np.linalg.inv(P[k]) @ P[k + 1]
            if min(len(clouds[k]), len(clouds[k + 1])) < MIN_POINTS:
                continue                            # no covariance for a dropped sweep
            reg = register_pair(clouds[k + 1], clouds[k], pair[k], points=points, block=block,
                                refine=False, seed=seed)
            if reg is not None:
                cov[k] = reg.covariance
    else:
        # Each sweep is the source of one pair and the target of the next: subsampled once.
        # A sweep with too few points (a dropped one) fails both its pairs.
        rng = np.random.default_rng(seed)

        def prepared(cloud, start):
            return None if len(cloud) < MIN_POINTS else prepare_cloud(cloud, points, rng, start)

        target = prepared(clouds[0], None)
        voxel = None if target is None else target.voxel
        prev = None
        for k in range(K - 1):
            t0 = time.perf_counter()
            source = prepared(clouds[k + 1], voxel)
            voxel = voxel if source is None else source.voxel
            reg = (None if source is None or target is None else
                   register_prepared(source, target, prev, max_translation=max_translation,
                                     block=block))
            target = source
            secs[k] = time.perf_counter() - t0
            if reg is None:
                log.warning("LiDAR odometry: sweeps %d and %d did not register", k, k + 1)
                prev = None
                continue
            pair[k], cov[k] = reg.T, reg.covariance
            prev = reg.T
    return _finish(method, pair, cov, secs, significance, note)


def _adjoint(T: np.ndarray) -> np.ndarray:
    """Adjoint (6, 6) of a 4x4 pose for twists ordered translation first."""
    R, t = T[:3, :3], T[:3, 3]
    tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    A = np.zeros((6, 6))
    A[:3, :3] = R
    A[:3, 3:] = tx @ R
    A[3:, 3:] = R
    return A


def _judge(t: np.ndarray, S: np.ndarray, significance: float):
    """Length (m), its standard deviation along itself (m), the direction's standard deviation
    (deg), the Mahalanobis value, standing or not, and the reason in words, of a translation
    ``t`` (3,) with covariance ``S`` (3, 3)."""
    if not (np.isfinite(t).all() and np.isfinite(S).all()):
        return (float("nan"), float("nan"), float("inf"), float("nan"), False,
                "the registration failed: no motion")
    limit = float(chi2.ppf(1.0 - significance, 3))
    tr = float(np.linalg.norm(t))
    try:
        maha = float(t @ np.linalg.solve(S, t))
    except np.linalg.LinAlgError:
        maha = float("inf")
    u = t / tr if tr > 0 else np.array([1.0, 0.0, 0.0])
    t_sig = math.sqrt(max(float(u @ S @ u), 0.0))
    Pp = np.eye(3) - np.outer(u, u)
    across = max(float(np.linalg.eigvalsh(Pp @ S @ Pp)[-1]), 0.0)
    if maha < limit:
        return (tr, t_sig, float("inf"), maha, True,
                f"standing: the LiDAR moved {100 * tr:.1f} cm, within its own uncertainty "
                f"({100 * t_sig:.1f} cm along it; Mahalanobis {maha:.1f} < {limit:.1f}, the "
                f"{100 * significance:g} % level)")
    return tr, t_sig, math.degrees(math.atan2(math.sqrt(across), tr)), maha, False, ""


def _finish(method: str, pair: np.ndarray, cov: np.ndarray, secs: np.ndarray,
            significance: float, note: str) -> LidarOdometry:
    """Chain the pair poses and judge each pair's translation against its covariance."""
    n = len(pair)
    poses = np.empty((n + 1, 4, 4))
    poses[0] = np.eye(4)
    for k in range(n):
        poses[k + 1] = poses[k] @ pair[k]
    cols = list(zip(*[_judge(pair[k, :3, 3], cov[k, :3, :3], significance) for k in range(n)]))
    tr, t_sig, d_sig, maha, standing, reasons = cols if n else ([],) * 6
    return LidarOdometry(method=method, pair_poses=pair, poses=poses, covariance=cov,
                         translation_m=np.array(tr), translation_sigma_m=np.array(t_sig),
                         direction_sigma_deg=np.array(d_sig), mahalanobis=np.array(maha),
                         standing=np.array(standing, bool), reasons=list(reasons), seconds=secs,
                         note=note, significance=significance)


# ----------------------------------------------------------------------------- visual odometry

@dataclass
class CameraPair:
    """Visual odometry between two images of one camera (:func:`camera_odometry`).

    Attributes
    ----------
    i, j : int
        Indices of the earlier and the later image.
    R : ndarray, shape (3, 3)
        ``R_c1_c2``: the later camera's rotation in the earlier camera's frame (identity when
        the pair gives no rotation, see ``rotation_ok``).
    direction : ndarray, shape (3,)
        Unit direction of travel in the earlier camera's frame (NaN when the pair gives none).
    matches : int
        Matches passing the ratio test with valid rays.
    inliers : int
        Matches consistent with the essential matrix and in front of both cameras.
    direction_sigma_deg : float
        Bootstrap RMS angle (over resampled inliers) of the direction about the estimate (deg).
    rotation_sigma_deg : float
        Bootstrap RMS angle of the rotation about the estimate (deg).
    parallax_px : float
        Median parallax of the inliers left after removing the rotation (angle times the mean
        focal length, px).
    noise_px : float
        Median angular distance of the inliers from their epipolar planes, in the same units.
    ok : bool
        The pair gives a direction of travel.
    rotation_ok : bool
        The pair gives a rotation (enough inliers; with or without parallax).
    reason : str
        Why there is no direction, in words ("" when ``ok``).
    seconds : float
        Wall time of the pair (matching, essential matrix, bootstrap; s), features not counted.
    """

    i: int
    j: int
    R: np.ndarray
    direction: np.ndarray
    matches: int
    inliers: int
    direction_sigma_deg: float
    rotation_sigma_deg: float
    parallax_px: float
    noise_px: float
    ok: bool
    rotation_ok: bool
    reason: str
    seconds: float = 0.0


def _features(img: np.ndarray, mask: np.ndarray | None, sift) -> tuple[np.ndarray, np.ndarray]:
    """SIFT keypoint positions (N, 2) px and descriptors (N, 128) of one image."""
    gray = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    m = None if mask is None else np.asarray(mask, dtype=np.uint8) * 255
    kp, desc = sift.detectAndCompute(gray, m)
    if desc is None or not kp:
        return np.zeros((0, 2)), np.zeros((0, 128), np.float32)
    return np.array([k.pt for k in kp], dtype=np.float64), desc


def _match(d1: np.ndarray, d2: np.ndarray, ratio: float) -> np.ndarray:
    """Index pairs (M, 2) of SIFT matches passing the ratio test, one per keypoint of image 2."""
    if len(d1) < 2 or len(d2) < 2:
        return np.zeros((0, 2), int)
    bf = cv2.BFMatcher(cv2.NORM_L2)
    out = [(m.queryIdx, m.trainIdx) for m, n in bf.knnMatch(d1, d2, k=2)
           if m.distance < ratio * n.distance]
    if not out:
        return np.zeros((0, 2), int)
    pairs = np.array(out, dtype=int)
    _, first = np.unique(pairs[:, 1], return_index=True)
    return pairs[np.sort(first)]


def _sign(R: np.ndarray, t: np.ndarray, r1: np.ndarray, r2: np.ndarray) -> float:
    """+1 when ``t`` (x2 = R x1 + t) points the way the de-rotated rays moved, else -1.

    For a static point ``r2 ~ lam R r1 + t`` with ``lam > 0``: the component of ``r2`` across
    ``R r1`` has the sign of ``t``'s across it. Summed over the inliers, each vote weighs with its
    parallax, so near points decide, not the far ones whose sign is noise (``recoverPose``
    instead counts points in front and ignores those beyond 50 baselines).
    """
    a = r1 @ R.T
    v = r2 - np.einsum("ij,ij->i", r2, a)[:, None] * a
    w = t[None] - (a @ t)[:, None] * a
    return 1.0 if float(np.einsum("ij,ij->", v, w)) >= 0 else -1.0


def _essential(x1: np.ndarray, x2: np.ndarray, r1: np.ndarray, r2: np.ndarray, thr: float,
               seed: int):
    """R, unit t (x2 = R x1 + t) and the inlier mask from normalised coordinates (N, 2) and
    unit rays (N, 3) of both images; None when no essential matrix is found."""
    cv2.setRNGSeed(seed)
    E, m = cv2.findEssentialMat(x1, x2, np.eye(3), method=cv2.RANSAC, prob=0.999, threshold=thr)
    if E is None or E.shape != (3, 3):
        return None
    m = m.reshape(-1).astype(bool)
    _, R, t, m2 = cv2.recoverPose(E, x1, x2, np.eye(3), mask=m.astype(np.uint8).copy())
    t = t.reshape(3) / np.linalg.norm(t)
    inl = m2.reshape(-1).astype(bool) & m
    if inl.sum() < 5:
        inl = m
    t = t * _sign(R, t, r1[inl], r2[inl])
    return R, t, inl


def _kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation R (3, 3) minimising ``sum |b - R a|^2`` over unit rays (N, 3)."""
    U, _, Vt = np.linalg.svd(b.T @ a)
    S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ S @ Vt


def _rotation_only(r1: np.ndarray, r2: np.ndarray, thr: float) -> tuple[np.ndarray, np.ndarray]:
    """Robust rotation-only fit ``r2 ~ R r1`` (R is camera 2 <- camera 1) and its residual
    angles (rad): Kabsch on all rays, then on those within ``max(3 thr, 3 MAD scale)``."""
    keep = np.ones(len(r1), bool)
    R = np.eye(3)
    for _ in range(5):
        R = _kabsch(r1[keep], r2[keep])
        res = np.arccos(np.clip(np.einsum("ij,ij->i", r1 @ R.T, r2), -1, 1))
        gate = max(3.0 * thr, 3.0 * 1.4826 * float(np.median(res[keep])))
        new = res < gate
        if new.sum() < 3 or np.array_equal(new, keep):
            break
        keep = new
    return R, res


def _epipolar_angle(E: np.ndarray, r1: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """Angular distance (rad) of unit rays ``r2`` from the epipolar planes ``E r1``."""
    n = r1 @ E.T
    nn = np.linalg.norm(n, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.abs(np.arcsin(np.clip(np.einsum("ij,ij->i", r2, n) / nn, -1, 1)))


@dataclass(frozen=True)
class _VOSettings:
    thr: float
    f: float
    ratio: float
    min_inliers: int
    min_parallax_ratio: float
    max_direction_sigma: float
    bootstrap: int
    seed: int


def camera_odometry(images: Sequence[np.ndarray], camera: Camera, *,  # noqa: PLR0913
                    pairs: Sequence[tuple[int, int]] | None = None,
                    mask: np.ndarray | None = None, ratio: float = 0.8, features: int = 4000,
                    threshold_px: float = 1.0, min_inliers: int = 30,
                    min_parallax_ratio: float = 3.0, max_direction_sigma_deg: float = 10.0,
                    bootstrap: int = 40, max_ray_deg: float = 80.0,
                    seed: int = 0, image_feats: dict | None = None) -> list[CameraPair]:
    """Rotation and direction of travel between images of one camera.

    SIFT features, Lowe's ratio test, then OpenCV's essential matrix with RANSAC on the
    undistorted normalised coordinates (from the rays of
    :meth:`paretocal.camera.Camera.unproject`, so every lens model of the project works),
    ``recoverPose`` for the rotation, the translation's sign from the parallax-weighted
    de-rotated flow, and a bootstrap over the inliers for the uncertainty of both.

    Parameters
    ----------
    images : sequence of ndarray, shape (H, W, 3) uint8 (BGR) or (H, W)
        Images of one camera, in time order.
    camera : Camera
        Its lens model.
    pairs : sequence of (i, j), optional
        Image index pairs to compare (``i < j``); default the consecutive ones. A longer
        baseline (``j - i`` larger) gives more parallax when the rig moves slowly.
    mask : ndarray, shape (H, W), bool, optional
        Pixels that show the scene (features elsewhere are ignored).
    ratio : float
        Lowe's ratio test (best over second-best descriptor distance).
    features : int
        Most SIFT features per image.
    threshold_px : float
        RANSAC threshold in pixels (converted to normalised units with the mean focal length).
    min_inliers : int
        Fewest inliers for a pair to give a rotation or a direction.
    min_parallax_ratio : float
        Smallest ratio of the median de-rotated parallax to the median epipolar residual for a
        direction (noise alone gives about 1.7; see the module notes).
    max_direction_sigma_deg : float
        Largest bootstrap spread of the direction (deg) for the pair to give one: beyond it the
        matches do not fix the direction, nor often its sign (KITTI pairs 0.2 m apart among
        moving trucks: 12-64 deg, three of 19 reversed; 2 m apart: 0.6-1.4 deg).
    bootstrap : int
        Bootstrap resamples of the inliers (0: no uncertainty, NaN, and no spread test).
    max_ray_deg : float
        Rays farther than this from the optical axis are dropped (the normalised plane
        stretches them without bound towards 90 degrees).
    seed : int
        Randomness of RANSAC and of the bootstrap.
    image_feats : dict, optional
        :func:`image_features` of the images already extracted (with the same ``mask``,
        ``features`` and ``max_ray_deg``), e.g. while the LiDAR's odometry ran.

    Returns
    -------
    list of CameraPair, one per pair
    """
    n = len(images)
    if pairs is None:
        pairs = [(k, k + 1) for k in range(n - 1)]
    pairs = [(int(i), int(j)) for i, j in pairs]
    if any(not 0 <= i < j < n for i, j in pairs):
        raise ValueError(f"pairs must satisfy 0 <= i < j < {n}")
    f = 0.5 * float(camera.K[0, 0] + camera.K[1, 1])
    vs = _VOSettings(threshold_px / f, f, ratio, min_inliers, min_parallax_ratio,
                     max_direction_sigma_deg, bootstrap, seed)
    need = sorted({k for p in pairs for k in p})
    feats = dict(image_feats or {})
    feats.update(image_features(images, camera, [k for k in need if k not in feats], mask=mask,
                                features=features, max_ray_deg=max_ray_deg))
    rng = np.random.default_rng(seed)
    out = []
    for i, j in pairs:
        t0 = time.perf_counter()
        pair = _camera_pair(i, j, feats[i], feats[j], vs, rng)
        pair.seconds = time.perf_counter() - t0
        out.append(pair)
    return out


def image_features(images: Sequence[np.ndarray], camera: Camera, indices=None, *,
                   mask: np.ndarray | None = None, features: int = 4000,
                   max_ray_deg: float = 80.0,
                   stop: threading.Event | None = None) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """SIFT features of the images of index ``indices`` (all by default) as
    :func:`camera_odometry` matches them: by index, the unit rays (M, 3) of the keypoints
    within ``max_ray_deg`` of the optical axis and their descriptors (M, 128). ``stop``, once
    set, ends the extraction after the image at hand (the images done so far are returned)."""
    # OpenCV's stubs declare SIFT only as the class SIFT, not its module-level factory.
    sift = cv2.SIFT_create(nfeatures=int(features))  # type: ignore[attr-defined]
    cos_max = math.cos(math.radians(max_ray_deg))
    out = {}
    for k in range(len(images)) if indices is None else indices:
        if stop is not None and stop.is_set():
            break
        uv, desc = _features(images[k], mask, sift)
        rays = camera.unproject(uv) if len(uv) else np.zeros((0, 3))
        good = np.isfinite(rays).all(axis=1) & (np.nan_to_num(rays[:, 2]) > cos_max)
        out[int(k)] = (rays[good], desc[good])
    return out


def _no_direction(i: int, j: int, matches: int, inliers: int, reason: str, R=None,
                  rot_sigma: float = float("nan"), parallax: float = float("nan"),
                  noise: float = float("nan")) -> CameraPair:
    return CameraPair(i=i, j=j, R=np.eye(3) if R is None else R, direction=np.full(3, np.nan),
                      matches=matches, inliers=inliers, direction_sigma_deg=float("nan"),
                      rotation_sigma_deg=rot_sigma, parallax_px=parallax, noise_px=noise,
                      ok=False, rotation_ok=R is not None, reason=reason)


def _camera_pair(i: int, j: int, a, b, vs: _VOSettings, rng) -> CameraPair:
    (r1, d1), (r2, d2) = a, b
    mt = _match(d1, d2, vs.ratio)
    M = len(mt)
    need = max(vs.min_inliers, 8)
    if M < need:
        return _no_direction(i, j, M, 0, f"too few matches ({M} < {need}): no motion")
    return _from_rays(i, j, r1[mt[:, 0]], r2[mt[:, 1]], vs, rng)


def pose_from_rays(r1: np.ndarray, r2: np.ndarray, focal: float, *,  # noqa: PLR0913
                   threshold_px: float = 1.0, min_inliers: int = 30,
                   min_parallax_ratio: float = 3.0, max_direction_sigma_deg: float = 10.0,
                   bootstrap: int = 40, seed: int = 0) -> CameraPair:
    """The geometric core of :func:`camera_odometry` on matched rays.

    Parameters
    ----------
    r1, r2 : ndarray, shape (M, 3)
        Unit rays (camera frame, z forward) of the same scene points in the earlier and the
        later image, in front of the camera (``z > 0``).
    focal : float
        Focal length (px) that converts angles to pixels for the thresholds and figures.
    threshold_px, min_inliers, min_parallax_ratio, max_direction_sigma_deg, bootstrap, seed
        As for :func:`camera_odometry`.

    Returns
    -------
    CameraPair
        With ``i, j = 0, 1``.
    """
    vs = _VOSettings(threshold_px / focal, float(focal), 1.0, min_inliers, min_parallax_ratio,
                     max_direction_sigma_deg, bootstrap, seed)
    r1 = np.asarray(r1, dtype=np.float64)
    r2 = np.asarray(r2, dtype=np.float64)
    if r1.shape != r2.shape or r1.ndim != 2 or r1.shape[1] != 3:
        raise ValueError(f"rays must be two (M, 3) arrays, got {r1.shape} and {r2.shape}")
    need = max(min_inliers, 8)
    if len(r1) < need:
        return _no_direction(0, 1, len(r1), 0, f"too few matches ({len(r1)} < {need}): no motion")
    return _from_rays(0, 1, r1, r2, vs, np.random.default_rng(seed))


def _from_rays(i: int, j: int, r1: np.ndarray, r2: np.ndarray, vs: _VOSettings, rng) -> CameraPair:
    M = len(r1)
    x1 = np.ascontiguousarray(r1[:, :2] / r1[:, 2:])
    x2 = np.ascontiguousarray(r2[:, :2] / r2[:, 2:])
    est = _essential(x1, x2, r1, r2, vs.thr, vs.seed)
    if est is None:
        return _no_direction(i, j, M, 0, "no essential matrix found: no motion")
    R, t, inl = est
    n_in = int(inl.sum())
    if n_in < vs.min_inliers:
        return _no_direction(i, j, M, n_in, f"too few inliers ({n_in} < {vs.min_inliers}): no motion")
    R12 = R.T
    d = -R.T @ t
    q1, q2 = r1[inl], r2[inl]
    # the parallax: what a rotation-only model leaves unexplained, against the epipolar residual
    Rr, _ = _rotation_only(q1, q2, vs.thr)
    par = np.arccos(np.clip(np.einsum("ij,ij->i", q1 @ Rr.T, q2), -1, 1))
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    res = _epipolar_angle(tx @ R, q1, q2)
    parallax, noise = float(np.median(par)) * vs.f, float(np.median(res)) * vs.f
    if not parallax > vs.min_parallax_ratio * noise:
        # no translation seen: the rotation is the rotation-only fit over all the matches
        Rr, rr = _rotation_only(r1, r2, vs.thr)
        n_rot = int((rr < 3.0 * vs.thr).sum())
        return _no_direction(
            i, j, M, n_rot, f"too little parallax: {parallax:.2f} px median once the rotation "
            f"is removed, against {noise:.2f} px of matching noise (ratio "
            f"{parallax / max(noise, 1e-12):.1f} < {vs.min_parallax_ratio:g}): the camera did not "
            "move enough to show a direction", R=Rr.T, parallax=parallax, noise=noise)
    d_sig, r_sig = _bootstrap(x1[inl], x2[inl], q1, q2, d, R12, vs, rng)
    if d_sig > vs.max_direction_sigma:
        out = _no_direction(
            i, j, M, n_in, f"direction not resolved: it moves by {d_sig:.1f} deg (RMS) over "
            f"bootstrap resamples of the {n_in} inliers, more than {vs.max_direction_sigma:g} deg "
            "(too little baseline for the depth of the scene, or moving objects among the "
            "matches)", R=R12, rot_sigma=r_sig, parallax=parallax, noise=noise)
        out.direction_sigma_deg = d_sig
        return out
    return CameraPair(i=i, j=j, R=R12, direction=d, matches=M, inliers=n_in,
                      direction_sigma_deg=d_sig, rotation_sigma_deg=r_sig, parallax_px=parallax,
                      noise_px=noise, ok=True, rotation_ok=True, reason="")


def _bootstrap(x1, x2, r1, r2, d, R12, vs: _VOSettings, rng) -> tuple[float, float]:
    """RMS angle (deg) of the direction and of the rotation over bootstrap resamples."""
    if vs.bootstrap <= 0:
        return float("nan"), float("nan")
    da, ra = [], []
    for b in range(vs.bootstrap):
        pick = rng.integers(0, len(x1), len(x1))
        est = _essential(np.ascontiguousarray(x1[pick]), np.ascontiguousarray(x2[pick]),
                         r1[pick], r2[pick], vs.thr, vs.seed + 1 + b)
        if est is None:
            continue
        R, t, _ = est
        da.append(_angle_deg(-R.T @ t, d))
        ra.append(rotation_angle_deg(R12.T @ R.T))
    if not da:
        return float("nan"), float("nan")
    return math.sqrt(float(np.mean(np.square(da)))), math.sqrt(float(np.mean(np.square(ra))))


# ----------------------------------------------------------------------------- agreement

@dataclass
class MotionAgreement:
    """Camera against LiDAR motion through an extrinsic (:func:`compare_motion`).

    Attributes
    ----------
    pairs : list of (int, int)
        The frame pairs compared.
    direction_deg : ndarray, shape (P,)
        Angle between the camera's direction of travel and the LiDAR's mapped through the
        extrinsic (deg); NaN where either gives no direction.
    rotation_deg : ndarray, shape (P,)
        Angle of ``R_cam^T R_lidar_in_cam`` (deg): how far the two relative rotations differ;
        NaN where the camera pair gives no rotation.
    camera_rotation_deg, lidar_rotation_deg : ndarray, shape (P,)
        The relative rotation angle of each (deg).
    lidar_direction_cam : ndarray, shape (P, 3)
        The LiDAR's direction of travel in the earlier camera frame (unit; NaN when none).
    reasons : list of str
        Why a pair has no direction angle ("" when it has one).
    """

    pairs: list[tuple[int, int]]
    direction_deg: np.ndarray
    rotation_deg: np.ndarray
    camera_rotation_deg: np.ndarray
    lidar_rotation_deg: np.ndarray
    lidar_direction_cam: np.ndarray
    reasons: list[str]

    def summary(self) -> dict:
        """Median and maximum over the pairs that give a value (deg), and their counts."""
        def stats(a):
            a = a[np.isfinite(a)]
            return {"n": int(len(a)), "median": float(np.median(a)) if len(a) else None,
                    "max": float(np.max(a)) if len(a) else None}
        return {"direction_deg": stats(self.direction_deg),
                "rotation_deg": stats(self.rotation_deg)}


def compare_motion(lidar: LidarOdometry, camera: Sequence[CameraPair],
                   T_cam_lidar: np.ndarray) -> MotionAgreement:
    """Compare each camera pair's motion with the LiDAR's over the same frames, mapped through
    ``T_cam_lidar``.

    Parameters
    ----------
    lidar : LidarOdometry
        Over the frames the camera pairs index.
    camera : sequence of CameraPair
    T_cam_lidar : ndarray, shape (4, 4)

    Returns
    -------
    MotionAgreement
    """
    P = len(camera)
    dd, rr = np.full(P, np.nan), np.full(P, np.nan)
    cr, lr = np.full(P, np.nan), np.full(P, np.nan)
    ldc = np.full((P, 3), np.nan)
    reasons = []
    for k, c in enumerate(camera):
        T, _ = lidar.relative(c.i, c.j)
        if not np.isfinite(T).all():
            reasons.append("the LiDAR registration failed")
            continue
        Tc = in_camera(T, T_cam_lidar)
        lr[k] = rotation_angle_deg(Tc[:3, :3])
        if c.rotation_ok:
            cr[k] = rotation_angle_deg(c.R)
            rr[k] = rotation_angle_deg(c.R.T @ Tc[:3, :3])
        _, why = lidar.judge(c.i, c.j)
        if not why:
            ldc[k] = Tc[:3, 3] / np.linalg.norm(Tc[:3, 3])
        why = "; ".join(w for w in (why, c.reason) if w)
        if not why:
            dd[k] = _angle_deg(c.direction, ldc[k])
        reasons.append(why)
    return MotionAgreement([(c.i, c.j) for c in camera], dd, rr, cr, lr, ldc, reasons)


# ----------------------------------------------------------------------------- rotation

#: Rotation errors the edge objective's search recovers from (deg): from starts +-5 deg per
#: axis on the KITTI drive 20 of 20 runs reached 0.18 deg (README, *Accuracy*). An angle the
#: motion leaves more uncertain than this (3 sigma) is left to search.
EDGE_BASIN_DEG = 5.0
#: A pair's relative rotation gives its axis (hand-eye) when the angle is at least this many
#: times both sensors' standard deviations of it.
MIN_TURN_SIGMAS = 5.0
#: Weight of the initial extrinsic's rotation about a direction the motion does not observe,
#: relative to the weakest motion vector: it only fills what the motion leaves free.
PRIOR_WEIGHT = 1e-3


@dataclass
class MotionRotation:
    """A rotation of the extrinsic from the two sensors' motion (:func:`rotation_from_motion`).

    Attributes
    ----------
    R : ndarray, shape (3, 3)
        ``R_cam_lidar``: maps the LiDAR's directions of travel (and rotation axes) onto the
        camera's; about an axis the motion does not observe it keeps the initial rotation.
    free_axis : ndarray, shape (3,), or None
        Unit axis, in the camera frame, about which the motion leaves the rotation open (the
        mean direction of travel on a straight drive); None when every axis is observed.
    sigma_deg : ndarray, shape (3,)
        Standard deviation of the rotation about the camera's x, y, z axes (deg), from the
        vectors' own uncertainties; inf where not observed.
    directions : int
        Pairs whose directions of travel were used.
    turns : int
        Pairs whose rotation axes were used (hand-eye).
    reversed : int
        Camera directions dropped because they point against the LiDAR's (through the initial
        rotation, more than 90 deg apart): the visual odometry's sign was wrong.
    residual_deg : float
        RMS angle between the camera's vectors and the LiDAR's mapped through ``R``.
    change_deg : float
        Angle of ``R`` against the initial rotation.
    reasons : list of str
        What the motion could not give, in words.
    """

    R: np.ndarray
    free_axis: np.ndarray | None
    sigma_deg: np.ndarray
    directions: int
    turns: int
    reversed: int
    residual_deg: float
    change_deg: float
    reasons: list

    @property
    def usable(self) -> bool:
        """At least two angles observed (a direction of travel, or turns)."""
        return self.directions + self.turns > 0


def _rotvec(R: np.ndarray) -> np.ndarray:
    """Rotation vector (rad) of a 3x3 rotation."""
    ang = math.radians(rotation_angle_deg(R))
    if ang < 1e-12:
        return np.zeros(3)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    n = np.linalg.norm(w)
    if n < 1e-12:                     # 180 deg: the axis from R + I
        k = int(np.argmax(np.diag(R)))
        v = (R[:, k] + np.eye(3)[:, k])
        return ang * v / np.linalg.norm(v)
    return ang * w / n


def _without_twist(D: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The swing ``S`` of ``D = T S`` (3x3), ``T`` a rotation about the unit ``axis``
    (swing-twist decomposition: the twist's quaternion is ``D``'s with its vector part
    projected on the axis)."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(D).as_quat()           # x, y, z, w
    a = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    t = np.r_[(q[:3] @ a) * a, q[3]]
    nt = np.linalg.norm(t)
    if nt < 1e-12:                                   # a half turn across the axis: no twist
        return D
    T = Rotation.from_quat(t / nt).as_matrix()
    return T.T @ D


def _weighted_kabsch(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``R`` minimising ``sum w |b - R a|^2`` (a, b: (K, 3); w: (K,))."""
    H = (a * w[:, None]).T @ b
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(Vt.T @ U.T))) or 1.0])
    return Vt.T @ D @ U.T


def rotation_from_motion(lidar: LidarOdometry, camera: Sequence[CameraPair],
                         R_init: np.ndarray, t_init: np.ndarray | None = None,
                         t_sigma_m: float = 0.0) -> MotionRotation:
    """The extrinsic's rotation from the directions of travel and the turns of both sensors.

    The camera moves by ``X T X^-1`` when the LiDAR moves by ``T`` (``X = T_cam_lidar``): its
    displacement is ``R t + (I - R_c) t_X`` (``R_c`` the camera's own turn), so its direction
    of travel, once the lever arm ``(I - R_c) t_X`` is taken off with the initial ``t_X``, is
    ``R`` times the LiDAR's, and its rotation axis ``R`` times the LiDAR's. The lever arm's
    uncertainty (``t_sigma_m`` per axis: a 10 deg turn with ``t_X`` 0.3 m off tilts a 2 m
    step by 1.5 deg) is added to each direction's variance. Every pair both sensors resolve
    adds a direction; every pair turning clearly (:data:`MIN_TURN_SIGMAS`) adds its axis. ``R``
    is the weighted least-squares rotation between the two sets (Wahba's problem; weights the
    inverse variances of the angles), with the initial rotation as a weak prior that only
    fills the angle the vectors leave free: on a straight drive, the rotation about the
    direction of travel.

    A camera direction more than 90 deg from the LiDAR's through ``R_init`` is taken for a
    wrong sign of the visual odometry and dropped (any initial rotation within 90 deg of the
    truth tells the two signs apart).

    Parameters
    ----------
    lidar : LidarOdometry
        Over the frames the camera pairs index.
    camera : sequence of CameraPair
    R_init : ndarray, shape (3, 3)
        The initial ``R_cam_lidar``.
    t_init : ndarray, shape (3,), optional
        The initial ``t_X`` (m; zero when not given).
    t_sigma_m : float
        Its uncertainty per axis (m).

    Returns
    -------
    MotionRotation
    """
    R0 = np.asarray(R_init, dtype=np.float64)
    tX = np.zeros(3) if t_init is None else np.asarray(t_init, dtype=np.float64)
    a_rows: list[np.ndarray] = []
    b_rows: list[np.ndarray] = []
    w_rows: list[float] = []
    n_dir = n_turn = n_rev = 0
    reasons: list[str] = []
    for c in camera:
        T, C = lidar.relative(c.i, c.j)
        if not np.isfinite(T).all():
            continue
        d_l, why = lidar.judge(c.i, c.j)
        if c.ok and not why and np.isfinite(c.direction).all():
            if float(c.direction @ (R0 @ d_l)) < 0.0:
                n_rev += 1
                reasons.append(f"frames {c.i}-{c.j}: the camera's direction of travel points "
                               f"against the LiDAR's ({_angle_deg(c.direction, R0 @ d_l):.0f} "
                               "deg apart): the visual odometry's sign is wrong, pair dropped")
            else:
                tr = float(np.linalg.norm(T[:3, 3]))
                S = C[:3, :3]
                P = np.eye(3) - np.outer(d_l, d_l)
                sig_l = math.sqrt(max(float(np.linalg.eigvalsh(P @ S @ P)[-1]), 0.0)) / tr
                sig_c = math.radians(c.direction_sigma_deg
                                     if np.isfinite(c.direction_sigma_deg) else 1.0)
                # The camera's step without its lever arm (its length taken as the LiDAR's).
                Rc = c.R if c.rotation_ok else R0 @ T[:3, :3] @ R0.T
                step = tr * c.direction / np.linalg.norm(c.direction) - (np.eye(3) - Rc) @ tX
                turn = math.radians(rotation_angle_deg(Rc))
                sig_arm = turn * math.sqrt(3.0) * t_sigma_m / tr
                a_rows.append(d_l)
                b_rows.append(step / np.linalg.norm(step))
                w_rows.append(1.0 / (sig_l ** 2 + sig_c ** 2 + sig_arm ** 2 + 1e-12))
                n_dir += 1
        if c.rotation_ok:
            rv_l, rv_c = _rotvec(T[:3, :3]), _rotvec(c.R)
            ang = float(np.linalg.norm(rv_l))
            sig_rl = math.sqrt(max(float(np.trace(C[3:, 3:])) / 3.0, 0.0))
            sig_rc = math.radians(c.rotation_sigma_deg
                                  if np.isfinite(c.rotation_sigma_deg) else 1.0)
            sig = math.hypot(sig_rl, sig_rc)
            if ang > MIN_TURN_SIGMAS * sig and np.linalg.norm(rv_c) > 0:
                a_rows.append(rv_l / ang)
                b_rows.append(rv_c / np.linalg.norm(rv_c))
                w_rows.append((ang / sig) ** 2)          # the axis's angular variance: (sig / ang)^2
                n_turn += 1
    if not a_rows:
        reasons.append("no pair gives a direction of travel or a clear turn that both sensors "
                       "resolve (standing, too little parallax, or no camera pairs)")
        return MotionRotation(R0.copy(), None, np.full(3, np.inf), 0, 0, n_rev, float("nan"),
                              0.0, reasons)
    a, b, w = np.array(a_rows), np.array(b_rows), np.array(w_rows)
    # Information about a small rotation phi (camera frame) of R: each vector b with weight w
    # constrains the components of phi across it: sum w (I - b b^T).
    info = sum(wk * (np.eye(3) - np.outer(bk, bk)) for wk, bk in zip(w, b))
    ev, V = np.linalg.eigh(info)
    limit = 1.0 / math.radians(EDGE_BASIN_DEG / 3.0) ** 2
    free = None
    if ev[0] < limit:
        free = V[:, 0] * np.sign(V[:, 0] @ b.mean(axis=0) or 1.0)
        # The prior: the initial rotation about the free axis, through two vectors across it.
        e1 = np.cross(free, [1.0, 0.0, 0.0] if abs(free[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(free, e1)
        pw = PRIOR_WEIGHT * float(w.min())
        a = np.vstack([a, R0.T @ e1, R0.T @ e2])
        b = np.vstack([b, e1, e2])
        w = np.r_[w, pw, pw]
        reasons.append(f"the rotation about the direction of travel is not observed (the motion "
                       f"fixes it only to {math.degrees(1.0 / math.sqrt(max(ev[0], 1e-300))):.2g}"
                       f" deg): the initial one is kept, for the search to refine")
    R = _weighted_kabsch(a, b, w)
    if free is not None:
        # The prior only breaks the tie: noise across nearly parallel directions can still
        # turn the fit about the free axis (by 150 deg on KITTI pairs 4 frames apart). Keep
        # the initial angle about it exactly: of R R0^T = twist * swing, with the twist about
        # the free axis applied last (it leaves the direction of travel where the fit put it),
        # keep the swing.
        R = _without_twist(R @ R0.T, free) @ R0
    keep = slice(0, n_dir + n_turn)
    res = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", (R @ a[keep].T).T, b[keep]),
                                       -1.0, 1.0)))
    var = (V ** 2 / np.maximum(ev, 1e-300)[None, :]).sum(axis=1)      # rad^2 per camera axis
    sig_deg = np.degrees(np.sqrt(var))
    sig_deg = np.where(sig_deg > 180.0, np.inf, sig_deg)
    return MotionRotation(R, free, sig_deg, n_dir, n_turn, n_rev,
                          float(np.sqrt(np.mean(res ** 2))), rotation_angle_deg(R @ R0.T), reasons)
