"""The three input layouts of INTERFACES.md section 2, detected from the source folder.

Each layout lists its frames (stem -> image path, points path) and knows the camera and the
dataset's own extrinsic; :func:`load_frames` selects and reads the frames.
"""

from __future__ import annotations

import logging
import math
import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..camera import Camera
from ..errors import InputError, SettingsError
from ..geometry import check_rigid
from .frame import Frame
from .readers import (IMAGE_SUFFIXES, POINT_SUFFIXES, calib_matrix, decode_image, read_image,
                      read_kitti_calib, read_mapping, read_points)

log = logging.getLogger(__name__)


@dataclass
class FrameFiles:
    """Paths of one frame before reading, with its calibration."""

    name: str
    image_path: Path
    points_path: Path
    camera: Camera
    T_ref: np.ndarray | None
    dist: np.ndarray | None = None  # distortion of the raw image, if any (see dist_model)
    #: "pinhole": ``dist`` holds OpenCV's k1, k2, p1, p2[, k3, ...] (cv2.undistort);
    #: "fisheye": ``dist`` holds the equidistant k1..k4 (cv2.fisheye).
    dist_model: str = "pinhole"
    #: KITTI sources only: ``[I | b] @ R_rect_00`` (4x4), so that ``T_ref = kitti_rect @ Tr``.
    kitti_rect: np.ndarray | None = None


@dataclass
class Source:
    """A detected dataset: its layout name and its frames in stem order."""

    layout: str
    root: Path
    frames: list[FrameFiles]


def _pair(root: Path, image_dir: Path, points_dir: Path,
          image_suffixes=IMAGE_SUFFIXES, point_suffixes=POINT_SUFFIXES) -> list[tuple[str, Path, Path]]:
    """Pair images and point clouds by stem; fail if the folders share no stem."""
    if not image_dir.is_dir():
        raise InputError(f"{image_dir}: image folder not found")
    if not points_dir.is_dir():
        raise InputError(f"{points_dir}: point cloud folder not found")
    images = {p.stem: p for p in _listdir(image_dir) if p.suffix.lower() in image_suffixes}
    points = {p.stem: p for p in _listdir(points_dir) if p.suffix.lower() in point_suffixes}
    common = sorted(set(images) & set(points))
    if not common:
        raise InputError(f"{root}: no frame pairs: {len(images)} images in {image_dir} and "
                         f"{len(points)} point clouds in {points_dir} share no file stem")
    for what, lone, folder in (("images", sorted(set(images) - set(points)), points_dir),
                               ("point clouds", sorted(set(points) - set(images)), image_dir)):
        if lone:
            log.warning("%s: %d %s without a partner in %s, skipped (%s%s)", root, len(lone),
                        what, folder, ", ".join(lone[:5]), ", ..." if len(lone) > 5 else "")
    return [(s, images[s], points[s]) for s in common]


def _listdir(folder: Path) -> list[Path]:
    """The entries of ``folder``, sorted, or an InputError naming it (e.g. no permission)."""
    try:
        return sorted(folder.iterdir())
    except OSError as exc:
        raise InputError(f"{folder}: cannot list the folder ({exc.strerror or exc})") from None


def _camera_from_P(P: np.ndarray, width: int, height: int) -> tuple[Camera, np.ndarray]:
    """Split a KITTI rectified projection ``P = K [I | b]`` into a camera and the offset ``[I | b]``.

    KITTI's ``P_rect_0N`` carries the stereo baseline in its last column; folding it into the
    extrinsic keeps the camera a plain pinhole, and ``K @ T[:3]`` reproduces ``P @ ...`` exactly.
    """
    K = P[:, :3].copy()
    B = np.eye(4)
    B[:3, 3] = np.linalg.solve(K, P[:, 3])
    return Camera(K=K, width=int(width), height=int(height)), B


def _rect4(R: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    return T


def _kitti_raw(root: Path, camera_index: int) -> Source:
    drive = root
    if not drive.name.endswith("_sync"):
        drives = [p for p in _listdir(root) if p.is_dir() and p.name.endswith("_sync")]
        if len(drives) != 1:
            raise InputError(f"{root}: a KITTI raw date folder must hold exactly one *_sync drive "
                             f"(found {len(drives)}); pass the drive folder instead")
        drive = drives[0]
    date = drive.parent
    c2c_path, v2c_path = date / "calib_cam_to_cam.txt", date / "calib_velo_to_cam.txt"
    c2c, v2c = read_kitti_calib(c2c_path), read_kitti_calib(v2c_path)
    P = calib_matrix(c2c, f"P_rect_0{camera_index}", (3, 4), c2c_path)
    R_rect = calib_matrix(c2c, "R_rect_00", (3, 3), c2c_path)
    size = calib_matrix(c2c, f"S_rect_0{camera_index}", (1, 2), c2c_path)[0]
    Tr = np.eye(4)
    Tr[:3, :3] = calib_matrix(v2c, "R", (3, 3), v2c_path)
    Tr[:3, 3] = calib_matrix(v2c, "T", (1, 3), v2c_path)[0]
    cam, B = _camera_from_P(P, size[0], size[1])
    rect = B @ _rect4(R_rect)
    T_ref = check_rigid(rect @ Tr, str(v2c_path))
    pairs = _pair(drive, drive / f"image_0{camera_index}" / "data",
                  drive / "velodyne_points" / "data", point_suffixes=(".bin",))
    return Source("kitti_raw", drive, [FrameFiles(s, i, p, cam, T_ref, kitti_rect=rect)
                                       for s, i, p in pairs])


def _kitti_object(root: Path, camera_index: int) -> Source:
    if camera_index not in (2, 3):
        raise SettingsError(f"--camera {camera_index}: the KITTI object layout has cameras 2 and 3")
    pairs = _pair(root, root / f"image_{camera_index}", root / "velodyne", point_suffixes=(".bin",))
    frames = []
    for stem, img, pts in pairs:
        cpath = root / "calib" / f"{stem}.txt"
        calib = read_kitti_calib(cpath)
        P = calib_matrix(calib, f"P{camera_index}", (3, 4), cpath)
        R0 = calib_matrix(calib, "R0_rect", (3, 3), cpath)
        Tr = np.vstack([calib_matrix(calib, "Tr_velo_to_cam", (3, 4), cpath), [0, 0, 0, 1]])
        # The object benchmark's calib files carry no image size: read it from the image header.
        shape = _image_shape(img)
        cam, B = _camera_from_P(P, shape[1], shape[0])
        rect = B @ _rect4(R0)
        frames.append(FrameFiles(stem, img, pts, cam, check_rigid(rect @ Tr, str(cpath)),
                                 kitti_rect=rect))
    return Source("kitti_object", root, frames)


def _image_shape(path: Path) -> tuple[int, int]:
    return decode_image(path).shape[:2]


#: Distortion model names of calib.yaml (``camera.model``) and of ROS camera_info
#: (``distortion_model``), mapped to how the image is undistorted.
_DIST_MODELS = {"pinhole": "pinhole", "plumb_bob": "pinhole", "rational_polynomial": "pinhole",
                "radtan": "pinhole", "fisheye": "fisheye", "equidistant": "fisheye"}
_OPENCV_D_SIZES = (4, 5, 8, 12, 14)


def _intrinsics(path: Path, where: dict[str, str], K, width, height, D,
                model) -> tuple[Camera, np.ndarray | None, str]:
    """Validate intrinsics read from ``path``; ``where`` maps a role to the key that held it.

    Returns the pinhole camera of the undistorted images, the distortion (None when there is
    nothing to undo) and the distortion model ("pinhole" or "fisheye").
    """
    K = _numbers(path, where["K"], K)
    width, height = (_size(path, where[k], v) for k, v in (("width", width), ("height", height)))
    D = None if D is None else _numbers(path, where["D"], D).ravel()
    if K.shape != (3, 3):
        raise InputError(f"{path}: {where['K']} must be a 3x3 matrix, got shape {K.shape}")
    if not np.all(np.isfinite(K)):
        raise InputError(f"{path}: {where['K']} contains NaN or infinite values")
    if not np.allclose(K[2], [0, 0, 1]) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError(f"{path}: {where['K']} must have positive focal lengths and last row "
                         "[0, 0, 1]")
    key = str(model).strip().lower() if model is not None else "pinhole"
    if key not in _DIST_MODELS:
        raise InputError(f"{path}: {where['model']} {model!r} is not one of "
                         f"{', '.join(_DIST_MODELS)}")
    kind = _DIST_MODELS[key]
    if D is not None and not np.all(np.isfinite(D)):
        raise InputError(f"{path}: {where['D']} contains NaN or infinite values")
    if kind == "fisheye":
        if D is None:
            D = np.zeros(4)  # the ideal equidistant lens: still not a pinhole, undistort it
        if D.size != 4:
            raise InputError(f"{path}: {where['D']} must hold the 4 fisheye (equidistant) "
                             f"coefficients k1, k2, k3, k4, got {D.size}")
    elif D is not None:
        if D.size not in _OPENCV_D_SIZES:
            raise InputError(f"{path}: {where['D']} must hold 4, 5, 8, 12 or 14 finite OpenCV "
                             f"coefficients, got {D.size}")
        if not np.any(D):
            D = None
    return Camera(K=K, width=width, height=height), D, kind


def _numbers(path: Path, name: str, value) -> np.ndarray:
    """``value`` as a float64 array, or an InputError naming ``name`` in ``path``."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as exc:
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if "inhomogeneous" in text or "sequence" in text:
            text = "rows of different lengths"
        raise InputError(f"{path}: {name} is not a list of numbers ({text})") from None


def _size(path: Path, name: str, value) -> int:
    """An image dimension: a positive whole number of pixels."""
    try:
        v = float(value.strip()) if isinstance(value, str) else value
        ok = (not isinstance(v, bool) and isinstance(v, (int, float, np.integer, np.floating))
              and math.isfinite(float(v)) and v == int(v) and v > 0)
    except (ValueError, OverflowError):
        ok = False
    if not ok:
        raise InputError(f"{path}: {name} must be a positive whole number of pixels, got "
                         f"{value!r}")
    return int(v)


def _ros_matrix(path: Path, info: dict, key: str, prefix: str, shape=None) -> np.ndarray | None:
    """A ROS camera_info matrix ``{rows, cols, data}``; None when the key is absent."""
    m = info.get(key)
    if m is None:
        return None
    name = f"{prefix}{key}"
    if not isinstance(m, dict) or "data" not in m:
        raise InputError(f"{path}: {name} must be a mapping with rows, cols and data")
    try:
        data = np.asarray(m["data"], dtype=np.float64)
        rows = int(m.get("rows", shape[0] if shape else 1))
        cols = int(m.get("cols", shape[1] if shape else data.size))
    except (TypeError, ValueError, OverflowError) as exc:
        raise InputError(f"{path}: {name} values are not numbers ({exc})") from None
    if data.ndim != 1:
        raise InputError(f"{path}: {name}.data must be a flat list of numbers")
    if rows * cols != data.size:
        raise InputError(f"{path}: {name}.data has {data.size} values, rows x cols is "
                         f"{rows} x {cols}")
    if shape is not None and (rows, cols) != shape:
        raise InputError(f"{path}: {name} must be {shape[0]} x {shape[1]}, got {rows} x {cols}")
    if not np.all(np.isfinite(data)):
        raise InputError(f"{path}: {name} contains NaN or infinite values")
    return data.reshape(rows, cols)


def _camera_info(path: Path, info: dict, prefix: str = "") -> tuple[Camera, np.ndarray | None, str]:
    """Intrinsics from a ROS ``camera_info`` mapping (camera_calibration_parsers' YAML form).

    Uses ``camera_matrix`` and the distortion; ``rectification_matrix`` and
    ``projection_matrix`` are ignored: images are undistorted into the camera's own frame with
    the same K, which is the frame ``T_cam_lidar`` refers to.
    """
    for key in ("image_width", "image_height", "camera_matrix"):
        if info.get(key) is None:
            raise InputError(f"{path}: missing {prefix}{key}")
    K = _ros_matrix(path, info, "camera_matrix", prefix, (3, 3))
    D = _ros_matrix(path, info, "distortion_coefficients", prefix)
    model = info.get("distortion_model")
    if model is None or str(model).strip().lower() in ("", "none"):
        if D is not None and np.any(D):
            raise InputError(f"{path}: {prefix}distortion_coefficients are not zero but "
                             f"{prefix}distortion_model is missing or none (expected plumb_bob, "
                             "rational_polynomial or equidistant)")
        model, D = None, None
    where = {"K": f"{prefix}camera_matrix", "width": f"{prefix}image_width",
             "height": f"{prefix}image_height", "model": f"{prefix}distortion_model",
             "D": f"{prefix}distortion_coefficients"}
    return _intrinsics(path, where, K, info["image_width"], info["image_height"], D, model)


def _folder_camera(root: Path, cpath: Path, data: dict) -> tuple[Camera, np.ndarray | None, str]:
    """The camera of a generic folder: ``camera`` in calib.yaml, or a ROS camera_info file."""
    if data.get("camera_info") is not None:
        if data.get("camera") is not None:
            raise InputError(f"{cpath}: give either 'camera' or 'camera_info', not both")
        ref = data["camera_info"]
        if not isinstance(ref, str) or not ref.strip():
            raise InputError(f"{cpath}: camera_info must be the path of a ROS camera_info YAML "
                             "file (relative to the folder)")
        ipath = root / ref
        if not ipath.is_file():
            raise InputError(f"{cpath}: camera_info file {ipath} not found")
        return _camera_info(ipath, read_mapping(ipath))
    cam = data.get("camera")
    if not isinstance(cam, dict):
        raise InputError(f"{cpath}: missing 'camera' section")
    if "camera_matrix" in cam or "image_width" in cam:
        return _camera_info(cpath, cam, "camera.")
    for key in ("K", "width", "height"):
        if key not in cam:
            raise InputError(f"{cpath}: missing camera.{key}")
    where = {k: f"camera.{k}" for k in ("K", "width", "height", "model", "D")}
    return _intrinsics(cpath, where, cam["K"], cam["width"], cam["height"], cam.get("D"),
                       cam.get("model"))


def _folder(root: Path) -> Source:
    cpath = root / "calib.yaml"
    data = read_mapping(cpath)
    camera, dist, model = _folder_camera(root, cpath, data)
    T_ref = None
    if data.get("T_cam_lidar") is not None:
        T_ref = check_rigid(data["T_cam_lidar"], str(cpath))
    pairs = _pair(root, root / "images", root / "points")
    return Source("folder", root, [FrameFiles(s, i, p, camera, T_ref, dist, model)
                                   for s, i, p in pairs])


def detect_source(source: Path, camera_index: int = 2) -> Source:
    """Detect the layout of ``source`` and list its frames (nothing heavy is read yet)."""
    root = Path(source)
    if not root.exists():
        raise InputError(f"{root}: source folder not found")
    if not root.is_dir():
        raise InputError(f"{root}: source must be a folder")
    if not 0 <= camera_index <= 3:
        raise SettingsError(f"--camera {camera_index}: must be 0, 1, 2 or 3")
    if (root / "calib.yaml").is_file():
        return _folder(root)
    if (root / "training").is_dir() and not (root / "velodyne").is_dir():
        root = root / "training"
    if (root / "velodyne").is_dir() and (root / "calib").is_dir():
        return _kitti_object(root, camera_index)
    if root.name.endswith("_sync") or any(p.name.endswith("_sync") for p in _listdir(root)
                                          if p.is_dir()):
        return _kitti_raw(root, camera_index)
    raise InputError(f"{root}: not a recognised layout (expected a KITTI raw drive or date folder, "
                     "a KITTI object 'training' folder, or a folder with calib.yaml, images/ "
                     "and points/)")


_SLICE = re.compile(r"^(-?\d*):(-?\d*)(?::(-?\d+))?$")


def select_frames(names: list[str], spec: str | None) -> list[int]:
    """Indices selected by a ``--frames`` spec: ``0:10``, ``0:20:4``, ``0,3,7``, stems, or a mix.

    A token equal to a frame stem selects that frame; otherwise an integer is an index into the
    frames in stem order and ``a:b`` or ``a:b:step`` a Python slice of them.
    """
    if spec is None or str(spec).strip() == "":
        return list(range(len(names)))
    index = {n: i for i, n in enumerate(names)}
    chosen: list[int] = []
    for token in (t.strip() for t in str(spec).split(",")):
        if not token:
            continue
        if token in index:
            chosen.append(index[token])
            continue
        m = _SLICE.match(token)
        if m:
            a = int(m.group(1)) if m.group(1) else None
            b = int(m.group(2)) if m.group(2) else None
            step = int(m.group(3)) if m.group(3) else None
            if step == 0:
                raise SettingsError(f"--frames {spec}: the step of {token!r} is zero")
            chosen.extend(range(len(names))[slice(a, b, step)])
        elif re.fullmatch(r"-?\d+", token):
            i = int(token)
            if not -len(names) <= i < len(names):
                raise SettingsError(f"--frames {spec}: index {i} is out of range "
                                    f"(the source has {len(names)} frames)")
            chosen.append(i % len(names))
        else:
            raise SettingsError(f"--frames {spec}: {token!r} is neither a frame stem nor an index")
    chosen = list(dict.fromkeys(chosen))
    if not chosen:
        raise SettingsError(f"--frames {spec}: selects no frame (the source has {len(names)})")
    return chosen


def read_frame(files: FrameFiles) -> Frame:
    """Read one frame's image and points, undistorting the image when the camera has ``D``.

    A fisheye (equidistant) image is remapped with ``cv2.fisheye`` to a pinhole image with the
    same K, so the rest of the pipeline sees a plain pinhole camera either way.
    """
    image = read_image(files.image_path)
    cam = files.camera
    if image.shape[1] != cam.width or image.shape[0] != cam.height:
        raise InputError(f"{files.image_path}: image is {image.shape[1]}x{image.shape[0]} but the "
                         f"calibration says {cam.width}x{cam.height}")
    if files.dist is not None and files.dist_model == "fisheye":
        image = cv2.fisheye.undistortImage(image, cam.K, files.dist, Knew=cam.K,
                                           new_size=(cam.width, cam.height))
    elif files.dist is not None:
        image = cv2.undistort(image, cam.K, files.dist)
    points = read_points(files.points_path)
    return Frame(files.name, image, points, cam, files.T_ref, files.image_path, files.points_path,
                 kitti_rect=files.kitti_rect)


def load_frames(source: str | Path, frames: str | None = None, camera: int = 2) -> list[Frame]:
    """Detect the layout of ``source`` and read the selected frames.

    Parameters
    ----------
    source : path
        A KITTI raw drive (or date) folder, a KITTI object ``training`` folder, or a generic
        folder with ``calib.yaml`` (INTERFACES.md section 2).
    frames : str, optional
        Selection spec (``0:10``, ``0,3,7``, stems); all frames by default.
    camera : int
        KITTI camera index (0-3 for raw, 2-3 for object); ignored by the generic layout.

    Returns
    -------
    list of Frame
    """
    src = detect_source(Path(source), camera)
    idx = select_frames([f.name for f in src.frames], frames)
    return [read_frame(src.frames[i]) for i in idx]
