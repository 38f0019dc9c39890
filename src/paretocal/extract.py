"""Frames from a ROS bag, written as a generic folder (``paretocal extract``).

:func:`extract_bag` reads an image topic, a point-cloud topic and the camera's CameraInfo from
a ROS1 or ROS2 bag (:mod:`paretocal.io.bags`), pairs images with clouds by header stamp, and
writes the generic layout every command reads::

    OUT/calib.yaml          camera (from CameraInfo, or --calib), T_cam_lidar when given
    OUT/images/<stem>.png   sensor_msgs/Image as stored (16-bit kept); CompressedImage as its
                            own .jpg / .png bytes
    OUT/points/<stem>.npy   a record array with every PointCloud2 field, native byte order
    OUT/extract.json        the bag, topics, tolerance, pairs, dropped messages, dt statistics

``<stem>`` is the pair's index and the image's stamp in nanoseconds, ``000000_1317046776123456789``,
so stems sort in time. The folder is written to a hidden staging folder beside OUT and renamed
to OUT at the end: an interrupted extraction never leaves a folder that looks complete.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml

from .errors import InputError, SettingsError, key_list
from .io.atomic import check_output_dir
from .io.images import check_image_size
from .io.bags import (CAMERA_INFO, COMPRESSED_IMAGE, IMAGE, IMAGE_ENCODINGS, POINT_CLOUD2, Bag,
                      camera_from_info, cloud_array, compressed_image, image_array,
                      pair_by_stamp, stamp_ns)
from .io.layouts import calib_camera, detect_source

log = logging.getLogger(__name__)

#: The report written beside the frames.
REPORT = "extract.json"


def extract_bag(bag: str | Path, out: str | Path, image_topic: str, cloud_topic: str,
                camera_info_topic: str | None = None, *, max_dt: float | None = None,
                every: int = 1, limit: int | None = None, calib: dict | None = None,
                progress=None) -> dict:
    """Extract paired frames from a ROS bag into the generic folder ``out``.

    Parameters
    ----------
    bag : path
        A ROS1 ``.bag``, a ROS2 ``.db3`` or ``.mcap`` file, or a rosbag2 folder.
    out : path
        The folder to create; it must not exist or be empty.
    image_topic : str
        ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage`` (JPEG, PNG).
    cloud_topic : str
        ``sensor_msgs/PointCloud2``.
    camera_info_topic : str, optional
        ``sensor_msgs/CameraInfo`` giving the camera (its first message). Default: the bag's
        CameraInfo topic beside the image topic (same namespace), or its only one.
    max_dt : float, optional
        Pairing tolerance in seconds; default half the median period of the cloud stamps.
    every : int
        Keep every ``every``-th pair.
    limit : int, optional
        Keep at most this many pairs.
    calib : dict, optional
        calib.yaml entries to write: ``camera`` (used instead of a CameraInfo) and
        ``T_cam_lidar`` (4 x 4, the initial extrinsic).
    progress : callable, optional
        ``progress(stage, done, total)`` as frames are written.

    Returns
    -------
    dict
        The report also written to ``out/extract.json``: ``bag``, ``topics``, ``camera_from``,
        ``max_dt_s`` and ``max_dt_rule``, ``counts`` (messages, pairs matched and kept,
        images and clouds dropped, pairs skipped by every/limit), ``dt_ms`` (min, median, max
        and mean absolute of the pairs kept), ``frames`` (stem, stamps, dt) and ``dropped``
        (stamps of the images and clouds without a partner), ``has_extrinsic``.

    Raises
    ------
    InputError
        Naming the bag and topic: a missing topic (listing those present), a topic of the wrong
        type, no pair within the tolerance (giving the nearest dt), an unsupported image
        encoding or compressed format, a malformed message, no camera.
    SettingsError
        For bad ``every``, ``limit``, ``max_dt`` or ``out``.
    """
    bag, out = Path(bag), Path(out)
    calib = dict(calib or {})
    _check_options(out, max_dt, every, limit)
    with Bag(bag) as b:
        image_type = b.require(image_topic, (IMAGE, COMPRESSED_IMAGE), "--image-topic")
        b.require(cloud_topic, (POINT_CLOUD2,), "--cloud-topic")
        camera, size, camera_from = _camera(b, image_topic, camera_info_topic, calib)
        image_ns, _ = _scan(b, image_topic, check_encoding=image_type == IMAGE)
        cloud_ns, sizes = _scan(b, cloud_topic)
        usable = [k for k, n in enumerate(sizes) if n > 0]
        if not usable:
            raise InputError(f"{bag}: every cloud on {cloud_topic!r} is empty")
        pairing = pair_by_stamp(image_ns, [cloud_ns[k] for k in usable], max_dt, every, limit)
        pairing.pairs = [(i, usable[c]) for i, c in pairing.pairs]
        pairing.clouds_dropped = sorted({usable[c] for c in pairing.clouds_dropped}
                                        | (set(range(len(sizes))) - set(usable)))
        if not pairing.pairs:
            raise InputError(_no_pairs(bag, image_topic, cloud_topic, pairing, len(usable)))
        stems = [f"{k:06d}_{image_ns[i]}" for k, (i, _) in enumerate(pairing.pairs)]
        report = _report(bag, (image_topic, image_type, cloud_topic), camera_from, pairing,
                         (image_ns, cloud_ns), stems)
        report["has_extrinsic"] = calib.get("T_cam_lidar") is not None
        calib_doc = {"camera": camera}
        if calib.get("T_cam_lidar") is not None:
            calib_doc["T_cam_lidar"] = np.asarray(calib["T_cam_lidar"], float).tolist()
        target = out.resolve()
        staging = target.parent / f".{target.name}.extracting-{os.getpid()}"
        shutil.rmtree(staging, ignore_errors=True)
        try:
            _write(b, staging, (image_topic, image_type, cloud_topic), pairing, stems, size,
                   progress)
            _write_text(staging / "calib.yaml", _calib_text(bag, report, calib_doc))
            _write_text(staging / REPORT, json.dumps(report, indent=2) + "\n")
            detect_source(staging)       # the folder loads as the generic layout
            _publish(staging, target)
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
    return report


#: The kinds of topic extract can use, in the order listed, by message type.
TOPIC_KINDS = {IMAGE: "image", COMPRESSED_IMAGE: "compressed image",
               POINT_CLOUD2: "point cloud", CAMERA_INFO: "camera info"}


@dataclass
class TopicChoice:
    """The topics to extract when the command line leaves some out (:func:`choose_topics`)."""

    image_topic: str | None          #: as given, the bag's only candidate, or None
    cloud_topic: str | None
    chosen: list[str]                #: the options filled in, ``"--cloud-topic /points"``
    candidates: dict[str, list[str]]  #: topic names by kind (:data:`TOPIC_KINDS` and "other")
    listing: str                     #: every topic, one line each: kind, name, type, count

    def missing(self, bag: str | Path) -> str:
        """The one-line error when a topic could not be chosen: the options to pass and the
        candidates for each."""
        c = self.candidates

        def names(*kinds):
            return ", ".join(n for k in kinds for n in c[k]) or "none"
        need = []
        if self.image_topic is None:
            need.append(f"--image-topic TOPIC (image topics: "
                        f"{names('image', 'compressed image')})")
        if self.cloud_topic is None:
            need.append(f"--cloud-topic TOPIC (point cloud topics: {names('point cloud')})")
        return (f"{bag}: which topics to extract? pass {' and '.join(need)}; camera info "
                f"topics: {names('camera info')}; the bag's topics are listed on stdout")


def choose_topics(bag: str | Path, image_topic: str | None = None,
                  cloud_topic: str | None = None) -> TopicChoice:
    """List the topics of ``bag`` and fill in the image and cloud topics not given: the bag's
    only image topic (Image or CompressedImage), its only PointCloud2 topic."""
    with Bag(bag) as b:
        topics = b.topics
    kinds = list(TOPIC_KINDS.values()) + ["other"]
    kind = {t.name: TOPIC_KINDS.get(t.msgtype, "other") for t in topics.values()}
    rows = sorted(topics.values(), key=lambda t: (kinds.index(kind[t.name]), t.name))
    width = max([len(t.name) for t in rows], default=0)
    listing = "\n".join(f"  {kind[t.name]:<16} {t.name:<{width}}  {t.msgtype}  {t.count} "
                         f"message{'' if t.count == 1 else 's'}" for t in rows)
    candidates = {k: [t.name for t in rows if kind[t.name] == k] for k in kinds}
    images = candidates["image"] + candidates["compressed image"]
    clouds = candidates["point cloud"]
    chosen = []
    if image_topic is None and len(images) == 1:
        image_topic = images[0]
        chosen.append(f"--image-topic {image_topic}")
    if cloud_topic is None and len(clouds) == 1:
        cloud_topic = clouds[0]
        chosen.append(f"--cloud-topic {cloud_topic}")
    return TopicChoice(image_topic, cloud_topic, chosen, candidates,
                       listing or "  (the bag has no topics)")


def _check_options(out: Path, max_dt, every: int, limit) -> None:
    if max_dt is not None and not (np.isfinite(max_dt) and max_dt > 0):
        raise SettingsError(f"--max-dt {max_dt}: must be a positive number of seconds")
    if every < 1:
        raise SettingsError(f"--every {every}: must be at least 1")
    if limit is not None and limit < 1:
        raise SettingsError(f"--limit {limit}: must be at least 1")
    check_output_dir(out)
    if out.is_dir() and any(out.iterdir()):
        raise SettingsError(f"--out {out}: the folder is not empty; extract writes a new "
                            "folder (choose another --out or remove this one)")


def _camera(bag: Bag, image_topic: str, info_topic: str | None,
            calib: dict) -> tuple[dict, tuple[int, int], str]:
    """The calib.yaml camera, its image size (width, height) and where it came from: --calib,
    or the first CameraInfo message."""
    if calib.get("camera") is not None:
        if info_topic is not None:
            raise SettingsError("give either --camera-info-topic or --calib (with its camera), "
                                "not both")
        cam = calib_camera({"camera": calib["camera"]}, "--calib")
        return calib["camera"], (cam.width, cam.height), "--calib"
    if info_topic is None:
        found = bag.of_type(CAMERA_INFO)
        near = [t for t in found if t.rsplit("/", 1)[0] == image_topic.rsplit("/", 1)[0]]
        pick = near if len(near) == 1 else found
        if len(pick) != 1:
            which = f"several ({', '.join(found)})" if found else "none"
            raise InputError(f"{bag.path}: cannot tell which CameraInfo topic gives the camera "
                             f"of {image_topic!r} (CameraInfo topics: {which}); pass "
                             "--camera-info-topic TOPIC, or --calib FILE with a calib.yaml "
                             "camera section")
        info_topic = pick[0]
    else:
        bag.require(info_topic, (CAMERA_INFO,), "--camera-info-topic")
    where = f"{bag.path}: topic {info_topic!r}"
    first = None
    for _, msg in bag.messages(info_topic):
        first = msg
        break
    if first is None:
        raise InputError(f"{where}: the CameraInfo topic holds no message; pass "
                         "--camera-info-topic TOPIC with messages, or --calib FILE with a "
                         "calib.yaml camera section")
    camera = camera_from_info(first, where)
    cam = calib_camera({"camera": camera}, where)
    return camera, (cam.width, cam.height), info_topic


def _scan(bag: Bag, topic: str, check_encoding: bool = False) -> tuple[list[int], list[int]]:
    """Header stamps (ns) and sizes (pixels or points) of a topic's messages.

    A message without a header stamp (0) gets its recording time, with a warning.
    ``check_encoding``: refuse an unsupported sensor_msgs/Image encoding now, before writing.
    """
    stamps, sizes, zero = [], [], 0
    for k, (t, msg) in enumerate(bag.messages(topic)):
        s = stamp_ns(msg)
        if check_encoding and str(msg.encoding).lower() not in IMAGE_ENCODINGS:
            image_array(msg, f"{bag.path}: topic {topic!r}, image {k} (stamp {s})")   # raises
        zero += s == 0
        stamps.append(s or t)
        sizes.append(int(getattr(msg, "width", 1)) * int(getattr(msg, "height", 1)))
    if zero:
        log.warning("%s: %d message(s) on %s have no header stamp; their recording time is used",
                    bag.path, zero, topic)
    return stamps, sizes


def _no_pairs(bag: Path, image_topic: str, cloud_topic: str, pairing, clouds: int) -> str:
    return (f"{bag}: no image on {image_topic!r} has a cloud on {cloud_topic!r} within "
            f"{_ms(pairing.max_dt)} ({pairing.max_dt_rule}); the nearest are "
            f"{_ms(pairing.nearest_dt)} apart ({clouds} non-empty clouds); pass a larger "
            "--max-dt if the clocks are offset")


def _ms(seconds: float) -> str:
    return "inf" if not np.isfinite(seconds) else f"{seconds * 1e3:.4g} ms"


def _report(bag: Path, topics: tuple[str, str, str], camera_from: str, pairing,
            stamps: tuple[list[int], list[int]], stems: list[str]) -> dict:
    image_topic, image_type, cloud_topic = topics
    image_ns, cloud_ns = stamps
    dt = pairing.dt * 1e3
    return {
        "bag": str(bag.resolve()),
        "topics": {"image": image_topic, "image_type": image_type, "cloud": cloud_topic},
        "camera_from": camera_from,
        "max_dt_s": pairing.max_dt, "max_dt_rule": pairing.max_dt_rule,
        "counts": {"images": len(image_ns), "clouds": len(cloud_ns),
                   "pairs_matched": pairing.matched, "pairs_kept": len(pairing.pairs),
                   "pairs_skipped": pairing.matched - len(pairing.pairs),
                   "images_dropped": len(pairing.images_dropped),
                   "clouds_dropped": len(pairing.clouds_dropped)},
        "dt_ms": {"min": float(dt.min()), "median": float(np.median(dt)),
                  "max": float(dt.max()), "mean_abs": float(np.abs(dt).mean())},
        "frames": [{"stem": s, "image_stamp_ns": image_ns[i], "cloud_stamp_ns": cloud_ns[c],
                    "dt_ms": float(d)} for s, (i, c), d in zip(stems, pairing.pairs, dt)],
        "dropped": {"image_stamps_ns": [image_ns[i] for i in pairing.images_dropped],
                    "cloud_stamps_ns": [cloud_ns[c] for c in pairing.clouds_dropped]},
    }


def _write(bag: Bag, staging: Path, topics: tuple[str, str, str], pairing, stems: list[str],
           size: tuple[int, int], progress) -> None:
    """Write the images and clouds of the pairs kept (one message in memory at a time)."""
    image_topic, image_type, cloud_topic = topics
    (staging / "images").mkdir(parents=True)
    (staging / "points").mkdir()
    by_image = {i: s for (i, _), s in zip(pairing.pairs, stems)}
    by_cloud = {c: s for (_, c), s in zip(pairing.pairs, stems)}
    total, done = 2 * len(stems), 0
    for k, (_, msg) in enumerate(bag.messages(image_topic)):
        if k > max(by_image):
            break
        if k not in by_image:
            continue
        stem = by_image[k]
        where = f"{bag.path}: topic {image_topic!r}, image {k} (stamp {stamp_ns(msg)})"
        if image_type == IMAGE:
            img = image_array(msg, where)
            ok, buf = cv2.imencode(".png", img)
            if not ok:
                raise InputError(f"{where}: cannot encode the image as PNG ({img.dtype}, "
                                 f"shape {img.shape})")
            data, suffix = buf.tobytes(), ".png"
        else:
            data, suffix, img = compressed_image(msg, where, size)
        check_image_size(where, (img.shape[1], img.shape[0]), size, against="the camera is")
        _write_bytes(staging / "images" / f"{stem}{suffix}", data)
        done += 1
        if progress:
            progress("frames", done, total)
    for k, (_, msg) in enumerate(bag.messages(cloud_topic)):
        if k > max(by_cloud):
            break
        if k not in by_cloud:
            continue
        where = f"{bag.path}: topic {cloud_topic!r}, cloud {k} (stamp {stamp_ns(msg)})"
        points = cloud_array(msg, where)
        fields = points.dtype.names or ()            # a structured array: () when no field
        missing = [c for c in "xyz" if c not in {n.lower() for n in fields}]
        if missing:
            raise InputError(f"{where}: no {', '.join(missing)} field (fields: "
                             f"{key_list(fields)})")
        path = staging / "points" / f"{by_cloud[k]}.npy"
        with open(path, "wb") as fh:
            np.save(fh, points, allow_pickle=False)
            fh.flush()
            os.fsync(fh.fileno())
        done += 1
        if progress:
            progress("frames", done, total)


def _write_bytes(path: Path, data: bytes) -> None:
    with open(path, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def _write_text(path: Path, text: str) -> None:
    _write_bytes(path, text.encode("utf-8"))


def _calib_text(bag: Path, report: dict, doc: dict) -> str:
    t = report["topics"]
    head = (f"# Extracted by paretocal extract from {bag}\n"
            f"# images {t['image']}, clouds {t['cloud']}, camera from {report['camera_from']}\n")
    if "T_cam_lidar" not in doc:
        head += "# No T_cam_lidar: pass --init to calibrate (or add T_cam_lidar here).\n"
    return head + yaml.safe_dump(doc, sort_keys=False)


def _publish(staging: Path, out: Path) -> None:
    """Make ``staging`` the folder ``out`` in one rename (``out`` absent or empty)."""
    for sub in ("images", "points"):
        fd = os.open(staging / sub, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    if out.is_dir():
        out.rmdir()                     # empty (checked before); refuses anything else
    os.rename(staging, out)
