"""Ego-motion from a sequence of LiDAR sweeps (and the time offset of their clocks).

Each sweep is de-skewed (:mod:`paretocal.lidar.trajectory`, whose conventions hold here) with the
current estimate and registered onto the next (:mod:`paretocal.lidar.registration`).

Estimating the motion
---------------------
:func:`estimate_motion` registers consecutive clouds of the sequence to each other
(point-to-plane ICP with a Cauchy robust kernel, coarse-to-fine over voxel subsamples), each
cloud first de-skewed to its own reference time (the window centre) with the current twist
estimate. The relative pose of consecutive reference times then gives the twist again,
``[v, w] = log(T(tau_k <- tau_k+1)) / (tau_k+1 - tau_k)``, and the two are iterated until the
de-skew moves no point by more than ``tol`` metres. The first pass de-skews with a zero twist,
i.e. registers the raw clouds; its residual is kept for comparison.

Registration on a road is nearly degenerate along the direction of travel: guard rails, kerbs,
lane marks and the road surface all slide along it. The estimate therefore reports, for every
pair, the information matrix of the point-to-plane cost, the *marginal information* along each
cloud axis (translation, Schur complement over the other five parameters), the smallest
eigenvalue of the translation information with its direction, and the share of the
translation constraint that acts along each axis, together with the spread of the pair
velocities. An axis whose median share is below ``min_share`` is reported unobservable, and
:meth:`MotionEstimate.frame_motion` refuses to hand out a twist for de-skewing unless forced:
a caller can then say "motion not observable, not compensated" instead of applying a wrong
de-skew. The spread alone does not reveal it: a corridor registers to zero motion with a
small, consistent spread.

Each correspondence is weighted by the planarity of its target neighbourhood as well as by the
robust kernel. Without it, normals fitted to single scan rings or to noise gave a corridor of
two walls and a floor a spurious 0.7 % share of constraint along the walls; with it the share
is 0.13-0.4 % for range noise up to 2 cm, but 2 % at 5 cm noise with 7 cm voxels (noise close
to the voxel edge: there the threshold below no longer separates). A synthetic street of
buildings and poles gives 10-25 %, and the aiMotive motorway 13-16 %: x is its weakest axis (the
weakest eigenvector lies within 10 degrees of x in every pair) but it is constrained. The
default ``min_share`` of 2 % sits between the two groups.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from ..geometry import transform_points
from .trajectory import Motion, Twist, check_cloud, deskew, se3_log, sweep_centre
from .registration import (PairFit, PlaneTarget, coarse_translation, conditioning, kd_tree,
                           neighbours, plane_target, prepare_levels, register_levels)

log = logging.getLogger(__name__)

__all__ = ["MotionEstimate", "TimeOffsetEstimate", "estimate_motion", "estimate_time_offset",
           "pair_residuals"]


# ----------------------------------------------------------------------------- estimation

@dataclass
class MotionEstimate:
    """Ego-motion estimated from a cloud sequence by :func:`estimate_motion`.

    Attributes
    ----------
    ref_times : ndarray, shape (K,)
        Reference time of each frame (s): the centre of its sweep window unless given.
    twist : Twist
        The shared twist: mean of the pair twists.
    frame_twists : list of Twist, length K
        Per-frame twist: mean of the twists of the (one or two) pairs the frame belongs to.
    pair_twists : ndarray, shape (K-1, 6)
        ``[vx, vy, vz, wx, wy, wz]`` (m/s, rad/s) of each consecutive pair,
        ``log(T(tau_k <- tau_k+1)) / (tau_k+1 - tau_k)``.
    pair_poses : ndarray, shape (K-1, 4, 4)
        ``T(tau_k <- tau_k+1)`` of each pair from the final registration.
    pair_se : ndarray, shape (K-1, 6)
        Standard error of each pair twist from the registration's own information matrix,
        scaled by its robust residual scale. Neighbouring points' residuals are correlated, so
        this is optimistic; ``speed_spread`` is the honest figure.
    information : ndarray, shape (K-1, 6)
        Marginal information per parameter (translation 1/m^2, rotation 1/rad^2) of each pair.
    share : ndarray, shape (K-1, 3)
        Share of the translation constraint along the cloud's x, y, z axes (dimensionless).
    min_eigenvalue : ndarray, shape (K-1,)
        Smallest eigenvalue of the translation information (1/m^2, rotation marginalised).
    weakest_axis : ndarray, shape (K-1, 3)
        Its unit eigenvector in cloud coordinates: the direction the data constrain least.
    hessian : ndarray, shape (K-1, 6, 6)
        The information matrices themselves (translation first, left perturbation, target
        frame).
    observable : ndarray, shape (3,), bool
        Per cloud axis: the median share over pairs is at least ``min_share``.
    speed, speed_spread, speed_sem : float
        Mean of the pair speeds ``|v|`` (m/s), their sample standard deviation, and the standard
        error of the mean (``spread / sqrt(K-1)``; neighbouring pairs share a cloud, so this is
        slightly optimistic).
    v_spread : ndarray, shape (3,)
        Sample standard deviation of the pair velocities per axis (m/s).
    residual_raw, residual : ndarray, shape (K-1,)
        Median distance (m) from the points of cloud k+1 to their nearest neighbour in cloud k
        after registration: raw clouds registered to each other (the first pass), and de-skewed
        clouds with the final motion. See :func:`pair_residuals`.
    inliers : ndarray, shape (K-1,), int
        Correspondences within the gate at the last registration of each pair.
    iterations : int
        De-skew / registration passes run (the raw pass included).
    converged : bool
        Whether the last pass changed the de-skew by less than ``tol``.
    voxel : ndarray, shape (K,)
        The voxel edge (m) of each cloud's finest subsample.
    per_frame : bool
        Whether each frame was de-skewed with its own twist during the iteration.
    min_share : float
        The least median share of the translation constraint that makes an axis observable.
    """

    ref_times: np.ndarray
    twist: Twist
    frame_twists: list[Twist]
    pair_twists: np.ndarray
    pair_poses: np.ndarray
    pair_se: np.ndarray
    information: np.ndarray
    share: np.ndarray
    min_eigenvalue: np.ndarray
    weakest_axis: np.ndarray
    hessian: np.ndarray
    observable: np.ndarray
    speed: float
    speed_spread: float
    speed_sem: float
    v_spread: np.ndarray
    residual_raw: np.ndarray
    residual: np.ndarray
    inliers: np.ndarray
    iterations: int
    converged: bool
    voxel: np.ndarray
    per_frame: bool
    min_share: float

    @property
    def compensable(self) -> bool:
        """True when translation is observable along all three axes and every pair registered."""
        return bool(self.observable.all()) and bool(np.isfinite(self.pair_twists).all())

    def frame_motion(self, k: int, *, force: bool = False) -> Twist:
        """The twist to de-skew frame ``k`` with (its own or the shared one, as estimated).

        Raises ``ValueError`` when the motion is not observable (see :attr:`observable`),
        unless ``force``: de-skewing with a twist the data do not determine moves points by
        a wrong amount, which is worse than leaving the cloud skewed.

        Parameters
        ----------
        k : int
            The frame's index.
        force : bool
            Return the twist even when the motion is not observable.

        Returns
        -------
        Twist
        """
        if not self.compensable and not force:
            axes = "".join(a for a, ok in zip("xyz", self.observable) if not ok)
            raise ValueError(f"ego-motion is not observable along {axes or 'some pair'} "
                             f"(median constraint share {np.median(self.share, axis=0).round(5)} "
                             f"< {self.min_share}); the clouds should not be de-skewed")
        return self.frame_twists[k] if self.per_frame else self.twist

    def summary(self) -> dict:
        """Plain-Python figures (for JSON or a log line)."""
        return {
            "speed_mps": self.speed,
            "speed_spread_mps": self.speed_spread,
            "speed_sem_mps": self.speed_sem,
            "v_mps": self.twist.v.tolist(),
            "w_radps": self.twist.w.tolist(),
            "v_spread_mps": self.v_spread.tolist(),
            "pair_speed_mps": np.linalg.norm(self.pair_twists[:, :3], axis=1).tolist(),
            "pair_v_mps": self.pair_twists[:, :3].tolist(),
            "pair_w_radps": self.pair_twists[:, 3:].tolist(),
            "pair_v_se_mps": self.pair_se[:, :3].tolist(),
            "share_xyz": self.share.tolist(),
            "median_share_xyz": np.median(self.share, axis=0).tolist(),
            "min_eigenvalue_per_m2": self.min_eigenvalue.tolist(),
            "weakest_axis": self.weakest_axis.tolist(),
            "observable_xyz": self.observable.tolist(),
            "compensable": self.compensable,
            "residual_raw_m": self.residual_raw.tolist(),
            "residual_m": self.residual.tolist(),
            "iterations": self.iterations,
            "converged": self.converged,
            "voxel_m": self.voxel.tolist(),
        }




def pair_residuals(clouds: Sequence[tuple[np.ndarray, np.ndarray]],
                   ref_times: Sequence[float] | np.ndarray, motions: Sequence[Motion],
                   pair_poses: np.ndarray, *, sample: int = 20000,
                   rng: np.random.Generator | int | None = 0) -> np.ndarray:
    """How well consecutive clouds overlap: median nearest-neighbour distance per pair (m).

    Cloud ``k`` is de-skewed to ``ref_times[k]`` with ``motions[k]``, a random sample of cloud
    ``k+1`` (de-skewed likewise) is moved by ``pair_poses[k]`` (``T(tau_k <- tau_k+1)``) and
    each sampled point's distance to its nearest neighbour in the whole of cloud ``k`` is taken.

    Parameters
    ----------
    clouds : sequence of (xyz (N, 3), t (N,))
    ref_times : sequence of float, length K
    motions : sequence of Motion, length K
        ``Twist.zero()`` for raw clouds.
    pair_poses : ndarray, shape (K-1, 4, 4)
    sample : int
        Points drawn from each source cloud.
    rng : Generator, int or None
        Randomness of the sample.

    Returns
    -------
    ndarray, shape (K-1,)
    """
    rng = np.random.default_rng(rng)
    out = np.empty(len(clouds) - 1)
    prev = None
    for k in range(len(clouds)):
        xyz, t = check_cloud(*clouds[k])
        pts = deskew(xyz, t, ref_times[k], motions[k])
        if prev is not None:                  # from k = 1 on: cloud k - 1's tree
            pick = rng.choice(len(pts), size=min(sample, len(pts)), replace=False)
            d, _ = prev.query(transform_points(pair_poses[k - 1], pts[pick]), k=1)
            out[k - 1] = float(np.median(d))
        if k < len(clouds) - 1:
            prev = kd_tree(pts)
    return out


def estimate_motion(  # noqa: PLR0913 - keyword-only options, each documented
        clouds: Sequence[tuple[np.ndarray, np.ndarray]], *,
        ref_times: Sequence[float] | None = None, per_frame: bool = False,
        initial: Twist | None = None, max_speed: float = 70.0,
        up: Sequence[float] = (0.0, 0.0, 1.0), points: int = 15000,
        max_passes: int = 10, tol: float = 1e-3, min_share: float = 0.02,
        residual_sample: int = 20000, k_normal: int = 12,
        seed: int | np.random.Generator | None = 0) -> MotionEstimate:
    """Estimate the ego-motion of a sweep sequence by de-skew-aware scan-to-scan registration.

    Parameters
    ----------
    clouds : sequence of (xyz (N, 3), t (N,))
        At least two consecutive sweeps in time order, points in metres in the cloud frame at
        their own times ``t`` (s). The clouds must have per-point times.
    ref_times : sequence of float, optional
        Reference time of each frame (s); default: each sweep's window centre.
    per_frame : bool
        De-skew each frame with its own twist (mean of its adjacent pairs) while iterating,
        instead of the shared mean twist. Use it when the speed changes along the sequence.
    initial : Twist, optional
        A prior twist (odometry, the previous estimate): seeds the registration instead of
        the coarse translation search.
    max_speed : float
        Largest speed considered by the coarse search (m/s); it sets the search radius
        ``max_speed * (tau_1 - tau_0)``.
    up : (3,) sequence
        The cloud frame's up axis: the coarse search runs in the plane normal to it.
    points : int
        Points kept per cloud for registration (a voxel subsample; the voxel edge follows
        from it and from the cloud's own extent). Coarser levels use 2x and 4x that voxel.
    max_passes : int
        Most de-skew / registration passes (the raw pass included).
    tol : float
        Stop when the largest change of the de-skew between passes, ``|dv| * sweep + |dw| *
        sweep * median range``, falls below ``tol`` metres.
    min_share : float
        Smallest median share of the translation constraint for an axis to count as
        observable (dimensionless, 0.02 = 2 %; see the module notes for measured shares).
    residual_sample : int
        Points sampled per cloud for the overlap residuals (0: skip them, NaN).
    k_normal : int
        Neighbours used for each target normal.
    seed : int, Generator or None
        Randomness of the voxel subsampling and of the residual sample.

    Returns
    -------
    MotionEstimate
    """
    if len(clouds) < 2:
        raise ValueError("motion estimation needs at least two consecutive clouds")
    rng = np.random.default_rng(seed)
    up_axis = np.asarray(up, dtype=np.float64)
    up_axis = up_axis / np.linalg.norm(up_axis)
    cl = [check_cloud(*c) for c in clouds]
    K = len(cl)
    if ref_times is None:
        tau = np.array([sweep_centre(t) for _, t in cl])
    else:
        tau = np.asarray(ref_times, dtype=np.float64).reshape(-1)
        if tau.shape != (K,):
            raise ValueError(f"{len(tau)} reference times for {K} clouds")
    dtau = np.diff(tau)
    if not (dtau > 0).all():
        raise ValueError("clouds must be in time order with distinct reference times")
    sweep = float(np.median([t.max() - t.min() for _, t in cl]))
    med_range = float(np.median([np.median(np.linalg.norm(x[:: max(1, len(x) // 5000)], axis=1))
                                 for x, _ in cl]))

    voxel = np.empty(K)
    levels = []       # per cloud: three (indices, neighbour graph) pairs, coarse to fine
    for k, (xyz, _) in enumerate(cl):
        voxel[k], lv = prepare_levels(xyz, points, rng)
        # Neighbourhoods are found once on the raw points: de-skewing is locally rigid (except
        # across the seam, where raw neighbours are far apart anyway), so the graph holds and
        # only the normals are recomputed from the de-skewed positions.
        levels.append([(i, neighbours(xyz[i], k_normal)) for i in lv])
    v_med = float(np.median(voxel))
    # Gates: a correspondence farther than 3 voxel edges of its level is not the same surface.
    gates = [12.0 * v_med, 6.0 * v_med, 3.0 * v_med]

    twists = [Twist.zero()] * K         # pass 0 registers the raw clouds
    poses = np.full((K - 1, 4, 4), np.nan)
    if initial is not None:
        for k in range(K - 1):
            poses[k] = initial.pose(dtau[k])
    pair_xi = np.full((K - 1, 6), np.nan)
    fits: list[PairFit | None] = [None] * (K - 1)
    residual_raw = np.full(K - 1, np.nan)
    converged = False
    passes = 0
    for passes in range(1, max_passes + 1):
        src_pts: list[list[np.ndarray | None]] = [
            [deskew(xyz[i], t[i], tau[k], twists[k]) if passes == 1 or lv == 2 else None
             for lv, (i, _) in enumerate(levels[k])] for k, (xyz, t) in enumerate(cl)]
        # After the first pass the pair poses move by little more than the change of the de-skew,
        # well inside the finest gate: the coarse levels are skipped.
        use = slice(0, 3) if passes == 1 else slice(2, 3)
        for k in range(K - 1):
            # Levels this pass skips stay None (the casts say what the pass structure holds).
            tgt: list[PlaneTarget | None] = [None] * 3
            for lv in range(3)[use]:
                tgt[lv] = plane_target(cast(np.ndarray, src_pts[k][lv]), levels[k][lv][1])
            if np.isfinite(poses[k]).all():
                T0 = poses[k]
            elif k > 0 and np.isfinite(pair_xi[k - 1]).all():
                # Constant velocity from the previous pair.
                T0 = Twist(pair_xi[k - 1, :3], pair_xi[k - 1, 3:]).pose(dtau[k])
            else:
                coarse = tgt[0]
                if coarse is None:
                    coarse = tgt[0] = plane_target(cast(np.ndarray, src_pts[k][0]),
                                                   levels[k][0][1])
                T0 = coarse_translation(cast(np.ndarray, src_pts[k + 1][0]), coarse, np.eye(4),
                                         max_speed * dtau[k], 4.0 * v_med, up_axis)
            fit = register_levels(cast(list[np.ndarray], src_pts[k + 1][use]),
                                  cast(list[PlaneTarget], tgt[use]), T0, gates[use], med_range)
            fits[k] = fit
            if fit is None:
                log.warning("motion: registration of clouds %d and %d failed", k, k + 1)
                poses[k] = np.nan
                pair_xi[k] = np.nan
                continue
            poses[k] = fit.T
            pair_xi[k] = se3_log(fit.T) / dtau[k]
        if passes == 1 and residual_sample > 0:
            ok = np.isfinite(poses).all(axis=(1, 2))
            if ok.any():
                rp = np.where(ok[:, None, None], poses, np.eye(4))
                residual_raw = pair_residuals(cl, tau, [Twist.zero()] * K, rp,
                                              sample=residual_sample, rng=rng)
                residual_raw[~ok] = np.nan
        if not np.isfinite(pair_xi).any():
            break
        shared_xi = np.nanmean(pair_xi, axis=0)
        new = (_frame_twists(pair_xi, np.isfinite(pair_xi).all(axis=1), shared_xi) if per_frame
               else [Twist(shared_xi[:3], shared_xi[3:])] * K)
        change = max(np.linalg.norm(a.v - b.v) * sweep + np.linalg.norm(a.w - b.w) * sweep * med_range
                     for a, b in zip(new, twists))
        twists = new
        log.debug("motion pass %d: speed %.3f m/s, de-skew change %.4f m", passes,
                  np.linalg.norm(shared_xi[:3]), change)
        if change < tol:
            converged = True
            break

    ok = np.array([f is not None for f in fits])
    info, share, min_eig, weakest, hess, se, inl = _pair_conditioning(fits, dtau)
    observable = np.median(share[ok], axis=0) >= min_share if ok.any() else np.zeros(3, bool)
    good = pair_xi[ok]
    speeds = np.linalg.norm(good[:, :3], axis=1)
    n = len(speeds)
    spread = float(np.std(speeds, ddof=1)) if n > 1 else float("nan")
    residual = (pair_residuals(cl, tau, twists, np.where(ok[:, None, None], poses, np.eye(4)),
                               sample=residual_sample, rng=rng)
                if ok.any() and residual_sample > 0 else np.full(K - 1, np.nan))
    residual[~ok] = np.nan
    shared = np.nanmean(pair_xi, axis=0) if ok.any() else np.zeros(6)
    frame_tw = _frame_twists(pair_xi, ok, shared)
    est = MotionEstimate(
        ref_times=tau, twist=Twist(shared[:3], shared[3:]), frame_twists=frame_tw,
        pair_twists=pair_xi, pair_poses=poses, pair_se=se, information=info, share=share,
        min_eigenvalue=min_eig, weakest_axis=weakest, hessian=hess, observable=observable,
        speed=float(speeds.mean()) if n else float("nan"), speed_spread=spread,
        speed_sem=spread / math.sqrt(n) if n > 1 else float("nan"),
        v_spread=np.std(good[:, :3], axis=0, ddof=1) if n > 1 else np.full(3, np.nan),
        residual_raw=residual_raw, residual=residual, inliers=inl, iterations=passes,
        converged=converged, voxel=voxel, per_frame=per_frame, min_share=min_share)
    if not est.compensable:
        log.warning("motion: not observable along %s (median constraint share %s < %g); "
                    "do not de-skew with this estimate",
                    "".join(a for a, o in zip("xyz", observable) if not o) or "-",
                    np.round(np.median(share[ok], axis=0), 5) if ok.any() else "n/a", min_share)
    return est


def _frame_twists(pair_xi: np.ndarray, ok: np.ndarray, shared: np.ndarray) -> list[Twist]:
    """Each frame's twist: the mean of its adjacent pairs' twists that are ``ok`` (K - 1,), or
    ``shared`` (6,) when it has none; ``pair_xi`` is (K - 1, 6)."""
    K = len(pair_xi) + 1
    out = []
    for k in range(K):
        rows = [pair_xi[j] for j in (k - 1, k) if 0 <= j < K - 1 and ok[j]]
        xi = np.mean(rows, axis=0) if rows else shared
        out.append(Twist(xi[:3], xi[3:]))
    return out


def _pair_conditioning(fits: list, dtau: np.ndarray):
    """Per registered pair: information and constraint share per axis, smallest eigenvalue and
    weakest direction of the translation Hessian, the Hessian, standard errors of the twist
    (per second) and inliers; zeros (and infinite errors) for a failed pair."""
    P = len(fits)
    info, share = np.zeros((P, 6)), np.zeros((P, 3))
    min_eig, weakest = np.zeros(P), np.zeros((P, 3))
    hess, se = np.zeros((P, 6, 6)), np.full((P, 6), np.inf)
    inl = np.zeros(P, dtype=int)
    for k, f in enumerate(fits):
        if f is None:
            continue
        hess[k] = f.H
        info[k], share[k], vals, vecs = conditioning(f.H)
        min_eig[k] = vals[0]
        weakest[k] = vecs[:, 0] * np.sign(vecs[np.argmax(np.abs(vecs[:, 0])), 0])
        with np.errstate(divide="ignore"):
            se[k] = 1.0 / np.sqrt(info[k]) / dtau[k]
        inl[k] = f.inliers
    return info, share, min_eig, weakest, hess, se, inl


# ----------------------------------------------------------------------------- time offset

@dataclass
class TimeOffsetEstimate:
    """Result of :func:`estimate_time_offset`.

    Attributes
    ----------
    offset : float
        Best image-time offset (s) from each sweep's centre, parabola-refined when possible.
    offsets : ndarray, shape (M,)
        The grid of offsets scored (s).
    scores : ndarray, shape (M,)
        The score at each offset (lower is better).
    refined : bool
        Whether the parabola through the minimum and its two neighbours refined ``offset``
        (False at the edge of the grid or for a flat / concave triple).
    at_edge : bool
        The grid minimum lies on the first or last offset: widen the grid.
    """

    offset: float
    offsets: np.ndarray
    scores: np.ndarray
    refined: bool
    at_edge: bool


def estimate_time_offset(clouds: Sequence[tuple[np.ndarray, np.ndarray]],
                         motion: Motion | Sequence[Motion] | MotionEstimate,
                         score: Callable[[list[np.ndarray]], float], *,
                         half_width: float = 0.060, step: float | None = None,
                         centres: Sequence[float] | None = None) -> TimeOffsetEstimate:
    """Find the image time relative to the sweep centres by scanning a 1-D grid of offsets.

    For each offset ``d`` every cloud ``k`` is de-skewed to ``centres[k] + d`` and the caller's
    ``score`` (its calibration objective, lower is better) is evaluated on the list; the grid
    minimum is refined with a parabola through it and its two neighbours.

    Parameters
    ----------
    clouds : sequence of (xyz (N, 3), t (N,))
        Points in metres and per-point times in seconds.
    motion : Motion, sequence of Motion, or MotionEstimate
        One motion for all clouds, one per cloud, or an estimate of this sequence (its
        :meth:`MotionEstimate.frame_motion` for each cloud, which refuses an unobservable one).
    score : callable
        ``score(list of (N_k, 3) arrays) -> float``.
    half_width : float
        The grid spans ``[-half_width, +half_width]`` seconds.
    step : float, optional
        Grid step (s); default: the median sweep duration / 20 (5 ms for a 10 Hz LiDAR).
    centres : sequence of float, optional
        Per-cloud time the offset is counted from; default: each sweep's window centre.

    Returns
    -------
    TimeOffsetEstimate
    """
    cl = [check_cloud(*c) for c in clouds]
    if not cl:
        raise ValueError("no clouds")
    motions: list[Motion]
    if isinstance(motion, MotionEstimate):
        motions = [motion.frame_motion(k) for k in range(len(cl))]
    elif isinstance(motion, Sequence):
        motions = list(motion)
    else:
        motions = [motion] * len(cl)
    if len(motions) != len(cl):
        raise ValueError(f"{len(motions)} motions for {len(cl)} clouds")
    if centres is None:
        centres = [sweep_centre(t) for _, t in cl]
    if step is None:
        step = float(np.median([t.max() - t.min() for _, t in cl])) / 20.0
    if not step > 0 or not half_width >= 0:
        raise ValueError(f"need step > 0 and half_width >= 0, got {step}, {half_width}")
    n = int(math.floor(half_width / step + 1e-9))
    offsets = np.arange(-n, n + 1) * step
    scores = np.array([float(score([deskew(x, t, c + d, m) for (x, t), c, m in zip(cl, centres, motions)]))
                       for d in offsets])
    i = int(np.nanargmin(scores))
    best = float(offsets[i])
    at_edge = i in (0, len(offsets) - 1)
    refined = False
    if not at_edge:
        s0, s1, s2 = scores[i - 1], scores[i], scores[i + 1]
        curv = s0 - 2.0 * s1 + s2
        if np.isfinite(curv) and curv > 0:
            best += 0.5 * step * (s0 - s2) / curv
            refined = True
    return TimeOffsetEstimate(best, offsets, scores, refined, at_edge)
