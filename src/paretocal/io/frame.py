"""The unit of input: one camera image paired with one LiDAR sweep."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..camera import Camera


@dataclass(eq=False)
class Frame:
    """One synchronised camera image and LiDAR sweep.

    Attributes
    ----------
    name : str
        The frame's stem (file name without extension), unique within a source.
    image : ndarray, shape (H, W, 3), uint8
        Undistorted colour image, BGR channel order (OpenCV's).
    points : ndarray, shape (N, 4), float32
        LiDAR points ``x, y, z`` in metres in the LiDAR frame and intensity (reflectance).
    camera : Camera
        Intrinsics of ``image``.
    T_ref : ndarray, shape (4, 4), or None
        The dataset's own ``T_cam_lidar`` when it has one (the reference for evaluation).
    image_path, points_path : Path
        Where the frame was read from.
    kitti_rect : ndarray, shape (4, 4), or None
        KITTI sources only: ``[I | b] @ R_rect_00``, so that ``T_cam_lidar = kitti_rect @ Tr``
        with KITTI's ``Tr_velo_to_cam`` (used to export the result in KITTI's own form).
    """

    name: str
    image: np.ndarray
    points: np.ndarray
    camera: Camera
    T_ref: np.ndarray | None
    image_path: Path
    points_path: Path
    kitti_rect: np.ndarray | None = None

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return self.camera.width, self.camera.height
