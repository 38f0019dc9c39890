"""Reading and writing a lone extrinsic (``--init`` files, ``extrinsic.yaml``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from ..errors import InputError, excerpt, first_line, key_list, quote
from ..geometry import check_rigid
from .atomic import atomic_write_text
from .text import MAX_TEXT_BYTES, read_mapping


#: Words in TF frame names that say which frame is the LiDAR's and which the camera's.
LIDAR_WORDS = ("lidar", "velo", "laser", "ouster", "os_sensor", "hesai", "pandar", "livox",
               "rslidar", "scan", "points", "cloud")
CAMERA_WORDS = ("cam", "optical", "image")


def read_extrinsic(path: str | Path, kitti_rect: np.ndarray | None = None) -> np.ndarray:
    """Read ``T_cam_lidar`` (4x4, LiDAR -> camera, metres) from any file the tool writes or a
    common form of it.

    Accepted, by what the file holds:

    * ``T_cam_lidar``: a 4x4 (or 3x4) matrix, or a mapping with ``translation`` (``[x, y, z]``
      or ``{x, y, z}``) and a rotation as ``quaternion_xyzw`` / ``quaternion_wxyz`` (lists)
      or ``rotation`` / ``quaternion`` (a mapping ``{x, y, z, w}``); ``extrinsic.yaml``;
    * ``T_lidar_cam``: the same forms, inverted (``extrinsic_inverse.yaml``);
    * ``transforms``: a ROS TF list (``tf_static.yaml``); the transform between a camera and a
      LiDAR frame is taken, in whichever direction it is stored;
    * ``R:`` and ``T:`` lines (``calib_velo_to_cam.txt``): KITTI's ``Tr_velo_to_cam`` to the
      unrectified camera 0, so ``kitti_rect`` (``[I | b] @ R_rect_00`` of the KITTI source,
      see :func:`needs_kitti_rect`) turns it into ``T_cam_lidar``; a file the tool wrote for a
      non-KITTI source holds ``T_cam_lidar`` itself and says so.

    Raises :class:`InputError` naming the file and the keys it found when none of these is
    there, or the values are not a finite rigid transform.

    Parameters
    ----------
    path : str or Path
        The file (YAML, JSON or KITTI calibration text).
    kitti_rect : ndarray, shape (4, 4), optional
        ``[I | b] @ R_rect_00`` of the KITTI source, for a ``calib_velo_to_cam.txt``.

    Returns
    -------
    ndarray, shape (4, 4)
        ``T_cam_lidar`` (m).
    """
    path = Path(path)
    if _kitti_text(path) is not None:
        from .exports import read_kitti_velo_to_cam

        T = read_kitti_velo_to_cam(path)
        if needs_kitti_rect(path):
            if kitti_rect is None:
                raise InputError(f"{path}: holds KITTI's Tr_velo_to_cam (LiDAR -> unrectified "
                                 "camera 0), which only a KITTI source's rectification turns "
                                 "into T_cam_lidar; use it with a KITTI source")
            T = np.asarray(kitti_rect, dtype=np.float64) @ T
        return T
    data = read_mapping(path)
    for key, inverse in (("T_cam_lidar", False), ("T_lidar_cam", True)):
        if key in data:
            value = data[key]
            T = (_pose(path, key, value) if isinstance(value, dict)
                 else check_rigid(value, str(path), key=key))
            return _inverse(T) if inverse else T
    if "transforms" in data:
        return _from_tf(path, data["transforms"])
    raise InputError(f"{path}: no extrinsic found (keys: {key_list(data)}); expected T_cam_lidar (a 4x4 "
                     "matrix, or translation + quaternion), T_lidar_cam, transforms (a ROS "
                     "tf_static list) or KITTI's R: and T: lines")


def needs_kitti_rect(path: str | Path) -> bool:
    """Whether ``path`` is a KITTI ``calib_velo_to_cam.txt`` holding ``Tr_velo_to_cam`` (to the
    unrectified camera 0), so that :func:`read_extrinsic` needs the source's ``kitti_rect``."""
    text = _kitti_text(Path(path))
    return text is not None and "T_cam_lidar itself" not in text



def read_init(path: str | Path, source, camera: int | None = None) -> np.ndarray:
    """The initial extrinsic of a calibration of ``source`` (``--init``): ``T_cam_lidar``
    (4x4) read from ``path`` by :func:`read_extrinsic`.

    A KITTI ``calib_velo_to_cam.txt`` holds ``Tr_velo_to_cam`` (to the unrectified camera 0):
    it is taken through the rectification of ``source`` (a folder, a source already detected
    by :func:`~paretocal.io.detect_source`, or its loaded frames, a list of
    :class:`~paretocal.io.Frame`), which must then be a KITTI source; ``camera`` is the
    camera index used to detect a folder (default 2).

    Raises :class:`InputError` naming the file when it cannot be read, or when it holds KITTI's
    ``Tr`` and ``source`` is not a KITTI source.

    Parameters
    ----------
    path : str or Path
        The file, in any form :func:`read_extrinsic` reads.
    source : str or Path or Source or list of Frame
        The dataset calibrated (for KITTI's rectification).
    camera : int, optional
        The KITTI camera index used to detect a folder (default 2).

    Returns
    -------
    ndarray, shape (4, 4)
        ``T_cam_lidar`` (m).
    """
    from .exports import kitti_rect_of
    from .layouts import detect_source

    rect = None
    if needs_kitti_rect(path):
        if isinstance(source, (list, tuple)):
            frames = source
        else:
            frames = (source if hasattr(source, "frames")
                      else detect_source(Path(source), 2 if camera is None else camera)).frames
        rect = kitti_rect_of(frames)
        if rect is None:
            where = (getattr(source, "root", source) if not isinstance(source, (list, tuple))
                     else "the frames given")
            raise InputError(f"{path}: holds KITTI's Tr_velo_to_cam (LiDAR -> unrectified "
                             f"camera 0) but {where} is not a KITTI source; give "
                             "T_cam_lidar instead")
    return read_extrinsic(path, kitti_rect=rect)


def _kitti_text(path: Path) -> str | None:
    """The text of a KITTI-style ``key: values`` file with ``R:`` and ``T:`` lines, or None."""
    try:
        if (path.suffix.lower() in (".yaml", ".yml", ".json") or not path.is_file()
                or path.stat().st_size > MAX_TEXT_BYTES):
            return None                 # read_mapping names what is wrong
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    keys = {line.split(":", 1)[0].strip() for line in text.splitlines() if ":" in line}
    return text if {"R", "T"} <= keys else None


def _inverse(T: np.ndarray) -> np.ndarray:
    from ..geometry import invert

    return invert(T)


def _vector(path: Path, name: str, value, names: str) -> np.ndarray:
    """A list or an ``{x, y, z[, w]}`` mapping of finite numbers, in the order of ``names``."""
    try:
        v = (np.array([float(value[k]) for k in names]) if isinstance(value, dict)
             else np.asarray(value, dtype=np.float64).ravel())
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: {name} must be {len(names)} numbers or a mapping with keys "
                         f"{', '.join(names)} ({type(exc).__name__}: {first_line(exc)})") from None
    if v.size != len(names) or not np.all(np.isfinite(v)):
        raise InputError(f"{path}: {name} must be {len(names)} finite numbers, got {quote(value)}")
    return v


def _pose(path: Path, key: str, value: dict) -> np.ndarray:
    """A 4x4 transform from ``{translation, quaternion_xyzw | quaternion_wxyz | rotation}``."""
    if "translation" not in value:
        raise InputError(f"{path}: {key} needs 'translation' with the rotation (keys found: "
                         f"{key_list(value)})")
    t = _vector(path, f"{key}.translation", value["translation"], "xyz")
    if "quaternion_xyzw" in value:
        q = _vector(path, f"{key}.quaternion_xyzw", value["quaternion_xyzw"], "xyzw")
    elif "quaternion_wxyz" in value:
        q = np.roll(_vector(path, f"{key}.quaternion_wxyz", value["quaternion_wxyz"], "wxyz"), -1)
    else:
        name = next((k for k in ("rotation", "quaternion") if k in value), None)
        if name is None:
            raise InputError(f"{path}: {key} needs a rotation: quaternion_xyzw, quaternion_wxyz "
                             f"or rotation {{x, y, z, w}} (keys found: {key_list(value)})")
        if not isinstance(value[name], dict):
            raise InputError(f"{path}: {key}.{name} as a list is ambiguous (x, y, z, w or w, x, "
                             "y, z?); write quaternion_xyzw or quaternion_wxyz, or a mapping "
                             "with keys x, y, z, w")
        q = _vector(path, f"{key}.{name}", value[name], "xyzw")
    return quaternion_pose(path, f"the rotation of {key}", t, q)


def quaternion_pose(path: Path, name: str, t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The 4x4 transform of a translation ``t`` (3,) and a quaternion ``q`` (x, y, z, w),
    which must be of unit norm (to 1e-3: written values carry a few digits) and is then
    normalised; ``name`` says which rotation in the error."""
    from scipy.spatial.transform import Rotation

    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > 1e-3:
        raise InputError(f"{path}: {name} is not a unit quaternion (norm {norm:.6g})")
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(np.asarray(q, dtype=np.float64) / norm).as_matrix()
    T[:3, 3] = t
    return T


def _from_tf(path: Path, transforms) -> np.ndarray:
    """``T_cam_lidar`` from a ROS TF list: the transform between a LiDAR and a camera frame
    (``T_parent_child`` maps child coordinates into the parent frame)."""
    if not isinstance(transforms, list) or not transforms:
        raise InputError(f"{path}: transforms must be a non-empty list of ROS transforms")
    frames = []
    for k, tf in enumerate(transforms):
        try:
            parent, child = str(tf["header"]["frame_id"]), str(tf["child_frame_id"])
            tr, rot = tf["transform"]["translation"], tf["transform"]["rotation"]
        except (KeyError, TypeError):
            raise InputError(f"{path}: transforms[{k}] lacks header.frame_id, child_frame_id or "
                             "transform.translation/rotation") from None
        frames.append(f"{excerpt(parent, 40)} -> {excerpt(child, 40)}")
        kind = [_frame_kind(parent), _frame_kind(child)]
        if kind in (["camera", "lidar"], ["lidar", "camera"]):
            T = _pose(path, f"transforms[{k}].transform",
                      {"translation": tr, "rotation": rot})
            return T if kind[0] == "camera" else _inverse(T)
    more = f"; and {len(frames) - 3} more" if len(frames) > 3 else ""
    raise InputError(f"{path}: no transform between a camera and a LiDAR frame (found "
                     f"{'; '.join(frames[:3])}{more}); frame names must contain one of "
                     f"{', '.join(CAMERA_WORDS)} and one of {', '.join(LIDAR_WORDS)}")


def _frame_kind(name: str) -> str | None:
    low = name.lower()
    if any(w in low for w in LIDAR_WORDS):
        return "lidar"
    return "camera" if any(w in low for w in CAMERA_WORDS) else None


def extrinsic_yaml(T: np.ndarray, comment: str = "") -> str:
    """YAML text holding ``T_cam_lidar`` alone, readable by :func:`read_extrinsic`."""
    rows = [[float(f"{v:.10g}") for v in row] for row in np.asarray(T, dtype=np.float64)]
    head = "".join(f"# {line}\n" for line in comment.splitlines()) if comment else ""
    return head + yaml.safe_dump({"T_cam_lidar": rows}, default_flow_style=None, sort_keys=False)


def write_extrinsic(path: str | Path, T: np.ndarray, comment: str = "") -> None:
    """Write ``T_cam_lidar`` to a YAML file atomically.

    Parameters
    ----------
    path : str or Path
        The file (``extrinsic.yaml``); an ``--init`` file for a later run.
    T : ndarray, shape (4, 4)
        ``T_cam_lidar`` (LiDAR -> camera, m).
    comment : str
        Comment lines written above the matrix (``# ...``).
    """
    atomic_write_text(Path(path), extrinsic_yaml(T, comment))
