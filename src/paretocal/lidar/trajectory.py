"""The motions of a LiDAR frame (a twist, a pose trajectory), their SE(3) algebra, and
de-skewing a sweep to one time.

A spinning LiDAR that moves while it turns stores each point in the sensor (or vehicle) frame
*at the time the point was measured*. A camera image is exposed at one time. Before a cloud is
compared with an image, every point must be expressed in the frame at the image time: that is
de-skewing, and it needs the motion of the frame during the sweep.

Conventions
-----------
* ``F(t)`` is the cloud's frame (sensor or vehicle body, whichever the points are stored in) at
  time ``t`` (seconds, on the clock of the per-point times).
* A *motion* maps coordinates in ``F(t)`` to coordinates in ``F(t_ref)``: a point observed at
  time ``t`` with coordinates ``p`` in ``F(t)`` has coordinates ``p' = T(t_ref <- t) p`` in
  ``F(t_ref)``. :func:`deskew` applies it to every point with its own ``t``.
* A :class:`Twist` is a constant body twist: linear velocity ``v`` (m/s) and angular velocity
  ``w`` (rad/s), both expressed in the moving frame itself. The frame's pose after ``dt``
  seconds, in the frame at the start, is ``exp(dt [v, w])`` (exact SE(3) exponential), so
  ``T(t_ref <- t) = exp((t - t_ref) [v, w])``. For pure forward motion at speed ``s`` along
  +x this is ``x' = x + s (t - t_ref)``, ``y' = y``, ``z' = z``: a static object ahead is seen
  nearer later in the sweep, and de-skewing to an earlier ``t_ref`` pushes late points forward.
* A :class:`PoseTrajectory` holds poses ``T_world_cloud`` (4x4, the frame's pose in a fixed
  world frame) at known times, interpolated by SLERP (rotation) and linearly (translation);
  ``T(t_ref <- t) = T_world_cloud(t_ref)^-1 T_world_cloud(t)``.

Per-point times are taken as given (a Hesai Pandar64 quantises them to about 166 us; the
rotation direction does not matter because every point carries its own time). A point's time
lies in ``[min(t), max(t)]`` of its own cloud by construction; ``t_ref`` may lie anywhere (an
image exposed outside the sweep window is fine, the constant-twist model then extrapolates).
Clouds without per-point times (KITTI ``.bin`` sweeps, for example) cannot be de-skewed: the
caller checks for a time column and skips de-skewing when there is none; these functions
raise ``ValueError`` on missing or non-finite times.

:mod:`paretocal.lidar.motion` estimates the motion from the sweeps;
:mod:`paretocal.lidar.registration` registers one rigid cloud onto another.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

__all__ = ["Motion", "PoseTrajectory", "Twist", "check_cloud", "cross_rows", "deskew",
           "se3_exp", "se3_log", "se3_matrix", "sweep_centre"]


# ----------------------------------------------------------------------------- SE(3) algebra

def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (N, 3) arrays (np.cross without its overhead checks)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def se3_exp(rho: np.ndarray, phi: np.ndarray) -> tuple[Rotation, np.ndarray]:
    """Exact SE(3) exponential of twists ``[rho, phi]`` (m, rad), shape (N, 3) each.

    Returns the rotation (N) and the translation ``V(phi) rho`` (N, 3), with
    ``V = I + A [phi]x + B [phi]x^2``, ``A = (1 - cos a) / a^2``, ``B = (a - sin a) / a^3``.
    """
    a2 = np.einsum("ij,ij->i", phi, phi)
    a = np.sqrt(a2)
    small = a < 1e-4
    safe = np.where(small, 1.0, a)
    # Taylor series below 1e-4 rad: the closed forms lose all digits there.
    A = np.where(small, 0.5 - a2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    B = np.where(small, 1.0 / 6.0 - a2 / 120.0, (safe - np.sin(safe)) / (safe ** 3))
    c1 = cross_rows(phi, rho)
    trans = rho + A[:, None] * c1 + B[:, None] * cross_rows(phi, c1)
    return Rotation.from_rotvec(phi), trans


def se3_log(T: np.ndarray) -> np.ndarray:
    """SE(3) logarithm of a 4x4 transform: the twist ``[rho, phi]``, shape (6,)."""
    phi = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    a2 = float(phi @ phi)
    a = math.sqrt(a2)
    if a < 1e-4:
        c = 1.0 / 12.0 + a2 / 720.0
    else:
        c = (1.0 - a * math.sin(a) / (2.0 * (1.0 - math.cos(a)))) / a2
    K = np.array([[0.0, -phi[2], phi[1]], [phi[2], 0.0, -phi[0]], [-phi[1], phi[0], 0.0]])
    Vinv = np.eye(3) - 0.5 * K + c * (K @ K)
    return np.concatenate([Vinv @ T[:3, 3], phi])


def se3_matrix(R: Rotation, t: np.ndarray) -> np.ndarray:
    """The 4x4 transform of a rotation and a translation (3,) in metres."""
    T = np.eye(4)
    T[:3, :3] = R.as_matrix()
    T[:3, 3] = t
    return T

# ----------------------------------------------------------------------------- motions

class Motion(Protocol):
    """Anything :func:`deskew` can use: maps ``F(t)`` coordinates into ``F(t_ref)``."""

    def relative(self, t: np.ndarray, t_ref: float) -> tuple[Rotation, np.ndarray]:
        """Rotations (N) and translations (N, 3) of ``T(t_ref <- t)`` for times ``t`` (N,).

        Parameters
        ----------
        t : ndarray, shape (N,)
            Times (s), on the clock of the per-point times.
        t_ref : float
            The reference time (s).

        Returns
        -------
        R : scipy.spatial.transform.Rotation
            N rotations.
        p : ndarray, shape (N, 3)
            Translations (m).
        """
        ...


@dataclass(frozen=True)
class Twist:
    """A constant body twist over the sweep.

    Attributes
    ----------
    v : ndarray, shape (3,)
        Linear velocity of the frame in m/s, expressed in the frame itself.
    w : ndarray, shape (3,)
        Angular velocity in rad/s, expressed in the frame itself (``w[2]`` is the yaw rate
        when z is up; positive turns left for x forward, y left).
    """

    v: np.ndarray
    w: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self):
        for name in ("v", "w"):
            a = np.array(getattr(self, name), dtype=np.float64).reshape(-1)
            if a.shape != (3,) or not np.isfinite(a).all():
                raise ValueError(f"Twist.{name} must be 3 finite numbers, got {getattr(self, name)!r}")
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @classmethod
    def zero(cls) -> Twist:
        """No motion."""
        return cls(np.zeros(3), np.zeros(3))

    @classmethod
    def from_pose(cls, T: np.ndarray, dt: float) -> Twist:
        """The constant twist that moves the frame by ``T`` (4x4, ``F(t0) <- F(t0 + dt)``) in
        ``dt`` seconds.

        Parameters
        ----------
        T : ndarray, shape (4, 4)
            The motion over ``dt`` (m).
        dt : float
            Its duration (s), non-zero.

        Returns
        -------
        Twist
        """
        if not dt:
            raise ValueError("Twist.from_pose needs a non-zero time step")
        xi = se3_log(np.asarray(T, dtype=np.float64)) / dt
        return cls(xi[:3], xi[3:])

    @property
    def vector(self) -> np.ndarray:
        """``[vx, vy, vz, wx, wy, wz]`` (m/s, rad/s), shape (6,)."""
        return np.concatenate([self.v, self.w])

    @property
    def speed(self) -> float:
        """``|v|`` in m/s."""
        return float(np.linalg.norm(self.v))

    def pose(self, dt: float) -> np.ndarray:
        """``T(t <- t + dt)``, 4x4: the frame's pose ``dt`` seconds later in the earlier frame.

        Parameters
        ----------
        dt : float
            Seconds.

        Returns
        -------
        ndarray, shape (4, 4)
        """
        R, t = se3_exp(dt * self.v[None], dt * self.w[None])
        return se3_matrix(R[0], t[0])

    def relative(self, t: np.ndarray, t_ref: float) -> tuple[Rotation, np.ndarray]:
        """Rotations (N) and translations (N, 3) of ``T(t_ref <- t)`` for times ``t`` (N,).

        Parameters
        ----------
        t : ndarray, shape (N,)
            Times (s).
        t_ref : float
            The reference time (s).

        Returns
        -------
        R : scipy.spatial.transform.Rotation
            N rotations.
        p : ndarray, shape (N, 3)
            Translations (m).
        """
        dt = np.asarray(t, dtype=np.float64).reshape(-1) - float(t_ref)
        return se3_exp(dt[:, None] * self.v, dt[:, None] * self.w)


class PoseTrajectory:
    """User-supplied poses of the cloud frame, interpolated in time.

    Rotation is interpolated by SLERP and translation linearly between the two enclosing
    poses. Times outside ``[times[0], times[-1]]`` raise ``ValueError`` (no extrapolation).

    Parameters
    ----------
    times : array_like, shape (M,)
        Strictly increasing times in seconds, on the clock of the per-point times; M >= 2.
    poses : array_like, shape (M, 4, 4)
        ``T_world_cloud``: the cloud frame's pose in any fixed world frame at each time.
    """

    def __init__(self, times, poses):
        times = np.asarray(times, dtype=np.float64).reshape(-1)
        poses = np.asarray(poses, dtype=np.float64)
        if poses.shape != (len(times), 4, 4):
            raise ValueError(f"poses must have shape ({len(times)}, 4, 4) to match {len(times)} "
                             f"times, got {poses.shape}")
        if len(times) < 2:
            raise ValueError("a pose trajectory needs at least 2 poses")
        if not (np.isfinite(times).all() and np.isfinite(poses).all()):
            raise ValueError("pose times and poses must be finite")
        if not (np.diff(times) > 0).all():
            raise ValueError("pose times must be strictly increasing")
        self.times = times
        self.poses = poses
        self._slerp = Slerp(times, Rotation.from_matrix(poses[:, :3, :3]))

    def pose_at(self, t) -> tuple[Rotation, np.ndarray]:
        """``T_world_cloud`` at times ``t`` (N,): rotations (N) and translations (N, 3).

        Parameters
        ----------
        t : array_like, shape (N,)
            Times (s), within the trajectory's.

        Returns
        -------
        R : scipy.spatial.transform.Rotation
            N rotations.
        p : ndarray, shape (N, 3)
            Translations (m).
        """
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        lo, hi = self.times[0], self.times[-1]
        if len(t) and (t.min() < lo or t.max() > hi):
            raise ValueError(f"times {t.min():.6f} .. {t.max():.6f} s fall outside the pose "
                             f"trajectory {lo:.6f} .. {hi:.6f} s")
        trans = np.stack([np.interp(t, self.times, self.poses[:, i, 3]) for i in range(3)], axis=1)
        return self._slerp(t), trans

    def relative(self, t: np.ndarray, t_ref: float) -> tuple[Rotation, np.ndarray]:
        """Rotations (N) and translations (N, 3) of ``T(t_ref <- t)`` for times ``t`` (N,).

        Parameters
        ----------
        t : ndarray, shape (N,)
            Times (s), within the trajectory's.
        t_ref : float
            The reference time (s), within the trajectory's.

        Returns
        -------
        R : scipy.spatial.transform.Rotation
            N rotations.
        p : ndarray, shape (N, 3)
            Translations (m).
        """
        R_t, p_t = self.pose_at(t)
        R_r, p_r = self.pose_at([t_ref])
        inv = R_r.inv()
        return inv * R_t, inv.apply(p_t - p_r[0])


def check_cloud(xyz, t) -> tuple[np.ndarray, np.ndarray]:
    """``xyz`` (N, 3) and per-point times ``t`` (N,) in seconds as float64 arrays; ValueError
    when the shapes disagree or a time is missing or not finite."""
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {xyz.shape}")
    if t is None:
        raise ValueError("the cloud has no per-point time: it cannot be de-skewed")
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if t.shape != (len(xyz),):
        raise ValueError(f"{len(t)} times for {len(xyz)} points")
    if not np.isfinite(t).all():
        raise ValueError("per-point times must be finite")
    return xyz, t


def sweep_centre(t: np.ndarray) -> float:
    """Centre of a sweep's time window, ``(min(t) + max(t)) / 2``, in seconds.

    Parameters
    ----------
    t : ndarray, shape (N,)
        The sweep's per-point times (s).

    Returns
    -------
    float
    """
    t = np.asarray(t, dtype=np.float64)
    return 0.5 * (float(t.min()) + float(t.max()))


def deskew(xyz: np.ndarray, t: np.ndarray, t_ref: float, motion: Motion) -> np.ndarray:
    """Express every point in the frame at time ``t_ref``.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Points in metres, each in the frame ``F(t_i)`` at its own time.
    t : ndarray, shape (N,)
        Per-point times in seconds (finite; a cloud without them cannot be de-skewed).
    t_ref : float
        Target time in seconds, on the same clock (inside the sweep or not).
    motion : Twist, PoseTrajectory or any :class:`Motion`
        Gives ``T(t_ref <- t)``; for a :class:`Twist` that is ``exp((t - t_ref) [v, w])``, so
        pure forward motion at speed ``s`` along +x gives ``x' = x + s (t - t_ref)``.

    Returns
    -------
    ndarray, shape (N, 3), float64
        The points in ``F(t_ref)``.
    """
    xyz, t = check_cloud(xyz, t)
    if len(xyz) == 0:
        return xyz.copy()
    R, trans = motion.relative(t, float(t_ref))
    return R.apply(xyz) + trans

