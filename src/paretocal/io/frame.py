"""The unit of input: one camera image paired with one LiDAR sweep."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..camera import Camera
from .board import Board


@dataclass(eq=False)
class Frame:
    """One synchronised camera image and LiDAR sweep.

    Attributes
    ----------
    name : str
        The frame's stem (file name without extension), unique within a source.
    image : ndarray, shape (H, W, 3), uint8
        Colour image as taken (not undistorted), BGR channel order (OpenCV's).
    points : ndarray, shape (N, 4), float32
        LiDAR points ``x, y, z`` in metres in the LiDAR frame and intensity (reflectance).
    camera : Camera
        Intrinsics of ``image`` with its lens model (pinhole with distortion, fisheye, Mei):
        everything projects through it.
    T_ref : ndarray, shape (4, 4), or None
        The dataset's own ``T_cam_lidar`` when it has one (the reference for evaluation).
    image_path, points_path : Path
        Where the frame was read from.
    kitti_rect : ndarray, shape (4, 4), or None
        KITTI sources only: ``[I | b] @ R_rect_00``, so that ``T_cam_lidar = kitti_rect @ Tr``
        with KITTI's ``Tr_velo_to_cam`` (used to export the result in KITTI's own form).
    ring : ndarray, shape (N,), int16, or None
        Laser (ring) index per point when the file carries one (``ring``, ``laser_id``,
        ``channel``, ``line``), 0 .. R-1; None when it must be recovered.
    time : ndarray, shape (N,), float64, or None
        Per-point time in seconds on the file's own clock (``time``, ``t``, ``timestamp``,
        ``offset_time``), None when the file has none.
    point_fields : dict
        Which file field gave each column: ``{"intensity": name or None, "ring": name or None,
        "time": name or None, "layout": ...}`` (written to result.json).
    sensor_pose : ndarray, shape (4, 4), or None
        Pose of the LiDAR sensor in the cloud's frame (cloud <- sensor), when the points are
        stored in another frame (a vehicle frame); None when the cloud's origin is the sensor
        or the pose is unknown (see :mod:`paretocal.lidar.rings`).
    mask : ndarray, shape (H, W), bool, or None
        Pixels that show the scene (True); False on the ego vehicle, black borders or lens
        areas the calibration must ignore (calib.yaml's ``camera.mask``, and the pixels the
        lens model cannot reach). A LiDAR point landing on a masked pixel counts as out of the
        image. None: every pixel.
    credit : str or None
        The data's credit line for figures (KITTI's for KITTI sources, calib.yaml's ``credit``).
    options : dict
        What the dataset states about itself, as its source does (calib.yaml's
        ``init_error`` as ``(deg, m)``; :func:`paretocal.io.source_options`): frames loaded
        from a folder are calibrated with it as the folder itself is.
    board : Board or None
        The checkerboard the frames show (calib.yaml's ``board:`` or a ``board.yaml`` beside
        it); None for a recording without one.
    """

    name: str
    image: np.ndarray
    points: np.ndarray
    camera: Camera
    T_ref: np.ndarray | None
    image_path: Path
    points_path: Path
    kitti_rect: np.ndarray | None = None
    ring: np.ndarray | None = None
    time: np.ndarray | None = None
    point_fields: dict = field(default_factory=dict)
    sensor_pose: np.ndarray | None = None
    mask: np.ndarray | None = None
    credit: str | None = None
    options: dict = field(default_factory=dict)
    board: Board | None = None

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return self.camera.width, self.camera.height
