"""Pinhole projection of LiDAR points, batched over extrinsics.

Pixels follow INTERFACES.md: ``(u, v)`` with the origin at the centre of the top-left pixel, so a
point is in the image when ``0 <= u <= width - 1`` and ``0 <= v <= height - 1``, and in front of
the camera when ``z_cam > z_min``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Camera:
    """A pinhole camera after undistortion.

    Attributes
    ----------
    K : ndarray, shape (3, 3)
        Intrinsic matrix in pixels, last row ``[0, 0, 1]``.
    width, height : int
        Image size in pixels.
    """

    K: np.ndarray
    width: int
    height: int

    def projection(self, T_cam_lidar: np.ndarray) -> np.ndarray:
        """``K @ T[:3, :]`` for transforms of shape (..., 4, 4); returns (..., 3, 4)."""
        return self.K @ np.asarray(T_cam_lidar, dtype=np.float64)[..., :3, :]


def project(points: np.ndarray, camera: Camera, T_cam_lidar: np.ndarray,
            z_min: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project LiDAR points into the image.

    Parameters
    ----------
    points : ndarray, shape (N, 3+)
        LiDAR points in metres (columns beyond the third are ignored).
    camera : Camera
    T_cam_lidar : ndarray, shape (4, 4)
    z_min : float
        Minimum depth in metres for a point to count as in front of the camera.

    Returns
    -------
    uv : ndarray, shape (N, 2)
        Pixel coordinates (undefined where ``z <= z_min``).
    z : ndarray, shape (N,)
        Depth along the optical axis in metres.
    visible : ndarray of bool, shape (N,)
        In front of the camera and inside the image.
    """
    p = np.asarray(points, dtype=np.float64)[:, :3]
    A = camera.projection(T_cam_lidar)
    h = p @ A[:, :3].T + A[:, 3]
    z = h[:, 2]
    # Points at or near z = 0 give inf/nan (or overflow) pixels; they are never visible.
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        uv = h[:, :2] / z[:, None]
    front = z > z_min
    visible = front & in_image(uv, camera.width, camera.height)
    return uv, z, visible


def in_image(uv: np.ndarray, width: int, height: int, margin: float = 0.0) -> np.ndarray:
    """Mask of pixel coordinates (N, 2) inside the image grown by ``margin`` pixels."""
    u, v = uv[:, 0], uv[:, 1]
    with np.errstate(invalid="ignore"):
        return ((u >= -margin) & (u <= width - 1 + margin)
                & (v >= -margin) & (v <= height - 1 + margin))
