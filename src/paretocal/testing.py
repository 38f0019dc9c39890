"""Rig variants of a real sweep, for tests and benchmarks (nothing is stored: made at run time).

A KITTI HDL-64E sweep in KITTI's storage order carries its exact ring index (one laser after
another, :func:`~paretocal.features.rings.rings_from_scan_order`). From it this module makes
clouds as other rigs record them, each with its exact truth:

* fewer beams (every 2nd or 4th ring by elevation: 32 and 16 beams, 0.8 / 1.7 deg apart);
* firing (column-major) order, as Velodyne/Hesai/Ouster drivers write it, and shuffled order;
* stored in a vehicle frame, the sensor 1-2 m from the origin and slightly tilted;
* per-point time as a 10 Hz spinning sensor would stamp it;
* motion-compensated into the frame of one instant while the vehicle drove and pitched
  (returns then lie on their lasers' cones only near the azimuth scanned at that instant).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .features.rings import azimuth, fit_ring_lines, ring_order, rings_from_scan_order
from .geometry import rotation_zyx, transform_points

#: Azimuth width of one firing column (deg) in :func:`firing_order`: an HDL-64E at 10 Hz.
COLUMN_DEG = 0.17


@dataclass
class Variant:
    """A cloud and its exact truth.

    Attributes
    ----------
    points : ndarray, shape (N, 4), float32
    ring : ndarray, shape (N,), int64
        True ring, numbered by elevation from the top (0 = highest laser).
    time : ndarray, shape (N,), float64
        Seconds since the start of the sweep (azimuth / rotation rate).
    sensor_pose : ndarray, shape (4, 4)
        The sensor's pose in the cloud's frame (identity unless moved to a vehicle frame).
    """

    points: np.ndarray
    ring: np.ndarray
    time: np.ndarray
    sensor_pose: np.ndarray


def kitti_truth(points: np.ndarray) -> Variant:
    """A KITTI-order sweep with its rings numbered by elevation (top first) and sweep times."""
    pts = np.asarray(points, dtype=np.float32)
    scan = rings_from_scan_order(pts)
    d = np.hypot(pts[:, 0], pts[:, 1]).astype(np.float64)
    ok = d > 0.5
    a, h, _ = fit_ring_lines(pts[ok, 2] / d[ok], 1.0 / d[ok], scan[ok], int(scan.max()) + 1)
    rank = np.empty(len(a), dtype=np.int64)
    rank[ring_order(a, h)] = np.arange(len(a))
    # A clockwise-spinning sensor starting behind the vehicle, 0.1 s per revolution.
    t = np.mod(np.pi - azimuth(pts), 2 * np.pi) / (2 * np.pi) * 0.1
    return Variant(pts, rank[scan], t, np.eye(4))


def _take(v: Variant, idx: np.ndarray) -> Variant:
    return Variant(v.points[idx], v.ring[idx], v.time[idx], v.sensor_pose)


def decimate(v: Variant, keep_every: int) -> Variant:
    """Keep every ``keep_every``-th ring by elevation (64 -> 32 with 2, -> 16 with 4)."""
    keep = np.flatnonzero(v.ring % keep_every == 0)
    out = _take(v, keep)
    out.ring = out.ring // keep_every
    return out


def firing_order(v: Variant) -> Variant:
    """Column-major order: by azimuth column, then laser from the top down."""
    col = np.floor(azimuth(v.points) / np.radians(COLUMN_DEG)).astype(np.int64)
    return _take(v, np.lexsort((v.ring, col)))


def shuffled(v: Variant, rng: np.random.Generator | int | None = 0) -> Variant:
    """A random order."""
    return _take(v, np.random.default_rng(rng).permutation(len(v.points)))


def vehicle_pose(offset_m=(1.2, 0.3, 0.9), ypr_deg=(90.0, 0.8, -0.5)) -> np.ndarray:
    """A sensor pose in a vehicle frame (4, 4): 1.5 m from the origin by default, turned and
    slightly tilted (the cloud's z is no longer the spinning axis)."""
    P = np.eye(4)
    P[:3, :3] = rotation_zyx(*ypr_deg)
    P[:3, 3] = offset_m
    return P


def to_vehicle_frame(v: Variant, pose: np.ndarray | None = None) -> Variant:
    """The same sweep expressed in a vehicle frame where the sensor sits at ``pose``."""
    P = vehicle_pose() if pose is None else np.asarray(pose, dtype=np.float64)
    pts = v.points.astype(np.float64)
    xyz = transform_points(P, pts)
    out = np.column_stack([xyz, pts[:, 3]]).astype(np.float32)
    return Variant(out, v.ring.copy(), v.time.copy(), P @ v.sensor_pose)


def compensated(v: Variant, speed_mps: float = 3.0, pitch_dps: float = 3.0,
                azimuth_deg: float = 0.0) -> Variant:
    """The sweep as a dataset stores it after motion compensation: every return moved into
    the sensor's frame at the instant the sweep passed ``azimuth_deg`` (a camera's view),
    while the sensor drove forward (x) at ``speed_mps`` and pitched at ``pitch_dps``. A return
    recorded ``dt`` seconds from that instant moves by ``speed * dt`` and turns by
    ``pitch * dt``: seen from the sensor's origin at the instant, it leaves its laser's cone
    unless it was recorded near it."""
    psi0 = np.radians(azimuth_deg)
    # Signed sweep time from the instant, within half a revolution either way (0.1 s a turn).
    dt = -(np.mod(azimuth(v.points) - psi0 + np.pi, 2 * np.pi) - np.pi) / (2 * np.pi) * 0.1
    pts = v.points.astype(np.float64)
    out = pts.copy()
    for k in np.unique(np.round(dt, 4)):                 # one rigid motion per 0.1 ms
        sel = np.round(dt, 4) == k
        R = rotation_zyx(0.0, pitch_dps * k, 0.0)
        out[sel, :3] = pts[sel, :3] @ R.T + np.array([speed_mps * k, 0.0, 0.0])
    return Variant(out.astype(np.float32), v.ring.copy(), v.time.copy(), v.sensor_pose)


def ring_accuracy(found: np.ndarray, truth: np.ndarray) -> float:
    """Share of points whose found ring is their true ring, both numbered top first.

    Found rings are matched to true rings one to one by their ranks (a method that misses or
    splits a ring shifts every ring below it, and that counts as wrong)."""
    found = np.asarray(found)
    truth = np.asarray(truth)
    return float(np.mean(found == truth))
