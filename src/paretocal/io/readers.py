"""Readers for the files a frame is made of: LiDAR sweeps, images, calibration text and YAML.

Every failure raises :class:`~paretocal.errors.InputError` naming the file and what is wrong.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import cv2
import numpy as np
import yaml

from ..errors import InputError

log = logging.getLogger(__name__)

POINT_SUFFIXES = (".bin", ".npy")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


def read_points(path: Path) -> np.ndarray:
    """Read a LiDAR sweep as an (N, 4) float32 array ``x, y, z, intensity``.

    ``.bin`` holds float32 quadruples (KITTI); ``.npy`` holds an (N, 3) or (N, 4) array (a
    missing intensity column reads as zeros). Points with a NaN or infinite coordinate are
    dropped with a warning that counts them.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: point cloud file not found")
    suffix = path.suffix.lower()
    try:
        if suffix == ".bin":
            size = path.stat().st_size
            if size % 16:
                raise InputError(f"{path}: size {size} bytes is not a multiple of 16 "
                                 "(float32 x, y, z, intensity); the file is truncated or not a "
                                 "KITTI .bin sweep")
            pts = np.fromfile(path, dtype=np.float32).reshape(-1, 4)
        elif suffix == ".npy":
            arr = np.load(path, allow_pickle=False)
            if arr.ndim != 2 or arr.shape[1] not in (3, 4):
                raise InputError(f"{path}: expected an N x 3 or N x 4 array, got shape {arr.shape}")
            if not np.issubdtype(arr.dtype, np.number):
                raise InputError(f"{path}: expected numbers, got dtype {arr.dtype}")
            pts = np.zeros((arr.shape[0], 4), dtype=np.float32)
            pts[:, : arr.shape[1]] = arr
        else:
            raise InputError(f"{path}: unsupported point cloud format {suffix!r} "
                             f"(supported: {', '.join(POINT_SUFFIXES)})")
    except InputError:
        raise
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read point cloud ({exc})") from None
    finite = np.isfinite(pts[:, :3]).all(axis=1)
    if not finite.all():
        log.warning("%s: dropped %d points with NaN or infinite coordinates",
                    path, int((~finite).sum()))
        pts = pts[finite]
    pts[:, 3] = np.nan_to_num(pts[:, 3], nan=0.0, posinf=0.0, neginf=0.0)
    if len(pts) == 0:
        raise InputError(f"{path}: the point cloud is empty")
    return np.ascontiguousarray(pts)


def read_image(path: Path) -> np.ndarray:
    """Read an image as (H, W, 3) uint8 BGR; grey images are expanded to three channels."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: image file not found")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None or img.size == 0:
        raise InputError(f"{path}: cannot decode the image (corrupt or not an image)")
    if img.dtype != np.uint8:
        # 16-bit images: keep the relative contrast for edge detection.
        img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img


def read_kitti_calib(path: Path) -> dict[str, np.ndarray]:
    """Parse a KITTI calibration text file (``key: numbers`` per line) into float64 arrays.

    Lines whose values are not numbers (such as ``calib_time``) are skipped.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: calibration file not found")
    out: dict[str, np.ndarray] = {}
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read calibration file ({exc})") from None
    for line in text.splitlines():
        if ":" not in line:
            continue
        key, _, rest = line.partition(":")
        try:
            out[key.strip()] = np.array([float(v) for v in rest.split()], dtype=np.float64)
        except ValueError:
            continue
    return out


def calib_matrix(calib: dict[str, np.ndarray], key: str, shape: tuple[int, int],
                 path: Path) -> np.ndarray:
    """Fetch ``key`` from a parsed KITTI calibration and reshape it, or fail naming the file."""
    if key not in calib:
        raise InputError(f"{path}: missing key {key!r}")
    v = calib[key]
    if v.size != shape[0] * shape[1]:
        raise InputError(f"{path}: {key!r} has {v.size} values, expected "
                         f"{shape[0] * shape[1]} ({shape[0]}x{shape[1]})")
    m = v.reshape(shape)
    if not np.all(np.isfinite(m)):
        raise InputError(f"{path}: {key!r} contains NaN or infinite values")
    return m


def read_mapping(path: Path) -> dict:
    """Read a YAML or JSON file whose top level is a mapping."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    try:
        text = path.read_text()
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (OSError, UnicodeDecodeError, ValueError, yaml.YAMLError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"{path}: cannot parse ({first})") from None
    if not isinstance(data, dict):
        raise InputError(f"{path}: expected a mapping at the top level")
    return data
