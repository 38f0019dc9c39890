"""The chosen extrinsic in other tools' formats, written beside ``extrinsic.yaml`` in every run.

- ``calib_velo_to_cam.txt``: KITTI's LiDAR-to-camera file (``calib_time``, ``R``, ``T``). For a
  KITTI source paretocal's ``T_cam_lidar`` is that of the rectified camera N,
  ``T_cam_lidar = [I | b] @ R_rect_00 @ Tr_velo_to_cam``; the file then holds
  ``Tr = ([I | b] @ R_rect_00)^-1 @ T_cam_lidar``, so KITTI tools (and paretocal's own KITTI
  loader) reproduce the chosen extrinsic from it. For other sources it holds ``T_cam_lidar``
  itself, and its ``calib_time`` line says so.
- ``tf_static.yaml``: a ROS static transform from parent ``camera`` to child ``lidar``, which in
  TF terms is the pose of the LiDAR in the camera frame, that is ``T_cam_lidar``; with the
  equivalent ROS 2 ``static_transform_publisher`` command line.
- ``extrinsic_inverse.yaml``: ``T_lidar_cam = T_cam_lidar^-1`` (camera -> LiDAR).

Every file is written atomically and has a reader, so round trips can be checked.
"""

from __future__ import annotations

import shlex
from datetime import datetime
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..geometry import check_rigid, invert
from .atomic import atomic_write_text
from .extrinsic import quaternion_pose
from .text import calib_matrix, read_kitti_calib, read_mapping

KITTI_FILE = "calib_velo_to_cam.txt"
TF_FILE = "tf_static.yaml"
INVERSE_FILE = "extrinsic_inverse.yaml"

_MONTHS = ("Jan", "Feb", "Mar", "Apr", "May", "Jun", "Jul", "Aug", "Sep", "Oct", "Nov", "Dec")


def kitti_rect_of(frames) -> np.ndarray | None:
    """The frames' common ``kitti_rect`` (``[I | b] @ R_rect_00``), or None.

    None when there are no frames, a frame has none (not a KITTI source), or the frames disagree
    (KITTI object frames from different drives): no single KITTI ``Tr`` then exists.
    """
    rects = [getattr(f, "kitti_rect", None) for f in frames or []]
    found = [r for r in rects if r is not None]
    if not rects or len(found) < len(rects):
        return None
    first = np.asarray(found[0], dtype=np.float64)
    if any(not np.allclose(r, first, rtol=0, atol=1e-12) for r in found[1:]):
        return None
    return first


def _kitti_time(when: datetime | None) -> str:
    when = when or datetime.now()
    return f"{when.day:02d}-{_MONTHS[when.month - 1]}-{when.year} {when:%H:%M:%S}"


def kitti_velo_to_cam_text(T_cam_lidar: np.ndarray, kitti_rect: np.ndarray | None = None,
                           version: str = "", when: datetime | None = None) -> str:
    """``calib_velo_to_cam.txt`` text in KITTI's format for the extrinsic ``T_cam_lidar``.

    With ``kitti_rect`` (``[I | b] @ R_rect_00`` of a KITTI source) ``R`` and ``T`` hold
    ``Tr = kitti_rect^-1 @ T_cam_lidar`` (LiDAR -> unrectified camera 0, as KITTI's file does);
    without it they hold ``T_cam_lidar`` itself. The ``calib_time`` line says which. Every line
    is ``key: values`` so that KITTI parsers that split on the first colon accept it.
    """
    T = np.asarray(T_cam_lidar, dtype=np.float64)
    who = f"paretocal {version}".strip()
    if kitti_rect is not None:
        # A true inverse (R_rect_00 is stored to 7 digits, so not exactly orthonormal): KITTI's
        # P_rect @ R_rect_00 @ Tr then reproduces K @ T_cam_lidar[:3] to rounding.
        Tr = np.linalg.inv(np.asarray(kitti_rect, dtype=np.float64)) @ T
        note = ("R|T = Tr_velo_to_cam, LiDAR -> unrectified camera 0 as in KITTI; "
                "T_cam_lidar = [I|b] R_rect_00 Tr for the rectified camera calibrated")
    else:
        Tr = T
        note = ("R|T = T_cam_lidar itself, LiDAR -> the calibrated camera's frame; "
                "no KITTI rectification applies (not a KITTI source)")
    return (f"calib_time: {_kitti_time(when)} ({who}; {note})\n"
            f"R: {' '.join(f'{v:.15e}' for v in Tr[:3, :3].ravel())}\n"
            f"T: {' '.join(f'{v:.15e}' for v in Tr[:3, 3])}\n")


def read_kitti_velo_to_cam(path: str | Path) -> np.ndarray:
    """The 4x4 ``[R | T]`` of a KITTI ``calib_velo_to_cam.txt`` (KITTI's ``Tr_velo_to_cam``).

    For a file written by :func:`write_exports` for a KITTI source, ``kitti_rect @`` this is
    the chosen ``T_cam_lidar``; for other sources it is ``T_cam_lidar`` itself.
    """
    path = Path(path)
    calib = read_kitti_calib(path)
    T = np.eye(4)
    T[:3, :3] = calib_matrix(calib, "R", (3, 3), path)
    T[:3, 3] = calib_matrix(calib, "T", (1, 3), path)[0]
    return check_rigid(T, str(path), key="[R | T]", orthonormalise=False)


def quaternion_xyzw(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(x, y, z, w)`` of a rotation matrix, with ``w >= 0``."""
    q = Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_quat()
    return -q if q[3] < 0 else q


def static_transform_publisher_args(T_parent_child: np.ndarray, parent: str = "camera",
                                    child: str = "lidar") -> str:
    """The ROS 2 ``static_transform_publisher`` command publishing ``T_parent_child``.

    ``--frame-id`` is the parent and ``--child-frame-id`` the child; the transform is the
    pose of the child in the parent frame (it maps child coordinates into the parent frame).
    """
    T = np.asarray(T_parent_child, dtype=np.float64)
    t, q = T[:3, 3], quaternion_xyzw(T[:3, :3])
    vals = " ".join(f"--{k} {v:.12g}" for k, v in zip(("x", "y", "z", "qx", "qy", "qz", "qw"),
                                                       (*t, *q)))
    return (f"ros2 run tf2_ros static_transform_publisher {vals} "
            f"--frame-id {shlex.quote(parent)} --child-frame-id {shlex.quote(child)}")


def tf_static_text(T_cam_lidar: np.ndarray, parent: str = "camera", child: str = "lidar",
                   version: str = "") -> str:
    """``tf_static.yaml``: the extrinsic as a ROS static transform ``parent -> child``.

    The layout follows a ``tf2_msgs/TFMessage`` as ``ros2 topic echo /tf_static`` prints it
    (``transforms[0].header.frame_id``, ``child_frame_id``, ``transform.translation``,
    ``transform.rotation``), plus the equivalent command line.
    """
    T = np.asarray(T_cam_lidar, dtype=np.float64)
    t, q = T[:3, 3], quaternion_xyzw(T[:3, :3])
    who = f"paretocal {version}".strip()
    head = (
        f"{who}: the chosen extrinsic as a ROS static transform.\n"
        f"Direction: parent '{parent}' -> child '{child}'. A TF from a parent to a child is the\n"
        f"pose of the child in the parent frame, so this is T_cam_lidar: it maps LiDAR points into\n"
        f"the camera frame, p_{parent} = R p_{child} + t (translation in metres, rotation as a unit\n"
        "quaternion x, y, z, w).\n"
        "The camera frame is x right, y down, z forward: ROS's optical frame convention (REP 103),\n"
        "so in a tree whose camera link is x forward the parent is the camera's *_optical_frame.\n"
        "For a tree with the LiDAR as the parent, publish T_lidar_cam (extrinsic_inverse.yaml)\n"
        f"with --frame-id {child} --child-frame-id {parent} instead; never both.\n")
    doc = {
        "transforms": [{
            "header": {"frame_id": parent},
            "child_frame_id": child,
            "transform": {
                "translation": {k: float(v) for k, v in zip("xyz", t)},
                "rotation": {k: float(v) for k, v in zip("xyzw", q)},
            },
        }],
        "direction": f"T_cam_lidar: maps {child} points into {parent}; pose of {child} in {parent}",
        "static_transform_publisher": static_transform_publisher_args(T, parent, child),
    }
    return ("".join(f"# {line}\n" for line in head.splitlines())
            + yaml.safe_dump(doc, sort_keys=False, width=1000))


def read_tf_static(path: str | Path) -> tuple[np.ndarray, str, str]:
    """Read the first transform of a ``tf_static.yaml``: ``(T_parent_child, parent, child)``."""
    path = Path(path)
    data = read_mapping(path)
    tfs = data.get("transforms")
    if not isinstance(tfs, list) or not tfs or not isinstance(tfs[0], dict):
        raise InputError(f"{path}: missing key 'transforms' (a list of transforms)")
    tf = tfs[0]
    try:
        parent = str(tf["header"]["frame_id"])
        child = str(tf["child_frame_id"])
        tr, rot = tf["transform"]["translation"], tf["transform"]["rotation"]
        t = np.array([float(tr[k]) for k in "xyz"])
        q = np.array([float(rot[k]) for k in "xyzw"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: transforms[0] lacks or has a bad {exc} (expected "
                         "header.frame_id, child_frame_id, transform.translation.x/y/z and "
                         "transform.rotation.x/y/z/w numbers)") from None
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
        raise InputError(f"{path}: transforms[0] has NaN or infinite values")
    return quaternion_pose(path, "transforms[0].transform.rotation", t, q), parent, child


def extrinsic_inverse_text(T_cam_lidar: np.ndarray, version: str = "") -> str:
    """``extrinsic_inverse.yaml``: ``T_lidar_cam`` (camera -> LiDAR), commented."""
    Ti = invert(T_cam_lidar)
    who = f"paretocal {version}".strip()
    head = (f"{who}: the INVERSE of the chosen extrinsic.\n"
            "T_lidar_cam maps points from the CAMERA frame into the LIDAR frame:\n"
            "p_lidar = T_lidar_cam @ [x, y, z, 1]; it is the pose of the camera in the LiDAR frame.\n"
            "T_lidar_cam = inverse(T_cam_lidar), where T_cam_lidar (LiDAR -> camera) is in\n"
            "extrinsic.yaml. As an --init file it is read as this inverse.\n")
    rows = [[float(v) for v in row] for row in Ti]
    return ("".join(f"# {line}\n" for line in head.splitlines())
            + yaml.safe_dump({"T_lidar_cam": rows}, default_flow_style=None, sort_keys=False,
                             width=1000))


def read_extrinsic_inverse(path: str | Path) -> np.ndarray:
    """Read ``T_lidar_cam`` (camera -> LiDAR) from an ``extrinsic_inverse.yaml``."""
    path = Path(path)
    data = read_mapping(path)
    if "T_lidar_cam" not in data:
        raise InputError(f"{path}: missing key 'T_lidar_cam'")
    return check_rigid(data["T_lidar_cam"], str(path), key="T_lidar_cam", orthonormalise=False)


def write_exports(out_dir: str | Path, T_cam_lidar: np.ndarray, kitti_rect: np.ndarray | None = None,
                  version: str = "", parent: str = "camera", child: str = "lidar") -> list[Path]:
    """Write ``calib_velo_to_cam.txt``, ``tf_static.yaml`` and ``extrinsic_inverse.yaml``.

    Parameters
    ----------
    out_dir : path
        The run directory.
    T_cam_lidar : ndarray, shape (4, 4)
        The chosen extrinsic (LiDAR -> camera).
    kitti_rect : ndarray, shape (4, 4), optional
        ``[I | b] @ R_rect_00`` of a KITTI source (see :func:`kitti_rect_of`); the KITTI file
        then holds KITTI's ``Tr_velo_to_cam`` rather than ``T_cam_lidar``.
    version : str
        paretocal's version, named in each file.
    parent, child : str
        TF frame names of the camera and of the LiDAR.

    Returns
    -------
    list of Path
        The files written.
    """
    out = Path(out_dir)
    T = np.asarray(T_cam_lidar, dtype=np.float64)
    files = {
        KITTI_FILE: kitti_velo_to_cam_text(T, kitti_rect, version),
        TF_FILE: tf_static_text(T, parent, child, version),
        INVERSE_FILE: extrinsic_inverse_text(T, version),
    }
    for name, text in files.items():
        atomic_write_text(out / name, text)
    return [out / name for name in files]
