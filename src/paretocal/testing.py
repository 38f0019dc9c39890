"""Rig variants of a real sweep, for tests and benchmarks (nothing is stored: made at run time).

A KITTI HDL-64E sweep in KITTI's storage order carries its exact ring index (one laser after
another, :func:`~paretocal.lidar.rings.rings_from_scan_order`). From it this module makes
clouds as other rigs record them, each with its exact truth:

* fewer beams (every 2nd or 4th ring by elevation: 32 and 16 beams, 0.8 / 1.7 deg apart);
* firing (column-major) order, as Velodyne/Hesai/Ouster drivers write it, and shuffled order;
* packet order with per-laser azimuth offsets, as an HDL-64E S2/S3 or Pandar64 driver writes
  it (each column's lasers fire at one encoder angle but point several degrees apart);
* stored in a vehicle frame, the sensor 1-2 m from the origin and slightly tilted;
* per-point time as a 10 Hz spinning sensor would stamp it;
* motion-compensated into the frame of one instant while the vehicle drove and pitched
  (returns then lie on their lasers' cones only near the azimuth scanned at that instant).

A cloud without a ring field (PandaSet's Pandar64 sweeps) gets its truth from the project's
own ring recovery instead (:func:`recovered_truth`): a truth only as good as that recovery,
checked by its line-model purity, against which the variants of the same sweep are compared.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .lidar.rings import (MIN_PURITY, MIN_RINGS, azimuth, fit_ring_lines, recover_rings,
                             ring_order, rings_from_scan_order)
from .geometry import invert, rotation_zyx, transform_points

#: Azimuth width of one firing column (deg) in :func:`firing_order`: an HDL-64E at 10 Hz.
COLUMN_DEG = 0.17
#: Per-laser azimuth offsets of :func:`packet_order` are drawn uniform in +- this (deg). The
#: lasers of one firing column do not point at one azimuth: a Pandar64's nominal offsets are
#: +-1.04, +-3.13 and +-5.21 deg, an HDL-64E's rotational corrections (``rotCorrection`` in
#: its calibration file) a few degrees either way; 8 deg spans both with room.
AZIMUTH_OFFSET_DEG = 8.0


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
    """Keep every ``keep_every``-th ring by elevation (64 -> 32 with 2, -> 16 with 4); points
    without a ring (-1, see :func:`recovered_truth`) are dropped."""
    keep = np.flatnonzero((v.ring >= 0) & (v.ring % keep_every == 0))
    out = _take(v, keep)
    out.ring = out.ring // keep_every
    return out


def firing_order(v: Variant) -> Variant:
    """Column-major order: by azimuth column, then laser from the top down."""
    col = np.floor(azimuth(v.points) / np.radians(COLUMN_DEG)).astype(np.int64)
    return _take(v, np.lexsort((v.ring, col)))


def sensor_azimuth(v: Variant) -> np.ndarray:
    """Azimuth of every point about the sensor's own axis, in [0, 2 pi), shape (N,) (rad).

    Measured from the x axis of ``v.sensor_pose``: a cloud stored in a vehicle frame is
    brought into the sensor's frame first."""
    if np.allclose(v.sensor_pose, np.eye(4)):
        return azimuth(v.points)
    return azimuth(transform_points(invert(v.sensor_pose), v.points.astype(np.float64)))


def packet_order(v: Variant, offsets_deg: np.ndarray | None = None,
                 rng: np.random.Generator | int | None = 0) -> Variant:
    """The storage order of a sensor that writes its points packet by packet, each laser
    with its own azimuth offset (an HDL-64E S2/S3 or Pandar64 driver).

    In one firing column every laser fires at the same encoder angle ``psi_enc``, but laser
    ``k`` points at ``psi_enc + delta_k``. A return at azimuth ``psi`` (about the sensor's
    axis) was therefore fired in column ``round((psi - delta_k) / COLUMN_DEG)``. Points are
    ordered by that column, then by laser (``v.ring``) within the column: consecutive points
    jump between elevations and, by the offsets, between azimuths up to twice
    :data:`AZIMUTH_OFFSET_DEG` apart, so the file's order tells neither the ring nor the
    azimuth. Coordinates (and the truth's times) are unchanged.

    Parameters
    ----------
    v : Variant
        The sweep, N points with their rings (``ring`` is taken as the laser id).
    offsets_deg : ndarray, shape (R,), optional
        ``delta_k`` (deg) of each laser ``k`` (R more than the largest ring). By default
        drawn once per laser from ``rng``, uniform in +- :data:`AZIMUTH_OFFSET_DEG`.
    rng : numpy Generator or seed
        Draws the default offsets.

    Returns
    -------
    Variant
        The same N points in packet order.
    """
    lasers = int(v.ring.max()) + 1 if len(v.ring) else 0
    if offsets_deg is None:
        offsets_deg = np.random.default_rng(rng).uniform(-AZIMUTH_OFFSET_DEG,
                                                         AZIMUTH_OFFSET_DEG, lasers)
    delta = np.radians(np.asarray(offsets_deg, dtype=np.float64))
    if delta.shape != (lasers,):
        raise ValueError(f"offsets_deg has shape {delta.shape}; expected ({lasers},), one "
                         "per laser")
    # Returns that no ring claims (ring -1) keep their azimuth: offset 0.
    enc = sensor_azimuth(v) - np.where(v.ring >= 0, delta[np.maximum(v.ring, 0)], 0.0)
    col = np.round(np.mod(enc, 2 * np.pi) / np.radians(COLUMN_DEG)).astype(np.int64)
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


def recovered_truth(points: np.ndarray, sensor_pose: np.ndarray,
                    rng: np.random.Generator | int | None = 0,
                    time: np.ndarray | None = None,
                    view: np.ndarray | None = None) -> Variant:
    """A sweep without a ring field (PandaSet's Pandar64) with rings recovered by the
    project's own :func:`~paretocal.lidar.rings.recover_rings` in the sensor's frame, as
    the truth its variants are compared with.

    The truth is the recovery's, not the sensor's: it is only as right as the line model's
    fit, which its purity checks (a sweep whose recovered rings are not plausible is
    refused). Compared with the same sweep in another order or decimated, it says whether
    the recovery depends on the order or the beam count, not whether it finds the lasers.

    Parameters
    ----------
    points : ndarray, shape (N, 4)
        The sweep in the cloud's own frame (x, y, z in metres, intensity), its stored order.
    sensor_pose : ndarray, shape (4, 4)
        The LiDAR's pose in the cloud's frame (cloud <- sensor): identity for a cloud in the
        sensor's frame, otherwise where the tool locates it
        (:func:`paretocal.inputs.locate_lidar`) or a dataset's documented pose.
    rng : numpy Generator or seed
        For the recovery's subsample.
    time : ndarray, shape (N,), optional
        The file's per-point time (s); else from the azimuth as for :func:`kitti_truth`.
    view : ndarray, shape (N,), bool, optional
        The returns near a camera's view (:func:`~paretocal.features.prepare.view_mask`):
        the rings are judged there, as the tool judges them. A sweep motion-compensated into
        one instant (PandaSet once the car moves) fits its lasers' cones only near the
        azimuth scanned then; elsewhere its truth may be wrong or -1.

    Returns
    -------
    Variant
        The points as given (in the cloud's frame), ``ring`` the recovered ring (-1 for the
        returns the recovery assigns to none: near the axis, or off every line), and
        ``sensor_pose``.

    Raises
    ------
    ValueError
        When the recovered rings are not plausible (fewer than
        :data:`~paretocal.lidar.rings.MIN_RINGS` rings or purity below
        :data:`~paretocal.lidar.rings.MIN_PURITY`).
    """
    pts = np.asarray(points, dtype=np.float32)
    P = np.asarray(sensor_pose, dtype=np.float64)
    local = transform_points(invert(P), pts.astype(np.float64))
    r = recover_rings(local, rng=rng, view=view)
    if r.n_rings < MIN_RINGS or r.purity < MIN_PURITY:
        raise ValueError(f"recovered rings not plausible: {r.n_rings} rings ({r.method}), "
                         f"purity {r.purity:.3f}; {'; '.join(r.notes)}")
    t = (np.mod(np.pi - azimuth(local), 2 * np.pi) / (2 * np.pi) * 0.1 if time is None
         else np.asarray(time, dtype=np.float64))
    return Variant(pts, r.ring.astype(np.int64), t, P)


def ring_accuracy(found: np.ndarray, truth: np.ndarray) -> float:
    """Share of points whose found ring is their true ring, both numbered top first.

    Found rings are matched to true rings one to one by their ranks (a method that misses or
    splits a ring shifts every ring below it, and that counts as wrong)."""
    found = np.asarray(found)
    truth = np.asarray(truth)
    return float(np.mean(found == truth))
