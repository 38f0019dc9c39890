"""Accuracy from random decalibrations of any dataset with a reference extrinsic, through the CLI.

Each trial draws a seeded correction, uniform per axis in +-ROT deg and +-TRANS m, and starts
from the extrinsic that this correction brings back to the dataset's reference (so the
correction to find lies in the box). It writes a *blind copy* of the dataset whose calibration
holds the perturbed extrinsic (symbolic links to the frames, the calibration file rewritten and
read back to check it), so the tool cannot see the reference, and runs

    paretocal calibrate COPY --init INIT.yaml --out RUN --quiet --no-figures
        [--frames ...] [--config ...] [--init-error DEG,M] [--extra options] [-- options]

then compares ``RUN/result.json`` with the reference and records the tool's own verdict
(``reliability.verdict`` and its reasons). The summary gives mean / median / p95 / max errors,
per-axis errors, success rates, wall times, and the verdict's honesty: how many results more than
1 deg or 10 cm off were flagged ``unreliable``, and how many correct ones were.

Datasets (``--source`` takes any folder ``paretocal`` reads):

* ``--dataset raw`` (default): the 20-frame KITTI raw drive of the sample data;
  ``--dataset object``: the single KITTI object frame;
* ``--source PATH``: a KITTI raw drive or date folder, a KITTI object ``training`` folder, or a
  generic folder (``calib.yaml`` with ``T_cam_lidar``, ``images/``, ``points/``), or a rig
  folder (``calib.yaml`` with ``cameras:``), whose cameras are calibrated at once
  (``calibrate --joint``): the start moves the LiDAR, so every camera's ``T_cam_lidar`` in the
  blind copy is its reference with the same correction undone, and the result compared is
  the first camera's. The blind copy
  of a generic folder links every entry of the folder (symbolic links resolved, including the
  one-line files that stand for a link where links were not kept) and rewrites ``calib.yaml``
  with ``T_cam_lidar`` set to the start, every other key unchanged;
* ``--variant NAME[,NAME...]`` (repeatable): rig variants of the source (``paretocal.testing``)
  written as generic folders: ``32beam`` / ``16beam`` (every 2nd / 4th ring), ``firing``
  (column-major order), ``packet`` (packet order with per-laser azimuth offsets, as an
  HDL-64E S2/S3 or Pandar64 driver writes it), ``shuffled`` (random order), ``vehicle`` (the
  cloud in a vehicle frame, the sensor 1.5 m from its origin; the reference becomes
  ``T_cam_lidar @ inv(sensor_pose)`` and ``calib.yaml`` gets ``lidar_pose``; ``vehicle+nopose``
  leaves it out, so the pose is estimated from the sweep), ``generic`` (unchanged, as a generic
  folder); ``a+b`` applies ``a`` then ``b``. Each variant is a dataset of its own, with the same
  trial seeds, holding the frames of ``--frames`` only (the runs then take all of them).

  A KITTI source's rings are exact (its scan order). A generic source (PandaSet, aiMotive) has
  no ring field: its rings are those the tool's own recovery finds in the sensor's frame
  (``paretocal.testing.recovered_truth``, the sensor located as the tool locates it, the rings
  judged near the camera's view at the reference). Its variant keeps the cloud in the source's
  frame (``lidar_pose`` only where the source's calib.yaml gives one, so the tool still locates
  the LiDAR), the points in ``.pcd`` (x, y, z, intensity, and time where the source has it),
  the images linked and every other calib.yaml key and folder entry the source's.

The figures the project reports (``DATA`` is the sample data folder, ``../shared/data``):

    # KITTI raw drive, 20 frames, +-10 deg / +-0.25 m, 20 trials
    .venv/bin/python benchmarks/accuracy.py --trials 20 --rot 10 --trans 0.25 \\
        --json runs/acc_kitti_10.json
    # aiMotive front pinhole and left fisheye (Mei), 20 frames each, 10 trials per box
    .venv/bin/python benchmarks/accuracy.py --source DATA/aimotive/front_pinhole \\
        --trials 10 --rot 5 --trans 0.2 --json runs/acc_aim_front_5.json
    .venv/bin/python benchmarks/accuracy.py --source DATA/aimotive/front_pinhole \\
        --trials 10 --rot 10 --trans 0.25 --json runs/acc_aim_front_10.json
    .venv/bin/python benchmarks/accuracy.py --source DATA/aimotive/left_fisheye \\
        --trials 10 --rot 5 --trans 0.2 --json runs/acc_aim_fisheye_5.json
    .venv/bin/python benchmarks/accuracy.py --source DATA/aimotive/left_fisheye \\
        --trials 10 --rot 10 --trans 0.25 --json runs/acc_aim_fisheye_10.json
    # KITTI rig variants, 20 frames, +-5 deg / +-0.2 m, 5 trials each
    .venv/bin/python benchmarks/accuracy.py \\
        --variant 32beam,16beam,firing,packet,shuffled,vehicle,vehicle+nopose --trials 5 \\
        --rot 5 --trans 0.2 --json runs/acc_variants_5.json
    # PandaSet front camera variants, the frames of the standing car
    .venv/bin/python benchmarks/accuracy.py --source DATA/pandaset/front --frames 0:12 \\
        --variant packet,shuffled,32beam,16beam --trials 5 --rot 5 --trans 0.2 \\
        --json runs/acc_pandaset_variants_5.json
    # KITTI raw drive, 2 frames (0 and 10), +-3 deg / +-0.1 m, 10 trials
    .venv/bin/python benchmarks/accuracy.py --frames 0,10 --trials 10 --rot 3 --trans 0.1 \\
        --json runs/acc_kitti_2frames_3.json

Other ranges: ``--rot 20 --trans 1.5`` (the paper's box), ``--frames 0:10`` for a subset.
``--init-error DEG,M`` passes the tool's ``--init-error`` (``--init-error box`` passes the trial
box ``ROT,TRANS``); ``--extra "OPTIONS"`` (repeatable) and everything after ``--`` are passed
to ``paretocal calibrate`` as they are. ``--api`` calls the library instead of the CLI (same
calibration, no process start; only ``--init-error`` of the passthrough options applies).
``--json FILE`` writes every trial and the summaries (rewritten after each trial); ``--keep DIR``
keeps the blind copies, variant folders and runs.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from paretocal.geometry import check_rigid, decalibrate, invert, pose_error
from paretocal.io import detect_source, load_frames, write_extrinsic
from paretocal.io.exports import kitti_velo_to_cam_text
from paretocal.io.text import read_mapping

DATA = Path(os.environ.get("PARETOCAL_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))
DATE = DATA / "kitti_raw" / "2011_09_26"
OBJECT = DATA / "kitti_object" / "training"
#: Per-axis errors (paretocal.geometry.pose_error): the correction's axes (translation in the
#: LiDAR frame, those of the verdict's intervals), then the translation in the camera frame.
AXES = ("x_lidar_cm", "y_lidar_cm", "z_lidar_cm", "yaw_deg", "pitch_deg", "roll_deg",
        "x_cam_cm", "y_cam_cm", "z_cam_cm")
#: A result is "off" beyond either limit (the verdict's honesty figures).
OFF_DEG, OFF_CM = 1.0, 10.0


# --- rig variants --------------------------------------------------------------------------

def _variant_steps():
    from paretocal import testing as T

    return {
        "generic": lambda v, k: v,
        "32beam": lambda v, k: T.decimate(v, 2),
        "16beam": lambda v, k: T.decimate(v, 4),
        "firing": lambda v, k: T.firing_order(v),
        # One sensor, one set of laser offsets: the same for every frame.
        "packet": lambda v, k: T.packet_order(v),
        "shuffled": lambda v, k: T.shuffled(v, k),
        "vehicle": lambda v, k: T.to_vehicle_frame(v),
        "nopose": lambda v, k: v,
    }


VARIANTS = ("generic", "32beam", "16beam", "firing", "packet", "shuffled", "vehicle", "nopose")


def parse_variants(values: list[str] | None) -> list[str]:
    """``--variant`` values (repeated and/or comma lists) -> names; ``a+b`` chains steps."""
    names = []
    for value in values or []:
        for name in (t.strip() for t in value.split(",")):
            if not name:
                continue
            bad = [s for s in name.split("+") if s not in VARIANTS]
            if bad:
                raise SystemExit(f"accuracy.py: unknown variant {bad[0]!r} (one of "
                                 f"{', '.join(VARIANTS)}, or steps joined by '+')")
            names.append(name)
    return list(dict.fromkeys(names))


def make_variant(points, name: str, k: int = 0):
    """The sweep as variant ``name``: a :class:`paretocal.testing.Variant` (points in the
    variant's order, sensor pose). ``points``: a KITTI sweep in its scan order (N, 4), or a
    sweep with its truth already made (a ``Variant``, see :func:`generic_truth`)."""
    from paretocal.testing import Variant, kitti_truth

    steps = _variant_steps()
    v = points if isinstance(points, Variant) else kitti_truth(points)
    for step in name.split("+"):
        v = steps[step](v, k)
    return v


def located_pose(frames, settings=None) -> np.ndarray:
    """The LiDAR's pose in the clouds' frame as the tool finds it
    (:func:`paretocal.inputs.locate_lidar`: calib.yaml's ``lidar_pose``, the cloud's own
    origin, or estimated from the first sweep), shape (4, 4), cloud <- sensor."""
    from paretocal.config import Settings
    from paretocal.inputs import locate_lidar

    moved, info, _ = locate_lidar(list(frames), settings or Settings())
    if info["source"] == "unknown":
        raise SystemExit(f"accuracy.py: {frames[0].points_path}: the LiDAR's pose is not "
                         f"known, so the sweep has no truth: {info.get('reason', '')}")
    pose = moved[0].sensor_pose
    return np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64)


def generic_truth(loaded: list) -> list:
    """The sweeps of a generic source's frames with the rings the tool's own recovery finds
    (:func:`paretocal.testing.recovered_truth`): about the sensor as the tool locates it, judged
    near the camera's view at the reference (as the tool judges them). One Variant per frame,
    in the cloud's frame with its stored order; ``time`` the file's where it has one."""
    from paretocal.config import FeatureSettings
    from paretocal.features.prepare import view_mask
    from paretocal.testing import recovered_truth

    pose = located_pose(loaded)
    out = []
    for k, f in enumerate(loaded):
        view = view_mask(f, [(f.camera, f.T_ref)], FeatureSettings())
        try:
            out.append(recovered_truth(f.points, pose, k, f.time, view))
        except ValueError as exc:
            raise SystemExit(f"accuracy.py: {f.points_path}: no truth for a variant: {exc}") \
                from None
    return out


def write_pcd(path: Path, points: np.ndarray, time: np.ndarray | None = None) -> None:
    """A binary PCD of ``points`` (N, 4) float32 x, y, z, intensity, and float64 ``time`` (s,
    shape (N,)) when given."""
    n = len(points)
    fields = [("x", "f4"), ("y", "f4"), ("z", "f4"), ("intensity", "f4")]
    if time is not None:
        fields.append(("time", "f8"))
    rec = np.empty(n, dtype=fields)
    for j, c in enumerate("xyz"):
        rec[c] = points[:, j]
    rec["intensity"] = points[:, 3]
    if time is not None:
        rec["time"] = time
    names = " ".join(name for name, _ in fields)
    head = (f"# .PCD v0.7\nVERSION 0.7\nFIELDS {names}\n"
            f"SIZE {' '.join(t[1:] for _, t in fields)}\nTYPE {' '.join('F' for _ in fields)}\n"
            f"COUNT {' '.join('1' for _ in fields)}\nWIDTH {n}\nHEIGHT 1\n"
            f"VIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary\n")
    Path(path).write_bytes(head.encode("ascii") + rec.tobytes())


def _rows(T) -> list[list[float]]:
    return [[float(x) for x in row] for row in np.asarray(T, dtype=np.float64)]


def build_variant(source: Path, name: str, dst: Path, frames: str | None = None,
                  camera: int = 2, cache: dict | None = None
                  ) -> tuple[Path, np.ndarray, np.ndarray]:
    """A generic folder at ``dst`` holding the ``source``'s frames as variant ``name``.

    Images are symbolic links. For a KITTI source (rectified images: the camera is the pinhole
    ``K`` of the rectified camera) the points are float32 ``.bin`` (x, y, z, intensity) in the
    variant's order; ``calib.yaml`` holds the camera, the reference ``T_cam_lidar`` (for a cloud
    moved to a vehicle frame ``T_ref @ inv(sensor_pose)``) and, when the sensor is not at the
    cloud's origin, ``lidar_pose`` (the LiDAR's pose in the cloud's frame, 4x4). A generic
    source is written as its module docstring says. ``cache``: a dict shared by the variants
    of one source, so that its frames are read and its truth made once.

    Returns the folder, its reference extrinsic and the LiDAR's pose in the variant's cloud
    frame (a KITTI source's: identity unless moved to a vehicle frame; a generic source's:
    where the tool locates it, moved with the cloud).
    """
    key = (str(Path(source).resolve()), frames, camera)
    if cache is not None and key in cache:
        src, loaded, truths = cache[key]
    else:
        src = detect_source(Path(source), camera)
        loaded = load_frames(source, frames, camera)
        truths = None
    T_src = loaded[0].T_ref
    if T_src is None:
        raise SystemExit(f"accuracy.py: {source} has no T_cam_lidar: no reference to measure "
                         "against")
    if any(f.T_ref is None or not np.allclose(f.T_ref, T_src, atol=1e-9) for f in loaded):
        raise SystemExit(f"accuracy.py: {source}: the frames' extrinsics differ; a variant "
                         "folder holds one calibration")
    kitti = src.layout in ("kitti_raw", "kitti_object")
    if truths is None:
        truths = [f.points for f in loaded] if kitti else generic_truth(loaded)
        if cache is not None:
            cache[key] = (src, loaded, truths)
    (dst / "images").mkdir(parents=True)
    (dst / "points").mkdir()
    moved = sensor = None
    for k, (f, truth) in enumerate(zip(loaded, truths)):
        v = make_variant(truth, name, k)
        if moved is None:
            # The variant's sensor pose over the source's: what the variant did to the cloud.
            sensor = v.sensor_pose
            moved = sensor @ invert(np.eye(4) if kitti else truth.sensor_pose)
        if kitti:
            v.points.astype(np.float32).tofile(dst / "points" / f"{f.name}.bin")
        else:
            write_pcd(dst / "points" / f"{f.name}.pcd", v.points,
                      None if f.time is None else v.time)
        image = Path(f.image_path).resolve()
        (dst / "images" / f"{f.name}{image.suffix.lower()}").symlink_to(image)
    T_ref = T_src @ invert(moved)
    keep_pose = "nopose" not in name.split("+")
    if kitti:
        calib = {"camera": {"model": "pinhole", "K": _rows(loaded[0].camera.K),
                            "width": int(loaded[0].camera.width),
                            "height": int(loaded[0].camera.height)},
                 "T_cam_lidar": _rows(T_ref)}
        if not np.allclose(moved, np.eye(4)) and keep_pose:
            calib["lidar_pose"] = _rows(moved)
        what = "KITTI frames"
    else:
        calib = _generic_calib(src.root, dst, T_ref, moved, keep_pose)
        what = "frames"
    header = (f"# {what} of {Path(source).resolve()} as rig variant '{name}'\n"
              "# (paretocal.testing); T_cam_lidar is the reference in the cloud's frame.\n")
    (dst / "calib.yaml").write_text(header + yaml.safe_dump(calib, sort_keys=False,
                                                            default_flow_style=None))
    return dst, T_ref, sensor


def _generic_calib(root: Path, dst: Path, T_ref: np.ndarray, moved: np.ndarray,
                   keep_pose: bool) -> dict:
    """The calib.yaml of a generic source's variant: the source's keys with the reference in
    the variant's frame and its ``lidar_pose`` (when it gives one) moved with the cloud; every
    folder entry other than calib.yaml, images and points linked, so relative references
    (masks, camera_info files) still hold."""
    data = dict(read_mapping(root / "calib.yaml"))
    for entry in sorted(root.iterdir()):
        if entry.name not in ("calib.yaml", "images", "points"):
            target = resolve_entry(entry)
            (dst / entry.name).symlink_to(target, target_is_directory=target.is_dir())
    data["T_cam_lidar"] = _rows(T_ref)
    if data.get("lidar_pose") is not None:
        if keep_pose:
            data["lidar_pose"] = _rows(moved @ np.asarray(data["lidar_pose"], dtype=np.float64))
        else:
            del data["lidar_pose"]
    return data


# --- blind copies ---------------------------------------------------------------------------

def resolve_entry(path: Path) -> Path:
    """The real target of a folder entry: symbolic links resolved, and a small one-line file
    without a suffix that names an existing path relative to its folder (what git writes for a
    link where links are not kept, like aiMotive's ``points -> ../points``) followed."""
    path = Path(path)
    if path.is_symlink():
        return path.resolve()
    if path.is_file() and not path.suffix and path.stat().st_size < 1024:
        try:
            text = path.read_text(encoding="utf-8").strip()
        except (UnicodeDecodeError, OSError):
            return path.resolve()
        if text and "\n" not in text and "\0" not in text:
            target = path.parent / text
            if target.exists():
                return resolve_entry(target) if target.is_symlink() else target.resolve()
    return path.resolve()


def folder_reference(root: Path) -> np.ndarray:
    """``T_cam_lidar`` of a generic folder's ``calib.yaml`` (the reference)."""
    cpath = Path(root) / "calib.yaml"
    data = read_mapping(cpath)
    if data.get("T_cam_lidar") is None:
        raise SystemExit(f"accuracy.py: {cpath} has no T_cam_lidar: no reference to measure "
                         "against")
    return check_rigid(data["T_cam_lidar"], str(cpath))


def _linked_folder(root: Path, dst: Path) -> Path:
    """``dst/<root's name>`` holding a symbolic link to the resolved target of every entry of
    ``root`` but its ``calib.yaml`` (so relative references in a rewritten calib.yaml hold)."""
    out = Path(dst) / Path(root).resolve().name
    out.mkdir(parents=True)
    for entry in sorted(Path(root).iterdir()):
        if entry.name != "calib.yaml":
            (out / entry.name).symlink_to(resolve_entry(entry),
                                          target_is_directory=resolve_entry(entry).is_dir())
    return out


def blind_copy_folder(root: Path, T_cam_lidar: np.ndarray, dst: Path) -> Path:
    """A generic folder whose ``calib.yaml`` holds ``T_cam_lidar``, every other key unchanged.

    Every other entry of ``root`` (``images``, ``points``, masks, camera_info files, ...) is a
    symbolic link to its resolved target, so relative references in ``calib.yaml`` still hold.
    The copy is read back (its layout, frame count and extrinsic) before it is used.
    """
    root = Path(root)
    data = read_mapping(root / "calib.yaml")
    out = _linked_folder(root, dst)
    data = dict(data)
    data["T_cam_lidar"] = _rows(T_cam_lidar)
    header = (f"# Blind copy of {root.resolve()} for an accuracy trial: T_cam_lidar is the\n"
              "# perturbed start, not the dataset's reference; every other key is the original's.\n")
    (out / "calib.yaml").write_text(header + yaml.safe_dump(data, sort_keys=False,
                                                            default_flow_style=None))
    src = detect_source(out)
    check = src.frames[0].T_ref
    assert src.layout == "folder", "blind copy is not read as a generic folder"
    assert check is not None and np.allclose(check, T_cam_lidar, atol=1e-9), \
        "blind copy does not hold the extrinsic"
    again = read_mapping(out / "calib.yaml")
    assert {k: v for k, v in again.items() if k != "T_cam_lidar"} == \
        {k: v for k, v in read_mapping(root / "calib.yaml").items() if k != "T_cam_lidar"}, \
        "blind copy changed a calib.yaml key other than T_cam_lidar"
    return out


def rig_references(root: Path) -> list[np.ndarray]:
    """Every camera's ``T_cam_lidar`` in a rig folder's ``calib.yaml``, in its order."""
    from paretocal.io import rig_cameras

    return [src.frames[0].T_ref for _, src in rig_cameras(root)]


def blind_copy_rig(root: Path, G: np.ndarray, dst: Path) -> Path:
    """A rig folder whose cameras' ``T_cam_lidar`` are their references times ``G`` (the LiDAR
    moved by one correction; the cameras' relative poses kept), entries linked as
    :func:`blind_copy_folder` does, and read back."""
    from paretocal.io import rig_cameras

    root = Path(root)
    data = dict(read_mapping(root / "calib.yaml"))
    refs = rig_references(root)
    out = _linked_folder(root, dst)
    cams = data["cameras"]
    entries = list(cams.values()) if isinstance(cams, dict) else cams
    moved = [dict(e, T_cam_lidar=_rows(T @ G)) for e, T in zip(entries, refs)]
    data["cameras"] = (dict(zip(cams, moved)) if isinstance(cams, dict) else moved)
    header = (f"# Blind copy of {root.resolve()} for an accuracy trial: every T_cam_lidar is the\n"
              "# camera's reference with one LiDAR correction undone; the other keys are the "
              "original's.\n")
    (out / "calib.yaml").write_text(header + yaml.safe_dump(data, sort_keys=False,
                                                            default_flow_style=None))
    for (_, src), T in zip(rig_cameras(out), refs):
        assert np.allclose(src.frames[0].T_ref, T @ G, atol=1e-9), \
            "blind copy does not hold the extrinsics"
    return out


def blind_copy(date: Path, T_cam_lidar: np.ndarray, dst: Path, camera: int = 2) -> Path:
    """A KITTI raw date folder whose ``calib_velo_to_cam.txt`` holds ``T_cam_lidar``.

    ``date`` is a date folder holding one drive, or a drive folder. The drive is a symbolic
    link; ``calib_cam_to_cam.txt`` is copied. Since the tool's extrinsic for camera N is
    ``[I | b] R_rect_00 Tr``, the file gets ``Tr = ([I | b] R_rect_00)^-1 T`` (written by the
    same exporter as every run's ``calib_velo_to_cam.txt``). Returns the drive folder of the copy.
    """
    src = detect_source(date, camera)
    date = src.root.parent
    out = dst / date.name
    out.mkdir(parents=True)
    (out / "calib_cam_to_cam.txt").write_text((date / "calib_cam_to_cam.txt").read_text())
    (out / "calib_velo_to_cam.txt").write_text(
        kitti_velo_to_cam_text(T_cam_lidar, src.frames[0].kitti_rect, "blind accuracy trial"))
    drive = out / src.root.name
    drive.symlink_to(src.root.resolve(), target_is_directory=True)
    check = detect_source(drive, camera).frames[0].T_ref
    assert np.allclose(check, T_cam_lidar, atol=1e-9), "blind copy does not hold the extrinsic"
    return drive


def blind_copy_object(root: Path, T_cam_lidar: np.ndarray, dst: Path, camera: int = 2) -> Path:
    """A KITTI object ``training`` folder whose calib files hold ``T_cam_lidar``.

    Images and scans are symbolic links; each ``calib/<stem>.txt`` is rewritten with
    ``Tr_velo_to_cam = ([I | b] R0_rect)^-1 T`` and its other lines unchanged.
    """
    root = detect_source(root, camera).root
    out = dst / "training"
    (out / "calib").mkdir(parents=True)
    for d in (f"image_{camera}", "velodyne"):
        (out / d).symlink_to((root / d).resolve(), target_is_directory=True)
    for files in detect_source(root, camera).frames:
        cfile = root / "calib" / f"{files.name}.txt"
        Tr = np.linalg.inv(files.kitti_rect) @ T_cam_lidar
        lines = [f"Tr_velo_to_cam: {' '.join(f'{v:.12e}' for v in Tr[:3].ravel())}"
                 if line.startswith("Tr_velo_to_cam:") else line
                 for line in cfile.read_text().splitlines()]
        (out / "calib" / cfile.name).write_text("\n".join(lines) + "\n")
    check = detect_source(out, camera).frames[0].T_ref
    assert np.allclose(check, T_cam_lidar, atol=1e-9), "blind copy does not hold the extrinsic"
    return out


# --- datasets and trials --------------------------------------------------------------------

@dataclass
class Dataset:
    """One dataset to run the trials on."""

    label: str                     #: shown in the summary, and the folder name under the work dir
    layout: str                    #: "kitti_raw", "kitti_object", "folder" or "rig"
    path: Path                     #: what the blind copies are made from
    T_ref: np.ndarray
    variant: str | None = None
    sensor_pose: np.ndarray | None = None   #: the LiDAR's pose in the cloud's frame, if moved
    rows: list = field(default_factory=list)
    #: The folder holds the selected frames only (a variant): the runs take all of them.
    all_frames: bool = False


def layout_of(path: Path) -> str:
    """The layout name of ``path`` (a generic folder is recognised by its calib.yaml alone, so
    a folder whose ``points`` still has to be resolved is recognised too)."""
    if (Path(path) / "calib.yaml").is_file():
        from paretocal.io import is_rig

        return "rig" if is_rig(path) else "folder"
    return detect_source(path).layout


def make_copy(ds: Dataset, T: np.ndarray, dst: Path) -> Path:
    """The blind copy of ``ds`` holding ``T``."""
    if ds.layout == "kitti_raw":
        return blind_copy(ds.path, T, dst)
    if ds.layout == "kitti_object":
        return blind_copy_object(ds.path, T, dst)
    if ds.layout == "rig":
        return blind_copy_rig(ds.path, invert(ds.T_ref) @ T, dst)
    return blind_copy_folder(ds.path, T, dst)


def calibrate_options(args, ds: Dataset | None = None) -> list[str]:
    """The options passed to ``paretocal calibrate`` beyond source, init and out."""
    opts = []
    if args.frames and not (ds is not None and ds.all_frames):
        opts += ["--frames", args.frames]
    if args.config:
        opts += ["--config", args.config]
    if args.init_error:
        opts += ["--init-error", init_error_text(args)]
    for extra in args.extra or []:
        opts += shlex.split(extra)
    return opts + list(args.passthrough)


def init_error_text(args) -> str:
    if args.init_error.strip().lower() == "box":
        return f"{args.rot:g},{args.trans:g}"
    return args.init_error


def trial_start(k: int, args, T_ref: np.ndarray) -> np.ndarray:
    """Trial ``k``'s start: the reference with the inverse of a seeded correction."""
    return decalibrate(T_ref, args.rot, args.trans, 1000 + k)[0]


def _run_api(args, ds: Dataset, view: Path, T_init: np.ndarray) -> dict:
    import dataclasses

    from paretocal import calibrate
    from paretocal.config import Settings, load_settings, states_init_error
    from paretocal.errors import ParetocalError

    settings = load_settings(args.config) if args.config else Settings()
    if args.init_error:
        deg, m = (float(v) for v in init_error_text(args).split(","))
        settings = settings.replace(search={"init_error_deg": deg, "init_error_m": m})
    settings = dataclasses.replace(settings, frames=None if ds.all_frames else args.frames)
    try:
        # The folder itself, so that its calib.yaml's init_error applies as on the CLI.
        r = calibrate(view, T_init, settings, dataset_options=not (
            args.init_error or states_init_error(args.config)))
    except ParetocalError as exc:
        return {"exit": 2, "error": str(exc)}
    rel = r.reliability.to_dict() if r.reliability is not None else {}     # result.json's form
    return {"T": r.T_cam_lidar, "n": int(r.n_points), "verdict": rel.get("verdict"),
            "reasons": list(rel.get("reasons") or []), "reliability": rel}


def _run_cli(args, ds: Dataset, T_init: np.ndarray, trial: Path) -> dict:
    data = make_copy(ds, T_init, trial / "data")
    init = trial / "init.yaml"
    write_extrinsic(init, T_init)
    run = trial / "run"
    start = ["--joint"] if ds.layout == "rig" else ["--init", str(init)]
    cmd = [sys.executable, "-m", "paretocal.cli", "calibrate", str(data), *start,
           "--out", str(run), "--quiet", "--no-figures"] + calibrate_options(args, ds)
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode in (130, -2):
        raise KeyboardInterrupt
    if proc.returncode != 0:
        lines = proc.stderr.strip().splitlines()
        return {"exit": proc.returncode, "error": lines[-1] if lines else ""}
    doc = json.loads((run / ("joint/result.json" if ds.layout == "rig" else "result.json"))
                     .read_text())
    rel = doc.get("reliability") or {}
    return {"T": np.array(doc["T_cam_lidar"]), "n": int(doc["n_points"]),
            "verdict": rel.get("verdict"), "reasons": list(rel.get("reasons") or []),
            "reliability": rel}


def run_trial(k: int, args, ds: Dataset, work: Path, view: Path | None = None) -> dict:
    """One trial on ``ds``: its row (errors, per-axis errors, verdict, wall time)."""
    T_ref = ds.T_ref
    T_init = trial_start(k, args, T_ref)
    t0 = time.perf_counter()
    out = (_run_api(args, ds, view or ds.path, T_init) if args.api
           else _run_cli(args, ds, T_init, work / f"trial_{k:03d}"))
    e0 = pose_error(T_init, T_ref)
    row = {"dataset": ds.label, "trial": k, "start_deg": float(e0["rotation_deg"]),
           "start_cm": float(e0["translation_cm"]), "wall_s": time.perf_counter() - t0}
    if "error" in out:
        row.update({"exit": out["exit"], "error": out["error"], "rot_deg": None,
                    "trans_cm": None, "n": None, "verdict": None, "reasons": []})
        row.update({a: None for a in AXES})
        return row
    e = pose_error(out["T"], T_ref)
    row.update({"rot_deg": float(e["rotation_deg"]), "trans_cm": float(e["translation_cm"]),
                "n": out["n"], "verdict": out["verdict"], "reasons": out["reasons"]})
    row.update({a: float(e[a]) for a in AXES})
    row.update(interval_record(out.get("reliability") or {}, out["T"], T_ref))
    if ds.sensor_pose is not None:
        P = ds.sensor_pose
        row["sensor_cm"] = float(pose_error(out["T"] @ P, T_ref @ P)["translation_cm"])
        row["start_sensor_cm"] = float(pose_error(T_init @ P, T_ref @ P)["translation_cm"])
    row["T_cam_lidar"] = _rows(out["T"])
    return row


def interval_record(rel: dict, T: np.ndarray, T_ref: np.ndarray) -> dict:
    """A trial's 95 % intervals and what they claim to hold: ``interval_error`` per axis
    (cm, deg), the correction ``d`` with ``T_ref = T @ D(d)`` (docs/conventions.md section 1);
    ``half_width`` (None per undetermined axis) for a result judged ok, ``half_width_not_trusted``
    for an unreliable one; and what they were built from (``interval_parts``)."""
    from paretocal.geometry import correction_params
    from paretocal.quality import AXES as IV_AXES, TO_REPORT

    d = correction_params(invert(np.asarray(T)) @ np.asarray(T_ref)) * TO_REPORT
    iv = rel.get("intervals")
    untrusted = rel.get("intervals_not_trusted")
    parts = iv or untrusted or {}
    return {"interval_error": {a: float(v) for a, v in zip(IV_AXES, d)},
            "half_width": (iv or {}).get("half_width"),
            "half_width_not_trusted": (untrusted or {}).get("half_width"),
            "interval_parts": {k: parts.get(k) for k in ("alignment_px", "sampling_px",
                                                          "per_px", "bias", "jackknife_se")}}


def interval_figures(rows: list[dict], key: str = "half_width") -> dict | None:
    """How the intervals ``key`` of ``rows`` held, per axis and over all axis-trials (the
    undetermined axes left out): ``coverage`` (share with |error| <= half-width), the median
    of half-width / |error| and the median half-width over the 95th percentile of |error|."""
    from paretocal.quality import AXES as IV_AXES

    have = [r for r in rows if r.get(key)]
    if not have:
        return None
    out = {"trials": len(have), "axes": {}}
    hits = total = 0
    ratios = []
    for a in IV_AXES:
        pairs = [(abs(r["interval_error"][a]), r[key][a]) for r in have
                 if r[key].get(a) is not None]
        if not pairs:
            out["axes"][a] = {"determined": 0}
            continue
        err, half = np.array(pairs).T
        ok = int(np.sum(err <= half))
        hits, total = hits + ok, total + len(err)
        ratio = half / np.maximum(err, 1e-9)
        ratios += list(ratio)
        out["axes"][a] = {"determined": int(len(err)), "covered": ok,
                          "median_half_width": float(np.median(half)),
                          "p95_error": float(np.percentile(err, 95)),
                          "median_ratio": float(np.median(ratio)),
                          "median_half_width_over_p95_error":
                              float(np.median(half) / max(np.percentile(err, 95), 1e-9))}
    out["axis_trials"] = total
    out["coverage"] = hits / total if total else None
    out["median_ratio"] = float(np.median(ratios)) if ratios else None
    return out


def _interval_lines(fig: dict | None, what: str) -> list[str]:
    if fig is None:
        return [f"  {what}: none"]
    ax = fig["axes"]
    det = {a: v for a, v in ax.items() if v["determined"]}
    cov = (f"{100 * fig['coverage']:.0f} % of {fig['axis_trials']} axis-trials"
           if fig["axis_trials"] else "no axis determined")
    lines = [f"  {what} ({fig['trials']} results): |error| within the half-width on {cov} ("
             + ", ".join(f"{a} {v['covered']}/{v['determined']}" for a, v in det.items()) + ")"]
    if det:
        lines.append("    median half-width / |error|: " + ", ".join(
            f"{a} {v['median_ratio']:.2g}" for a, v in det.items())
            + f"; all axes {fig['median_ratio']:.2g}")
        lines.append("    median half-width / p95 |error|: " + ", ".join(
            f"{a} {v['median_half_width']:.3g}/{v['p95_error']:.3g} = "
            f"{v['median_half_width_over_p95_error']:.2g}" for a, v in det.items()))
    return lines


# --- summary --------------------------------------------------------------------------------

def _stats(v) -> dict:
    v = np.asarray(v, dtype=np.float64)
    if v.size == 0:
        return {}
    return {"mean": float(np.mean(v)), "median": float(np.median(v)),
            "p95": float(np.percentile(v, 95)), "max": float(np.max(v))}


def summary_figures(rows: list[dict]) -> dict:
    """The summary of ``rows`` as numbers (what ``summarise`` prints and --json stores)."""
    done = [r for r in rows if "error" not in r]
    R = np.array([r["rot_deg"] for r in done])
    Tc = np.array([r["trans_cm"] for r in done])
    s = {"trials": len(rows), "completed": len(done), "failed": len(rows) - len(done),
         "start_deg": _stats([r["start_deg"] for r in rows]),
         "start_cm": _stats([r["start_cm"] for r in rows]),
         "rotation_deg": _stats(R), "translation_cm": _stats(Tc),
         "axes_abs": {a: _stats(np.abs([r[a] for r in done])) for a in AXES},
         "within": {}, "wall_s": _stats([r["wall_s"] for r in done])}
    if any("sensor_cm" in r for r in done):
        s["translation_at_sensor_cm"] = _stats([r["sensor_cm"] for r in done])
        s["start_at_sensor_cm"] = _stats([r["start_sensor_cm"] for r in done])
    for rot, cm in ((1.0, 10.0), (0.5, 5.0), (0.3, 3.0)):
        s["within"][f"{rot:g}deg_{cm:g}cm"] = int(np.sum((R < rot) & (Tc < cm)))
    off = [r for r in done if not (r["rot_deg"] < OFF_DEG and r["trans_cm"] < OFF_CM)]
    good = [r for r in done if r["rot_deg"] < OFF_DEG and r["trans_cm"] < OFF_CM]
    s["verdict"] = {
        "off": len(off),
        "off_flagged": sum(r["verdict"] == "unreliable" for r in off),
        "off_passed": sum(r["verdict"] == "ok" for r in off),
        "correct": len(good),
        "correct_flagged": sum(r["verdict"] == "unreliable" for r in good),
        "no_verdict": sum(r["verdict"] not in ("ok", "unreliable") for r in done),
        "reasons": _reason_counts(done),
    }
    s["intervals"] = interval_figures(done)
    s["intervals_not_trusted"] = interval_figures(done, "half_width_not_trusted")
    return s


def _reason_counts(rows: list[dict]) -> dict:
    """How often each kind of reason was given (its text up to the first colon, numbers
    replaced by N)."""
    counts: dict[str, int] = {}
    for r in rows:
        for reason in r.get("reasons") or []:
            key = " ".join(re.sub(r"\d+(\.\d+)?", "N", reason.split(":")[0]).split())
            counts[key] = counts.get(key, 0) + 1
    return dict(sorted(counts.items(), key=lambda kv: -kv[1]))


def describe(ds: Dataset, args) -> str:
    via = "API" if args.api else "CLI (blind copy)"
    opts = calibrate_options(args)
    opts = [o for i, o in enumerate(opts)
            if o != "--frames" and (i == 0 or opts[i - 1] != "--frames")]
    extra = f", calibrate {' '.join(opts)}" if opts else ""
    return (f"start +-{args.rot} deg / +-{args.trans} m per axis, {ds.label} frames "
            f"{args.frames or 'all'}, via {via}{extra}")


def summarise(rows: list[dict], args, ds: Dataset | None = None) -> str:
    s = summary_figures(rows)
    n = len(rows)

    def fmt(d):
        if not d:
            return "n/a"
        return (f"mean {d['mean']:.3f}, median {d['median']:.3f}, p95 {d['p95']:.3f}, "
                f"max {d['max']:.3f}")

    head = describe(ds, args) if ds is not None else ""
    lines = [f"summary: {n} trials, {head}"]
    if ds is not None and ds.variant:
        lines.append(f"  variant: {ds.variant} (generic folder from {ds.path})")
    if s["failed"]:
        lines.append(f"  failed runs (non-zero exit, counted as not within): {s['failed']}/{n}: "
                     + "; ".join(f"trial {r['trial']} exit {r['exit']}: {r['error']}"
                                 for r in rows if "error" in r)[:600])
    lines += [f"  start (deg):       {fmt(s['start_deg'])}",
              f"  start (cm):        {fmt(s['start_cm'])}",
              f"  rotation (deg):    {fmt(s['rotation_deg'])}",
              f"  translation (cm):  {fmt(s['translation_cm'])}"]
    if "start_at_sensor_cm" in s:
        lines.insert(-2, f"  start at the LiDAR sensor (cm): {fmt(s['start_at_sensor_cm'])}")
    if "translation_at_sensor_cm" in s:
        lines.append(f"  translation at the LiDAR sensor (cm): {fmt(s['translation_at_sensor_cm'])}")
    for a in AXES:
        lines.append(f"  |{a}|: {fmt(s['axes_abs'][a])}")
    for key, ok in s["within"].items():
        rot, cm = key.replace("deg", "").replace("cm", "").split("_")
        lines.append(f"  within {float(rot)} deg and {cm} cm: {ok}/{n} ({100.0 * ok / n:.0f} %)")
    v = s["verdict"]
    lines.append(f"  verdict: {v['off']} result(s) off by {OFF_DEG:g} deg or {OFF_CM:g} cm or "
                 f"more, {v['off_flagged']} of them flagged unreliable ({v['off_passed']} "
                 f"passed as ok); {v['correct_flagged']} of {v['correct']} correct results "
                 f"flagged unreliable" + (f"; {v['no_verdict']} without a verdict"
                                          if v["no_verdict"] else ""))
    for reason, count in v["reasons"].items():
        lines.append(f"    reason x{count}: {reason}")
    lines += _interval_lines(s["intervals"], "95 % intervals, results judged ok")
    if s["intervals_not_trusted"] is not None:
        lines += _interval_lines(s["intervals_not_trusted"],
                                 "intervals not trusted, results judged unreliable")
    if s["wall_s"]:
        lines.append(f"  wall time per calibration (s): median {s['wall_s']['median']:.0f}, "
                     f"max {s['wall_s']['max']:.0f}")
    return "\n".join(lines)


# --- main -----------------------------------------------------------------------------------

def datasets(args, work: Path) -> list[Dataset]:
    """The datasets of the command line (variant folders are built under ``work``)."""
    if args.source is not None:
        # "DATA/" stands for the data folder, as in the commands the docs show.
        source = Path(args.source.replace("DATA/", f"{DATA}/", 1)
                      if args.source.startswith("DATA/") else args.source)
    else:
        source = DATE if args.dataset == "raw" else OBJECT
    if not source.exists():
        raise SystemExit(f"accuracy.py: {source}: not found")
    variants = parse_variants(args.variant)
    if variants:
        out, cache = [], {}
        kind = {"kitti_object": "KITTI object", "kitti_raw": "KITTI raw"}.get(
            layout_of(source), f"folder {source}")
        for name in variants:
            folder, T_ref, pose = build_variant(source, name, work / "variants" / name,
                                                args.frames, cache=cache)
            moved = None if np.allclose(pose, np.eye(4)) else pose
            out.append(Dataset(f"{kind} variant {name}", "folder", folder, T_ref, name, moved,
                               all_frames=True))
        return out
    layout = layout_of(source)
    if layout == "rig":
        if args.api:
            raise SystemExit("accuracy.py: a rig folder runs through the CLI (no --api)")
        T_ref = rig_references(source)[0]
        label = f"rig {source} (--joint)"
    elif layout == "folder":
        T_ref = folder_reference(source)
        label = f"folder {source}"
    else:
        T_ref = detect_source(source).frames[0].T_ref
        label = {"kitti_raw": "raw", "kitti_object": "object"}[layout]
        if args.source is not None:
            label = f"{label} {source}"
    return [Dataset(label, layout, source, T_ref)]


def _slug(label: str) -> str:
    return "".join(c if c.isalnum() or c in "-+." else "_" for c in label).strip("_")[-80:]


def _json_doc(args, argv, sets: list[Dataset]) -> dict:
    return {"argv": argv, "rot": args.rot, "trans": args.trans, "frames": args.frames,
            "api": bool(args.api), "calibrate_options": calibrate_options(args),
            "datasets": [{"label": d.label, "layout": d.layout, "path": str(d.path),
                          "variant": d.variant, "T_ref": _rows(d.T_ref),
                          "sensor_pose": None if d.sensor_pose is None else _rows(d.sensor_pose),
                          "trials": d.rows,
                          "summary": summary_figures(d.rows) if d.rows else None}
                         for d in sets]}


def parse_args(argv: list[str]):
    passthrough: list[str] = []
    if "--" in argv:
        i = argv.index("--")
        argv, passthrough = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 epilog="Options after -- are passed to paretocal calibrate.")
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--rot", type=float, default=10.0, help="per-axis bound, deg")
    ap.add_argument("--trans", type=float, default=0.25, help="per-axis bound, m")
    ap.add_argument("--dataset", choices=("raw", "object"), default="raw",
                    help="shortcut for the sample data: the 20-frame raw drive, or the single "
                         "KITTI object frame (another scene, not used to tune anything)")
    ap.add_argument("--source", default=None,
                    help="any dataset folder paretocal reads, with a reference extrinsic "
                         "(overrides --dataset)")
    ap.add_argument("--variant", action="append", default=None,
                    help=f"rig variant(s) of the KITTI source, repeatable or a comma list: "
                         f"{', '.join(VARIANTS)} (a+b chains)")
    ap.add_argument("--frames", default=None, help="frame selection, e.g. 0:10")
    ap.add_argument("--config", default=None, help="settings file (YAML/JSON by section)")
    ap.add_argument("--init-error", default=None, metavar="DEG,M",
                    help="passed to paretocal calibrate --init-error ('box': ROT,TRANS)")
    ap.add_argument("--extra", action="append", default=None, metavar="OPTIONS",
                    help="more options for paretocal calibrate, one string (repeatable)")
    ap.add_argument("--api", action="store_true", help="call the library, not the CLI")
    ap.add_argument("--json", default=None, help="also write the trials and summaries here")
    ap.add_argument("--keep", default=None, help="keep the blind copies and runs here")
    args = ap.parse_args(argv)
    args.passthrough = passthrough
    if args.init_error and args.init_error.strip().lower() != "box":
        try:
            _deg, _m = (float(v) for v in args.init_error.split(","))
        except ValueError:
            ap.error(f"--init-error {args.init_error}: expected DEG,M (e.g. 5,0.2) or box")
    if args.api and (args.extra or passthrough):
        ap.error("--extra and -- options go to the CLI; they cannot be used with --api")
    if args.keep and Path(args.keep).exists() and any(Path(args.keep).iterdir()):
        ap.error(f"--keep {args.keep}: the folder is not empty")
    return args


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="paretocal-acc-") as tmp:
        work = Path(args.keep) if args.keep else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        sets = datasets(args, work)
        summaries = []
        for ds in sets:
            dwork = work / _slug(ds.label) if len(sets) > 1 or args.variant else work
            dwork.mkdir(parents=True, exist_ok=True)
            view = None
            if args.api and ds.layout == "folder":   # links resolved, reference kept
                view = blind_copy_folder(ds.path, ds.T_ref, dwork / "view")
            print(f"dataset: {ds.label} [{ds.layout}]", flush=True)
            for k in range(args.first_seed, args.first_seed + args.trials):
                row = run_trial(k, args, ds, dwork, view)
                ds.rows.append(row)
                if "error" in row:
                    print(f"trial {k:3d}: start {row['start_deg']:5.2f} deg "
                          f"{row['start_cm']:6.1f} cm -> failed (exit {row['exit']}): "
                          f"{row['error']}", flush=True)
                else:
                    print(f"trial {k:3d}: start {row['start_deg']:5.2f} deg "
                          f"{row['start_cm']:6.1f} cm -> {row['rot_deg']:.3f} deg "
                          f"{row['trans_cm']:.2f} cm (n = {row['n']}) {row['wall_s']:.0f} s "
                          f"{row['verdict'] or 'no verdict'}", flush=True)
                if args.json:
                    Path(args.json).write_text(json.dumps(_json_doc(args, argv, sets), indent=1))
            summaries.append(summarise(ds.rows, args, ds))
            print(summaries[-1], flush=True)
        if len(summaries) > 1:
            print("\n" + "\n".join(summaries))
    return 0


if __name__ == "__main__":
    sys.exit(main())
