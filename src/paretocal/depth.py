"""Sparse depth maps from a LiDAR sweep and an extrinsic (the paper's "Depth Map Generation").

The depth of a pixel is the camera-frame ``z`` (metres) of the LiDAR return projecting into it
through the camera's lens model, in the image as it was taken; where several returns land on
one pixel the nearest wins (a z-buffer), and pixels without a return, or masked (the frame's
``mask``: the ego vehicle, borders), hold 0. Files follow the KITTI depth benchmark: 16-bit PNG
holding ``round(z * 256)`` (0 = no return, so the largest representable depth is 255.996 m).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from .camera import Camera, project
from .errors import InputError
from .io.atomic import atomic_path

KITTI_DEPTH_SCALE = 256.0


def depth_map(points: np.ndarray, camera: Camera, T_cam_lidar: np.ndarray,
              z_min: float = 0.1, mask: np.ndarray | None = None) -> np.ndarray:
    """The sparse depth image of one sweep.

    Parameters
    ----------
    points : ndarray, shape (N, 3) or (N, 4)
        LiDAR returns (metres; a fourth column is ignored).
    camera : Camera
        The camera's model, intrinsics and size.
    T_cam_lidar : ndarray, shape (4, 4)
        The extrinsic (LiDAR -> camera, m).
    z_min : float
        Returns closer than this in front of the camera are ignored (metres); so are returns
        a wide-angle model sees behind the image plane (no positive depth).
    mask : ndarray, shape (height, width), bool, optional
        Usable pixels; returns landing on other pixels are dropped.

    Returns
    -------
    ndarray, shape (height, width), float32
        Depth in metres at each pixel hit by a return (the nearest one), 0 elsewhere. A return
        belongs to the pixel whose centre is nearest to its projection.
    """
    uv, z, vis = project(np.asarray(points)[:, :3], camera, T_cam_lidar, z_min)
    vis &= z > z_min
    u = np.rint(uv[vis, 0]).astype(np.int64)
    v = np.rint(uv[vis, 1]).astype(np.int64)
    z = z[vis]
    ok = (u >= 0) & (u < camera.width) & (v >= 0) & (v < camera.height)
    u, v, z = u[ok], v[ok], z[ok]
    if mask is not None:
        keep = np.asarray(mask, dtype=bool)[v, u]
        u, v, z = u[keep], v[keep], z[keep]
    depth = np.full(camera.height * camera.width, np.inf)
    np.minimum.at(depth, v * camera.width + u, z)
    depth[~np.isfinite(depth)] = 0.0
    return depth.reshape(camera.height, camera.width).astype(np.float32)


def to_kitti_png(depth: np.ndarray) -> np.ndarray:
    """Depth (metres, float) to KITTI's uint16 encoding ``round(z * 256)``, 0 = no return.

    Depths beyond 255.996 m are dropped (set to 0) rather than wrapped.
    """
    q = np.rint(np.asarray(depth, dtype=np.float64) * KITTI_DEPTH_SCALE)
    q[(q > np.iinfo(np.uint16).max) | ~np.isfinite(q)] = 0
    return q.astype(np.uint16)


def read_kitti_png(path: str | Path) -> np.ndarray:
    """A KITTI-convention depth PNG back to metres (float32, 0 = no return)."""
    img = cv2.imread(str(path), cv2.IMREAD_ANYDEPTH)
    if img is None or img.dtype != np.uint16:
        raise InputError(f"{path}: not a 16-bit depth PNG")
    return (img.astype(np.float32) / KITTI_DEPTH_SCALE).astype(np.float32)


def depth_overlay(image: np.ndarray, depth: np.ndarray, max_depth: float = 50.0,
                  radius: int = 1) -> np.ndarray:
    """The image (BGR, uint8) with every depth pixel drawn in a turbo colour (near red).

    Returns a BGR uint8 image of the same shape.
    """
    out = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    v, u = np.nonzero(depth > 0)
    z = depth[v, u]
    level = np.clip(255 * (1 - z / max_depth), 0, 255).astype(np.uint8)
    colours = cv2.applyColorMap(level[:, None], cv2.COLORMAP_TURBO)[:, 0, :]
    for k in np.argsort(-z):                   # far first, near drawn on top
        cv2.circle(out, (int(u[k]), int(v[k])), radius, tuple(int(c) for c in colours[k]), -1)
    return out


def write_depth(frame, T_cam_lidar: np.ndarray, out_dir: str | Path, z_min: float = 0.1,
                max_depth: float = 50.0) -> list[Path]:
    """Write ``<stem>.png`` (KITTI 16-bit), ``<stem>.npy`` (float32 metres) and
    ``<stem>_overlay.png`` for one frame into ``out_dir``; returns the paths.

    Parameters
    ----------
    frame : Frame
        The frame (:func:`paretocal.load_frames`): its image, cloud, camera and mask.
    T_cam_lidar : ndarray, shape (4, 4)
        The extrinsic (LiDAR -> camera, m).
    out_dir : str or Path
        The folder to write into (made when missing).
    z_min : float
        Returns closer than this in front of the camera are ignored (m).
    max_depth : float
        The far end of the overlay's colour scale (m).

    Returns
    -------
    list of Path
        The three files written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    d = depth_map(frame.points, frame.camera, T_cam_lidar, z_min, getattr(frame, "mask", None))
    paths = [out / f"{frame.name}.png", out / f"{frame.name}.npy",
             out / f"{frame.name}_overlay.png"]
    for path, img in ((paths[0], to_kitti_png(d)),
                      (paths[2], depth_overlay(frame.image, d, max_depth))):
        ok, buf = cv2.imencode(".png", img)
        if not ok:
            raise InputError(f"{path}: could not encode the PNG")
        with atomic_path(path) as tmp:
            tmp.write_bytes(buf.tobytes())
    with atomic_path(paths[1]) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, d)
    return paths
