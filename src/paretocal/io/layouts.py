"""The three input layouts of docs/conventions.md section 2, detected from the source folder.

Each layout lists its frames (stem -> image path, points path) and knows the camera and the
dataset's own extrinsic; :func:`load_frames` selects and reads the frames.
"""

from __future__ import annotations

import logging
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..camera import MAX_XI, Camera
from ..errors import PATH_CHARS, InputError, SettingsError, excerpt, first_line, key_list, quote
from ..geometry import check_rigid
from .bags import extract_hint, is_bag
from .board import Board, read_board
from .frame import Frame
from .paths import kind_of, missing, not_found
from .clouds import BIN_LAYOUTS, POINT_SUFFIXES, read_cloud
from .images import decode_image, IMAGE_SUFFIXES, image_size, read_image
from .text import calib_matrix, read_kitti_calib, read_mapping

log = logging.getLogger(__name__)


#: The credit figures of KITTI's data carry (its licence asks for attribution).
KITTI_CREDIT = "data: KITTI (Geiger et al., IJRR 2013), CC BY-NC-SA 3.0"


@dataclass
class FrameFiles:
    """Paths of one frame before reading, with its calibration."""

    name: str
    image_path: Path
    points_path: Path
    camera: Camera  # the full lens model of the image as stored (images are not undistorted)
    T_ref: np.ndarray | None
    #: Usable pixels from the calib.yaml mask file, (H, W) bool, or None (every pixel).
    mask: np.ndarray | None = None
    #: KITTI sources only: ``[I | b] @ R_rect_00`` (4x4), so that ``T_ref = kitti_rect @ Tr``.
    kitti_rect: np.ndarray | None = None
    #: The LiDAR's pose in the cloud's frame (calib.yaml ``lidar_pose``), or None.
    sensor_pose: np.ndarray | None = None
    #: Declared ``.bin`` column layout (calib.yaml ``points: {layout: NAME}``), or None.
    bin_layout: str | None = None
    #: The data's credit line for figures (KITTI's for KITTI, calib.yaml ``credit``), or None.
    credit: str | None = None
    #: The checkerboard in view (calib.yaml ``board``, or board.yaml beside it), or None.
    board: Board | None = None


@dataclass
class Source:
    """A detected dataset: its layout name, its frames in stem order, and settings the dataset
    states about itself (``options``: ``init_error`` as (deg, m) from calib.yaml)."""

    layout: str
    root: Path
    frames: list[FrameFiles]
    options: dict = field(default_factory=dict)


def _link_file(path: Path) -> Path:
    """``path``, or the folder a *link file* at ``path`` names.

    A symbolic link copied by a tool that does not keep links (git with ``core.symlinks``
    off, some archivers) becomes a small text file holding the link's target. A folder entry
    that is such a file, naming an existing folder relative to its own, is followed (with a
    note in the log) instead of failing with "folder not found".
    """
    if kind_of(path) == "a regular file" and path.stat().st_size < 4096:
        try:
            target = path.read_text(encoding="utf-8").strip()
        except (OSError, UnicodeDecodeError):
            return path
        if target and "\n" not in target and kind_of(path.parent / target) == "a folder":
            log.info("%s: a link file naming %s; following it", path, target)
            return (path.parent / target).resolve()
    return path


def _pair(root: Path, image_dir: Path, points_dir: Path,
          image_suffixes=IMAGE_SUFFIXES, point_suffixes=POINT_SUFFIXES) -> list[tuple[str, Path, Path]]:
    """Pair images and point clouds by stem; fail if the folders share no stem."""
    image_dir, points_dir = _link_file(image_dir), _link_file(points_dir)
    if kind_of(image_dir) != "a folder":
        raise InputError(not_found(image_dir, "image folder", "a folder"))
    if kind_of(points_dir) != "a folder":
        raise InputError(not_found(points_dir, "point cloud folder", "a folder"))
    images = _by_stem(_listdir(image_dir), image_suffixes)
    points = _by_stem(_listdir(points_dir), point_suffixes)
    common = sorted(set(images) & set(points))
    if not common:
        raise InputError(f"{root}: no frame pairs: {len(images)} images in {image_dir} and "
                         f"{len(points)} point clouds in {points_dir} share no file stem")
    # Which of two files of one frame is meant cannot be guessed.
    for what, found in (("images", images), ("point clouds", points)):
        twice = [s for s in common if len(found[s]) > 1]
        if twice:
            files = " and ".join(str(p) for p in found[twice[0]])
            more = f" (and {len(twice) - 1} more frames like it)" if len(twice) > 1 else ""
            raise InputError(f"{files}: {len(found[twice[0]])} {what} for frame {twice[0]}"
                             f"{more}; a frame has one image and one point cloud: remove or "
                             "rename the others")
    for what, lone, folder in (("images", sorted(set(images) - set(points)), points_dir),
                               ("point clouds", sorted(set(points) - set(images)), image_dir)):
        if lone:
            log.warning("%s: %d %s without a partner in %s, skipped (%s%s)", root, len(lone),
                        what, folder, ", ".join(lone[:5]), ", ..." if len(lone) > 5 else "")
    return [(s, images[s][0], points[s][0]) for s in common]


def _by_stem(paths: list[Path], suffixes) -> dict[str, list[Path]]:
    """The files with one of ``suffixes`` (any case), grouped by stem."""
    out: dict[str, list[Path]] = {}
    for p in paths:
        if p.suffix.lower() in suffixes:
            out.setdefault(p.stem, []).append(p)
    return out


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
    return Source("kitti_raw", drive, [FrameFiles(s, i, p, cam, T_ref, kitti_rect=rect,
                                                  credit=KITTI_CREDIT)
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
        width, height = image_size(img)
        cam, B = _camera_from_P(P, width, height)
        rect = B @ _rect4(R0)
        frames.append(FrameFiles(stem, img, pts, cam, check_rigid(rect @ Tr, str(cpath)),
                                 kitti_rect=rect, credit=KITTI_CREDIT))
    return Source("kitti_object", root, frames)


#: Camera model names of calib.yaml (``camera.model``) and of ROS camera_info
#: (``distortion_model``), mapped to the :class:`~paretocal.camera.Camera` model.
_MODELS = {"pinhole": "pinhole", "radtan": "pinhole", "plumb_bob": "pinhole",
           "rational_polynomial": "pinhole", "fisheye": "fisheye", "equidistant": "fisheye",
           "kannala_brandt": "fisheye", "mei": "mei", "omni": "mei", "unified": "mei"}
_OPENCV_D_SIZES = (4, 5, 8, 12, 14)


def _intrinsics(path: str | Path, where: dict[str, str], K, width, height, D, model,
                xi=None) -> Camera:
    """Validate intrinsics read from ``path``; ``where`` maps a role to the key that held it.

    Returns the camera with its full lens model: the images are used as they are.
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
    if K[1, 0] != 0:
        raise InputError(f"{path}: {where['K']} must be upper triangular (its second row "
                         "starts with 0)")
    key = str(model).strip().lower() if model is not None else "pinhole"
    if key not in _MODELS:
        raise InputError(f"{path}: {where['model']} {quote(model)} is not one of "
                         f"{', '.join(_MODELS)}")
    kind = _MODELS[key]
    if D is not None and not np.all(np.isfinite(D)):
        raise InputError(f"{path}: {where['D']} contains NaN or infinite values")
    if kind == "fisheye":
        if D is not None and D.size != 4:
            raise InputError(f"{path}: {where['D']} must hold the 4 fisheye (equidistant) "
                             f"coefficients k1, k2, k3, k4, got {D.size}")
    elif kind == "mei":
        if D is not None and D.size not in (4, 5):
            raise InputError(f"{path}: {where['D']} must hold the Mei model's k1, k2, p1, p2 "
                             f"[, k3], got {D.size}")
        if xi is None:
            raise InputError(f"{path}: {where['xi']} is missing: the {key} (unified) model "
                             "needs the mirror parameter xi")
        try:
            xi_v = float(xi.strip()) if isinstance(xi, str) else xi
            ok = (not isinstance(xi_v, bool) and isinstance(xi_v, (int, float, np.number))
                  and math.isfinite(float(xi_v)) and float(xi_v) >= 0)
        except (ValueError, OverflowError):
            ok = False
        if not ok:
            raise InputError(f"{path}: {where['xi']} must be a finite number >= 0, got {quote(xi)}")
        if float(xi_v) > MAX_XI:
            raise InputError(f"{path}: {where['xi']} must be at most {MAX_XI:g} (the unified "
                             "model's mirror parameter: about 1 for mirrors, up to about 3 for "
                             f"fisheye lenses), got {quote(xi)}")
        xi = float(xi_v)
    elif D is not None:
        if D.size not in _OPENCV_D_SIZES:
            raise InputError(f"{path}: {where['D']} must hold 4, 5, 8, 12 or 14 finite OpenCV "
                             f"coefficients, got {D.size}")
        if D.size == 14 and np.any(D[12:]):
            raise InputError(f"{path}: {where['D']}: the tilted-sensor coefficients (the last "
                             "two of 14) are not supported; they must be 0")
    return Camera(K=K, width=width, height=height, model=kind, D=D,
                  xi=xi if kind == "mei" else 0.0)


def _numbers(path: str | Path, name: str, value) -> np.ndarray:
    """``value`` as a float64 array, or an InputError naming ``name`` in ``path``."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as exc:
        text = first_line(exc)
        if "inhomogeneous" in text or "sequence" in text:
            text = "rows of different lengths"
        raise InputError(f"{path}: {name} is not a list of numbers ({text})") from None


def _size(path: str | Path, name: str, value) -> int:
    """An image dimension: a positive whole number of pixels."""
    try:
        v = float(value.strip()) if isinstance(value, str) else value
        ok = (not isinstance(v, bool) and isinstance(v, (int, float, np.integer, np.floating))
              and math.isfinite(float(v)) and v == int(v) and v > 0)
    except (ValueError, OverflowError):
        ok = False
    if not ok:
        raise InputError(f"{path}: {name} must be a positive whole number of pixels, got "
                         f"{quote(value)}")
    return int(v)


def _ros_matrix(path: str | Path, info: dict, key: str, prefix: str, shape=None) -> np.ndarray | None:
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
        raise InputError(f"{path}: {name} values are not numbers ({first_line(exc)})") from None
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


def _camera_info(path: str | Path, info: dict, prefix: str = "") -> Camera:
    """Intrinsics from a ROS ``camera_info`` mapping (camera_calibration_parsers' YAML form).

    Uses ``camera_matrix`` and the distortion (and ``xi`` for a Mei model, a key ROS itself
    does not have); ``rectification_matrix`` and ``projection_matrix`` are ignored: points are
    projected through the lens model into the raw image, in the camera's own frame, which is
    the frame ``T_cam_lidar`` refers to.
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
             "D": f"{prefix}distortion_coefficients", "xi": f"{prefix}xi"}
    return _intrinsics(path, where, K, info["image_width"], info["image_height"], D, model,
                       info.get("xi"))


def _is_message(info: dict) -> bool:
    """Whether a mapping is a sensor_msgs/CameraInfo message (flat ``K``, ``D``, ``P``)."""
    return "camera_matrix" not in info and any(k in info for k in ("distortion_model", "k", "d",
                                                                     "p", "P"))


def _camera_info_message(path: str | Path, info: dict, prefix: str = "") -> Camera:
    """Intrinsics from a sensor_msgs/CameraInfo message as ``rostopic echo`` (``K``, ``D``,
    ``P``) or ``ros2 topic echo`` (``k``, ``d``, ``p``) prints it: ``K`` row-major 3x3 (9
    numbers), or, where ``K`` is absent or all zeros, the left 3x3 of ``P`` (3x4, 12 numbers);
    ``width``, ``height``, ``distortion_model`` and ``D`` (empty: none)."""
    def get(key):
        return info.get(key, info.get(key.lower()))

    def name(key):
        return f"{prefix}{key if key in info else key.lower()}"

    K = None if get("K") is None else _numbers(path, name("K"), get("K")).ravel()
    where_K = name("K")
    if K is None or (K.size == 9 and not np.any(K)):
        if get("P") is None:
            raise InputError(f"{path}: missing {prefix}K (or P) (keys found: "
                             f"{key_list(info)})")
        P = _numbers(path, name("P"), get("P")).ravel()
        if P.size != 12:
            raise InputError(f"{path}: {name('P')} must hold 12 numbers (row-major 3x4), got "
                             f"{P.size}")
        K, where_K = P.reshape(3, 4)[:, :3], f"{name('P')} (its left 3x3)"
    elif K.size != 9:
        raise InputError(f"{path}: {where_K} must hold 9 numbers (row-major 3x3), got {K.size}")
    for key in ("width", "height"):
        if get(key) is None:
            raise InputError(f"{path}: missing {prefix}{key} (keys found: "
                             f"{key_list(info)})")
    D = get("D")
    if isinstance(D, (list, tuple)) and len(D) == 0:        # "D: []": no distortion
        D = None
    model = get("distortion_model")
    if model is not None and str(model).strip().lower() in ("", "none"):
        model = None
    where = {"K": where_K, "width": name("width"), "height": name("height"),
             "model": name("distortion_model"), "D": name("D"), "xi": f"{prefix}xi"}
    return _intrinsics(path, where, np.reshape(K, (3, 3)), get("width"), get("height"), D,
                       model, info.get("xi"))


def _folder_camera(root: Path, cpath: str | Path, data: dict) -> Camera:
    """The camera of a generic folder: ``camera`` in calib.yaml, or a ROS camera_info file."""
    if data.get("camera_info") is not None:
        if data.get("camera") is not None:
            raise InputError(f"{cpath}: give either 'camera' or 'camera_info', not both")
        ref = data["camera_info"]
        if not isinstance(ref, str) or not ref.strip():
            raise InputError(f"{cpath}: camera_info must be the path of a ROS camera_info YAML "
                             "file (relative to the folder)")
        ipath = root / ref
        if kind_of(ipath) != "a regular file":
            raise InputError(f"{cpath}: camera_info file {excerpt(ipath, PATH_CHARS)} "
                             f"{missing(ipath)}")
        info = read_mapping(ipath)
        return (_camera_info_message(ipath, info) if _is_message(info)
                else _camera_info(ipath, info))
    cam = data.get("camera")
    if not isinstance(cam, dict):
        raise InputError(f"{cpath}: missing 'camera' section")
    if "camera_matrix" in cam or "image_width" in cam:
        return _camera_info(cpath, cam, "camera.")
    if _is_message(cam):
        return _camera_info_message(cpath, cam, "camera.")
    check_keys(cpath, cam, CAMERA_KEYS, "camera")
    for key in ("K", "width", "height"):
        if key not in cam:
            raise InputError(f"{cpath}: missing camera.{key}")
    where = {k: f"camera.{k}" for k in ("K", "width", "height", "model", "D", "xi")}
    return _intrinsics(cpath, where, cam["K"], cam["width"], cam["height"], cam.get("D"),
                       cam.get("model"), cam.get("xi"))


def calib_camera(data: dict, where: str | Path, root: Path | None = None) -> Camera:
    """The camera of a ``calib.yaml`` mapping, validated as the generic folder's loader does.

    Parameters
    ----------
    data : dict
        The mapping: a ``camera`` section (``K``, ``width``, ``height``, optional ``model``,
        ``D``, ``xi``, or the ROS camera_info form) or a ``camera_info`` file name.
    where : str or path
        What the mapping is called in error messages (a file, or e.g. a bag's topic).
    root : path, optional
        The folder a ``camera_info`` file name is relative to.

    Raises
    ------
    InputError
        Naming ``where`` and the key at fault.
    """
    return _folder_camera(Path(root) if root is not None else Path("."), where, data)


def _folder_mask(root: Path, cpath: Path, data: dict, camera: Camera) -> np.ndarray | None:
    """The usable pixels named by ``camera.mask`` (or a top-level ``mask``) in calib.yaml.

    The file is an image of the camera's size, nonzero (in any channel) on usable pixels.
    """
    cam = data.get("camera")
    key, ref = "mask", data.get("mask")
    if isinstance(cam, dict) and cam.get("mask") is not None:
        if ref is not None:
            raise InputError(f"{cpath}: give either camera.mask or mask, not both")
        key, ref = "camera.mask", cam["mask"]
    if ref is None:
        return None
    if not isinstance(ref, str) or not ref.strip():
        raise InputError(f"{cpath}: {key} must be the path of a mask image (relative to the "
                         "folder), nonzero on usable pixels")
    mpath = root / ref
    if kind_of(mpath) != "a regular file":
        raise InputError(f"{cpath}: {key} file {excerpt(mpath, PATH_CHARS)} {missing(mpath)}")
    img = decode_image(mpath, (camera.width, camera.height), "mask")
    usable = img != 0 if img.ndim == 2 else np.any(img != 0, axis=2)
    if not usable.any():
        raise InputError(f"{mpath}: the mask has no usable (nonzero) pixel")
    usable.setflags(write=False)
    return usable


def _folder(root: Path) -> Source:
    cpath = root / "calib.yaml"
    data = read_mapping(cpath)
    if data.get("cameras") is not None:
        names = ", ".join(name for name, _ in _rig_entries(cpath, data))
        raise InputError(f"{cpath}: 'cameras' lists the cameras of a rig ({names}): name "
                         "one with --camera NAME ('paretocal calibrate' takes all of them); in "
                         "Python, read one camera's frames with load_frames(paretocal.io."
                         "rig_source(FOLDER, NAME))")
    check_keys(cpath, data, CALIB_KEYS)
    camera = _folder_camera(root, cpath, data)
    mask = _folder_mask(root, cpath, data, camera)
    T_ref = None
    if data.get("T_cam_lidar") is not None:
        T_ref = check_rigid(data["T_cam_lidar"], str(cpath))
    pose = None
    if data.get("lidar_pose") is not None:
        pose = check_rigid(data["lidar_pose"], str(cpath), key="lidar_pose")
    layout = _points_layout(cpath, data.get("points"))
    options = _options(cpath, data)
    pairs = _pair(root, root / "images", root / "points")
    credit = _credit(cpath, data)
    board = folder_board(root, cpath, data)
    return Source("folder", root, [FrameFiles(s, i, p, camera, T_ref, mask, sensor_pose=pose,
                                              bin_layout=layout, credit=credit, board=board)
                                   for s, i, p in pairs], options)


#: The file beside calib.yaml that may describe the board instead of its ``board:`` section.
BOARD_FILE = "board.yaml"


def folder_board(root: Path, cpath: Path, data: dict, where: str = "board") -> Board | None:
    """The board of a generic folder: calib.yaml's ``board:`` section (``where`` in it), or
    the ``board:`` section of a ``board.yaml`` beside calib.yaml; None when neither is
    given. Both at once are refused (which one is meant cannot be guessed)."""
    bpath = root / BOARD_FILE
    beside = kind_of(bpath) is not None or bpath.is_symlink()
    if data.get("board") is not None:
        if beside and where == "board":
            raise InputError(f"{cpath}: board is given here and in {bpath}; keep one")
        return read_board(data["board"], cpath, where)
    if not beside or where != "board":
        return None
    doc = read_mapping(bpath)
    check_keys(bpath, doc, ("board",))
    if doc.get("board") is None:
        raise InputError(f"{bpath}: missing 'board' section (kind, squares, square_m, size_m)")
    return read_board(doc["board"], bpath)


def _credit(cpath: Path, data: dict) -> str | None:
    """calib.yaml's ``credit``: the line figures of this data carry (a dataset's licence may
    require one)."""
    value = data.get("credit")
    if value is not None and (not isinstance(value, str) or not value.strip()):
        raise InputError(f"{cpath}: credit must be a line of text (the data's credit for "
                         f"figures), got {quote(value)}")
    return value.strip() if value else None


#: The keys of one entry of a rig calib.yaml's ``cameras``.
RIG_CAMERA_KEYS = ("name", "camera", "camera_info", "mask", "T_cam_lidar", "images", "board")
#: The keys of a calib.yaml: a single camera's (:func:`_folder`) and a rig's top level
#: (:func:`rig_cameras`), and those of a ``camera`` section in the K / width / height form.
CALIB_KEYS = ("camera", "camera_info", "T_cam_lidar", "lidar_pose", "points", "mask",
              "init_error", "credit", "board")
RIG_KEYS = ("cameras", "lidar_pose", "points", "init_error", "credit", "board")
CAMERA_KEYS = ("K", "width", "height", "model", "D", "xi", "mask")


def check_keys(cpath: str | Path, mapping: dict, allowed, where: str = "") -> None:
    """An :class:`InputError` naming the file, where in it, the keys ``mapping`` holds that
    are not ``allowed`` and the allowed ones: a typo (``widht``) is named as such, not
    reported as a missing key."""
    unknown = sorted(set(map(str, mapping)) - set(allowed))
    if unknown:
        at = f"{where}: " if where else ""
        raise InputError(f"{cpath}: {at}unknown key(s) {key_list(unknown)} "
                         f"(expected {', '.join(allowed)})")


def is_rig(source: str | Path) -> bool:
    """Whether ``source`` is a generic folder whose calib.yaml lists several cameras
    (``cameras:``); nothing but calib.yaml is read."""
    cpath = Path(source) / "calib.yaml"
    if not cpath.is_file():
        return False
    return read_mapping(cpath).get("cameras") is not None


def _rig_entries(cpath: Path, data: dict) -> list[tuple[str, dict]]:
    """The ``cameras`` of a rig calib.yaml as (name, entry): a list of entries with ``name``,
    or a mapping name -> entry. Names are unique and non-empty."""
    cams = data.get("cameras")
    if isinstance(cams, dict):
        items = []
        for name, entry in cams.items():
            if isinstance(entry, dict) and entry.get("name") not in (None, name):
                raise InputError(f"{cpath}: cameras.{excerpt(name)}.name is {quote(entry['name'])}; leave it "
                                 "out or make it the key")
            items.append((name, entry))
    elif isinstance(cams, list):
        items = [(e.get("name") if isinstance(e, dict) else None, e) for e in cams]
    else:
        raise InputError(f"{cpath}: cameras must be a list of cameras (each with name, camera, "
                         "T_cam_lidar and images) or a mapping from name to camera")
    if not items:
        raise InputError(f"{cpath}: cameras lists no camera")
    out, seen = [], set()
    for i, (name, entry) in enumerate(items):
        where = f"cameras[{i}]" if isinstance(cams, list) else f"cameras.{excerpt(name)}"
        if not isinstance(entry, dict):
            raise InputError(f"{cpath}: {where} must be a mapping with name, camera, "
                             "T_cam_lidar and images")
        if not isinstance(name, (str, int)) or isinstance(name, bool) or not str(name).strip():
            raise InputError(f"{cpath}: {where}.name is missing (each camera needs a name)")
        name = str(name).strip()
        if not re.fullmatch(r"[A-Za-z0-9_.-]+", name) or name in (".", ".."):
            raise InputError(f"{cpath}: {where}.name {quote(name)}: use letters, digits, '_', '-' "
                             "and '.' only (it names the camera's output folder)")
        if name in seen:
            raise InputError(f"{cpath}: cameras: the name {name!r} is given twice")
        seen.add(name)
        check_keys(cpath, entry, RIG_CAMERA_KEYS, f"cameras.{name}")
        out.append((name, entry))
    return out


def _rig_camera(root: Path, cpath: Path, name: str, entry: dict, shared: dict) -> Source:
    """One camera of a rig folder as a generic-folder source over the shared points/."""
    prefix = f"cameras.{name}"
    try:
        camera = _folder_camera(root, cpath, entry)
        mask = _folder_mask(root, cpath, entry, camera)
    except InputError as exc:
        # The single-camera messages name camera.K, mask, ...: say which camera's.
        text = str(exc)
        head = f"{cpath}: "
        if text.startswith(head):
            text = f"{head}{prefix}: {text[len(head):]}"
        raise InputError(text) from None
    if entry.get("T_cam_lidar") is None:
        raise InputError(f"{cpath}: {prefix}.T_cam_lidar is missing (each camera of a rig "
                         "needs its initial extrinsic)")
    T_ref = check_rigid(entry["T_cam_lidar"], str(cpath), key=f"{prefix}.T_cam_lidar")
    images = entry.get("images")
    if not isinstance(images, str) or not images.strip():
        raise InputError(f"{cpath}: {prefix}.images is missing: the camera's image folder, "
                         "relative to the rig folder")
    image_dir = root / images
    if kind_of(_link_file(image_dir)) != "a folder":
        raise InputError(f"{cpath}: {prefix}.images: folder {excerpt(image_dir, PATH_CHARS)} "
                         f"{missing(image_dir, 'a folder')}")
    pairs = _pair(root, image_dir, root / "points")
    board = (read_board(entry["board"], cpath, f"{prefix}.board")
             if entry.get("board") is not None else shared["board"])
    frames = [FrameFiles(s, i, p, camera, T_ref, mask, sensor_pose=shared["pose"],
                         bin_layout=shared["layout"], credit=shared["credit"], board=board)
              for s, i, p in pairs]
    return Source("folder", root, frames, dict(shared["options"], rig_camera=name))


def rig_cameras(source: str | Path) -> list[tuple[str, Source]]:
    """The cameras of a rig folder, as ``(name, Source)`` in calib.yaml's order.

    A rig folder is a generic folder whose calib.yaml has ``cameras:`` instead of ``camera``
    and ``T_cam_lidar``: a list of ``{name, camera (or camera_info), T_cam_lidar, images,
    mask}`` (or a mapping name -> entry), with one shared ``points/`` folder and the shared
    keys of a single-camera calib.yaml (``lidar_pose``, ``points``, ``init_error``). Each
    camera's source is that of a single-camera folder with its images; its frames' ``T_ref``
    is the camera's ``T_cam_lidar``.
    """
    root = Path(source)
    if not root.is_dir():
        raise InputError(not_found(root, "source folder", "a folder"))
    cpath = root / "calib.yaml"
    data = read_mapping(cpath)
    if data.get("cameras") is None:
        raise InputError(f"{cpath}: not a rig: no 'cameras' list")
    entries = _rig_entries(cpath, data)
    clash = [k for k in ("camera", "camera_info", "T_cam_lidar", "mask") if data.get(k) is not None]
    if not clash:
        check_keys(cpath, data, RIG_KEYS)
    if clash:
        raise InputError(f"{cpath}: {', '.join(clash)} at the top level and 'cameras' both "
                         "given; with several cameras each entry of cameras holds its own")
    shared: dict[str, Any] = {
        "pose": None, "layout": _points_layout(cpath, data.get("points")),
        "options": _options(cpath, data), "credit": _credit(cpath, data),
        "board": folder_board(root, cpath, data)}
    if data.get("lidar_pose") is not None:
        shared["pose"] = check_rigid(data["lidar_pose"], str(cpath), key="lidar_pose")
    return [(name, _rig_camera(root, cpath, name, entry, shared)) for name, entry in entries]


def rig_source(source: str | Path, name: str) -> Source:
    """The camera ``name`` of the rig folder ``source`` (:func:`rig_cameras`)."""
    cams = dict(rig_cameras(source))
    if name not in cams:
        raise SettingsError(f"--camera {name}: {Path(source) / 'calib.yaml'} lists the cameras "
                            f"{', '.join(cams)}")
    return cams[name]


def _points_layout(cpath: Path, section) -> str | None:
    """The declared ``.bin`` layout of calib.yaml's ``points: {layout: NAME}`` (or None)."""
    if section is None:
        return None
    if not isinstance(section, dict) or set(section) - {"layout"}:
        raise InputError(f"{cpath}: points must be a mapping with the key layout (one of "
                         f"{', '.join(BIN_LAYOUTS)})")
    name = section.get("layout")
    if name is None:
        return None
    if str(name).lower() not in BIN_LAYOUTS:
        raise InputError(f"{cpath}: points.layout {quote(name)} is not one of "
                         f"{', '.join(BIN_LAYOUTS)}")
    return str(name).lower()


def _options(cpath: Path, data: dict) -> dict:
    """What calib.yaml states about the dataset (:attr:`Source.options`)."""
    if data.get("init_error") is None:
        return {}
    return {"init_error": _init_error(cpath, data["init_error"])}


def source_options(source: str | Path | Source | list[Frame]) -> dict:
    """What a dataset states about itself (:attr:`Source.options`: calib.yaml's
    ``init_error`` as ``(deg, m)``), read from its calib.yaml alone: no frame is listed, so
    nothing is said twice. A source with no calib.yaml (KITTI) states nothing; a rig folder
    states it for all its cameras. Frames already loaded state what their source stated
    (:attr:`Frame.options`), where every frame states the same."""
    if isinstance(source, Source):
        return dict(source.options)
    if isinstance(source, (list, tuple)):
        frames = list(source)
        first = frames[0].options if frames else {}
        return {k: v for k, v in first.items() if all(f.options.get(k) == v for f in frames)}
    cpath = Path(source) / "calib.yaml"
    if not cpath.is_file():
        return {}
    return _options(cpath, read_mapping(cpath))


def positive_pair(items) -> tuple[float, float] | None:
    """A stated initial error ``(deg, m)`` from two items that are finite positive numbers,
    else None (the caller names the file or option)."""
    try:
        deg, m = (float(v) for v in items)
    except (TypeError, ValueError):
        return None
    ok = math.isfinite(deg) and math.isfinite(m) and deg > 0 and m > 0
    return (deg, m) if ok else None


def _init_error(cpath: Path, value) -> tuple[float, float]:
    """calib.yaml ``init_error``: ``[deg, m]`` or ``{rotation_deg: .., translation_m: ..}``."""
    if isinstance(value, dict):
        value = [value.get("rotation_deg"), value.get("translation_m")]
    pair = positive_pair(value)
    if pair is None:
        raise InputError(f"{cpath}: init_error must be [DEG, M] (or rotation_deg and "
                         f"translation_m), two positive numbers, got {quote(value)}")
    return pair


def detect_source(source: Path, camera_index: int = 2) -> Source:
    """Detect the layout of ``source`` and list its frames (nothing heavy is read yet)."""
    root = Path(source)
    if not root.exists():
        raise InputError(not_found(root, "source folder"))
    if is_bag(root) and not (root / "calib.yaml").is_file():
        raise InputError(f"{root}: a ROS bag; extract its frames to a folder first ("
                         f"{extract_hint(root)}) and pass that folder")
    if not root.is_dir():
        raise InputError(f"{root}: source must be a folder")
    if not 0 <= camera_index <= 3:
        raise SettingsError(f"--camera {camera_index}: must be 0, 1, 2 or 3")
    if kind_of(root / "calib.yaml") or (root / "calib.yaml").is_symlink():
        # The folder's calib.yaml, read or refused by name: a broken link, a FIFO, a folder.
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
            _check_slice(spec, token, a, b, len(names), step)
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


def _check_slice(spec: str, token: str, a: int | None, b: int | None, n: int,
                 step: int | None) -> None:
    """Refuse a slice of the frames that reaches beyond them, as a single index beyond them
    is refused: ``0:50`` of 10 frames would silently take 10."""
    out = [v for v in (a, b) if v is not None and not -n <= v <= n]
    if not out:
        return
    every = "" if step is None else f":{step}"
    if a is not None and -n <= a < n:
        hint = f"{a}:{n}{every}"
    else:
        hint = f"0:{n}{every}"
    raise SettingsError(f"--frames {spec}: {token!r} reaches index {out[0]}, beyond the "
                        f"source's {n} frames (indices 0 to {n - 1}); {hint} ends at the "
                        "last one")


def frame_mask(camera: Camera, mask: np.ndarray | None) -> np.ndarray | None:
    """``mask`` (H, W) bool or None, and-ed with the pixels the lens model reaches
    (:attr:`Camera.valid_pixels`); None when every pixel is usable."""
    if not camera.ideal:
        reach = camera.valid_pixels
        if not reach.all():
            return reach if mask is None else mask & reach
    return mask


def read_frame(files: FrameFiles, clouds: dict | None = None) -> Frame:
    """Read one frame's image and points.

    The image is kept as stored, with the camera's full lens model: every projection goes
    through the model (nothing is undistorted, so no field of view is lost and no pixel is
    resampled). The frame's mask is the calib.yaml mask and-ed with the pixels the model
    reaches (for example the Mei model's fold-back region is masked). ``clouds``, a dict
    from points path to cloud, is a cache shared by the cameras of a rig: each cloud is read
    once.
    """
    cam = files.camera
    image = read_image(files.image_path, (cam.width, cam.height))
    mask = frame_mask(cam, files.mask)
    key = (files.points_path, files.bin_layout)
    cloud = clouds.get(key) if clouds is not None else None
    if cloud is None:
        cloud = read_cloud(files.points_path, bin_layout=files.bin_layout)
        if clouds is not None:
            clouds[key] = cloud
    return Frame(files.name, image, cloud.points, cam, files.T_ref, files.image_path,
                 files.points_path, kitti_rect=files.kitti_rect, mask=mask, ring=cloud.ring,
                 time=cloud.time, point_fields=dict(cloud.fields),
                 sensor_pose=files.sensor_pose, credit=files.credit, board=files.board)


def load_frames(source: str | Path | Source, frames: str | None = None,
                camera: int = 2) -> list[Frame]:
    """Detect the layout of ``source`` and read the selected frames.

    Parameters
    ----------
    source : path or Source
        A KITTI raw drive (or date) folder, a KITTI object ``training`` folder, or a generic
        folder with ``calib.yaml`` (docs/conventions.md section 2); or a source already
        detected (:func:`detect_source`, whose warnings are then not said again).
    frames : str, optional
        Selection spec (``0:10``, ``0,3,7``, stems); all frames by default.
    camera : int
        KITTI camera index (0-3 for raw, 2-3 for object); ignored by the generic layout.

    Returns
    -------
    list of Frame
    """
    src = source if isinstance(source, Source) else detect_source(Path(source), camera)
    return _read_selected(src, frames, None)


def load_rig_frames(cameras: list[tuple[str, Source]], frames: str | None = None
                    ) -> dict[str, list[Frame]]:
    """Read the selected frames of every camera of a rig (:func:`rig_cameras`), each point
    cloud once: the cameras' frames share their points arrays. ``frames`` selects by stem or
    by index into each camera's own frames."""
    clouds: dict = {}
    return {name: _read_selected(src, frames, clouds) for name, src in cameras}


def _read_selected(src: Source, frames: str | None, clouds: dict | None) -> list[Frame]:
    idx = select_frames([f.name for f in src.frames], frames)
    out = [read_frame(src.frames[i], clouds) for i in idx]
    for f in out:
        # Carried with the frames, so that calibrating them is calibrating the folder.
        f.options = {k: v for k, v in src.options.items() if k == "init_error"}
    # The readers note what they could not find (no intensity field, an odd time unit) per
    # file; say each thing once per source.
    notes: dict[str, Path] = {}
    for f in out:
        for w in f.point_fields.get("warnings", ()):
            notes.setdefault(w, f.points_path)
    for w, path in notes.items():
        log.warning("%s: %s", path, w)
    return out
