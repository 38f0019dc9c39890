"""ROS bags: ROS1 ``.bag`` and ROS2 (``.db3``, ``.mcap``) read with the pure-Python ``rosbags``.

The reading half of ``paretocal extract`` (the folder it writes is made by
:mod:`paretocal.extract`): open a bag, list and check its topics, iterate a topic's messages,
and turn messages into arrays:

- ``sensor_msgs/Image`` -> :func:`image_array` (the encodings of :data:`IMAGE_ENCODINGS`),
- ``sensor_msgs/CompressedImage`` -> :func:`compressed_image` (JPEG and PNG, bytes kept),
- ``sensor_msgs/PointCloud2`` -> :func:`cloud_array` (any field layout, every field kept),
- ``sensor_msgs/CameraInfo`` -> :func:`camera_from_info` (the ``camera`` of calib.yaml),

and pair images with clouds by their header stamps (:func:`pair_by_stamp`).

``rosbags`` is an optional dependency (``pip install paretocal[bags]``); it is imported inside
the functions that read bags, so the rest of the package works without it, and without it they
raise :class:`~paretocal.errors.ParetocalError` saying how to install it. The conversions take
any object with the message's attributes (ROS1 and ROS2 spellings: ``K``/``k``, ``D``/``d``).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from ..errors import InputError, ParetocalError, SettingsError, first_line, quote
from .paths import kind_of
from .text import read_mapping
from .images import check_image_size, image_header_size

if TYPE_CHECKING:                      # an optional dependency, imported where bags are read
    from rosbags.highlevel import AnyReader

log = logging.getLogger(__name__)

#: File suffixes of bags: ROS1, ROS2 sqlite3, ROS2 MCAP (a rosbag2 folder holds metadata.yaml).
BAG_SUFFIXES = (".bag", ".db3", ".mcap")
#: What to do when rosbags is missing (the end of the error message).
INSTALL = "install paretocal[bags] (pip install 'paretocal[bags]', which adds rosbags)"

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"

#: sensor_msgs/Image encodings read (lower case): numpy type, channels, and the OpenCV colour
#: conversion to OpenCV's order (BGR, BGRA), or None when the data is already in it.
IMAGE_ENCODINGS: dict[str, tuple[str, int, int | None]] = {
    "mono8": ("u1", 1, None), "8uc1": ("u1", 1, None),
    "mono16": ("u2", 1, None), "16uc1": ("u2", 1, None),
    "bgr8": ("u1", 3, None), "8uc3": ("u1", 3, None), "rgb8": ("u1", 3, cv2.COLOR_RGB2BGR),
    "bgra8": ("u1", 4, None), "8uc4": ("u1", 4, None), "rgba8": ("u1", 4, cv2.COLOR_RGBA2BGRA),
    "bgr16": ("u2", 3, None), "16uc3": ("u2", 3, None), "rgb16": ("u2", 3, cv2.COLOR_RGB2BGR),
    "bgra16": ("u2", 4, None), "16uc4": ("u2", 4, None),
    "rgba16": ("u2", 4, cv2.COLOR_RGBA2BGRA),
    # Bayer mosaics, demosaiced as cv_bridge does (OpenCV names the pattern one pixel later).
    "bayer_rggb8": ("u1", 1, cv2.COLOR_BayerBG2BGR), "bayer_bggr8": ("u1", 1, cv2.COLOR_BayerRG2BGR),
    "bayer_gbrg8": ("u1", 1, cv2.COLOR_BayerGR2BGR), "bayer_grbg8": ("u1", 1, cv2.COLOR_BayerGB2BGR),
    "yuv422": ("u1", 2, cv2.COLOR_YUV2BGR_UYVY), "uyvy": ("u1", 2, cv2.COLOR_YUV2BGR_UYVY),
    "yuv422_yuy2": ("u1", 2, cv2.COLOR_YUV2BGR_YUY2), "yuyv": ("u1", 2, cv2.COLOR_YUV2BGR_YUY2),
}

#: sensor_msgs/PointField datatypes -> numpy types (without byte order).
POINT_FIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}

#: CameraInfo ``distortion_model`` -> calib.yaml ``camera.model``.
CAMERA_MODELS = {"plumb_bob": "pinhole", "rational_polynomial": "pinhole",
                 "equidistant": "fisheye"}

_PNG = b"\x89PNG\r\n\x1a\n"
_JPEG = b"\xff\xd8\xff"
#: Where an image's expected size comes from, in messages.
_THE_CAMERA = "the camera is"


def is_bag(path: str | Path) -> bool:
    """Whether ``path`` is a ROS bag: a ``.bag``, ``.db3`` or ``.mcap`` file, or a rosbag2 folder
    (one holding ``metadata.yaml``). Only the name and the folder are looked at."""
    p = Path(path)
    if p.is_dir():
        return (p / "metadata.yaml").is_file()
    return p.suffix.lower() in BAG_SUFFIXES


def require_rosbags() -> None:
    """Raise :class:`ParetocalError` saying how to install ``rosbags`` when it is missing."""
    try:
        import rosbags.highlevel  # noqa: F401
    except ImportError:
        raise ParetocalError(f"reading ROS bags needs the rosbags package: {INSTALL}") from None


def _bag_errors() -> tuple[type[BaseException], ...]:
    """The exceptions rosbags raises for unreadable or malformed bags."""
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error
    from rosbags.serde import SerdeError

    return AnyReaderError, Reader1Error, Reader2Error, SerdeError


@dataclass(frozen=True)
class Topic:
    """A topic of a bag: its name, message type (``pkg/msg/Name``) and message count."""

    name: str
    msgtype: str
    count: int


class Bag:
    """An open ROS bag (a context manager): its topics, and the messages of one topic.

    Parameters
    ----------
    path : path
        A ROS1 ``.bag`` file, a ROS2 ``.db3`` or ``.mcap`` file, or a rosbag2 folder.

    Raises
    ------
    ParetocalError
        When rosbags is not installed.
    InputError
        Naming the bag when it is missing, not a bag, or cannot be read.
    """

    def __init__(self, path: str | Path):
        require_rosbags()
        self.path = Path(path)
        self._reader: AnyReader | None = None
        if not self.path.exists():
            raise InputError(f"{self.path}: bag not found")
        if not (self.path.is_file() or self.path.is_dir()):    # a FIFO would block the reader
            raise InputError(f"{self.path}: a bag expected, but this is {kind_of(self.path)}")
        if not is_bag(self.path):
            raise InputError(f"{self.path}: not a ROS bag (expected a ROS1 .bag file, a ROS2 "
                             ".db3 or .mcap file, or a rosbag2 folder with metadata.yaml)")

    def __enter__(self) -> Bag:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        ros1 = self.path.suffix == ".bag" and self.path.is_file()
        # The bag's own message definitions are used; the typestore only serves bags without.
        store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        # Recent rosbags read a bare .db3 / .mcap file; should that fail for a file inside a
        # rosbag2 folder (with metadata.yaml), the folder is read instead.
        tries = [self.path]
        if not ros1 and self.path.is_file() and (self.path.parent / "metadata.yaml").is_file():
            tries.append(self.path.parent)
        unreadable: tuple[type[BaseException], ...] = (*_bag_errors(), OSError, KeyError,
                                                       ValueError)
        failures: list[BaseException] = []
        for path in tries:
            if path.is_dir():
                # rosbags reads metadata.yaml with its own YAML reader, which takes an alias
                # bomb: the bounded reader of calib.yaml sees it first (and names it).
                read_mapping(path / "metadata.yaml")
            try:
                reader = AnyReader([path], default_typestore=store)
                reader.open()
            except unreadable as exc:
                failures.append(exc)
                continue
            self._reader = reader
            return self
        raise InputError(f"{self.path}: not a readable ROS bag ({first_line(failures[0])})")

    def __exit__(self, *exc) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    def _open_reader(self) -> AnyReader:
        """The reader of the open bag; a bag is read inside its ``with`` block."""
        if self._reader is None:
            raise ParetocalError(f"{self.path}: the bag is not open (read it inside "
                                 "'with Bag(path) as bag')")
        return self._reader

    @property
    def topics(self) -> dict[str, Topic]:
        """The bag's topics by name."""
        return {name: Topic(name, info.msgtype or "(mixed types)", int(info.msgcount))
                for name, info in self._open_reader().topics.items()}

    def describe_topics(self) -> str:
        """The topics in words for an error message: ``/a (sensor_msgs/msg/Image, 3), ...``."""
        topics = self.topics
        if not topics:
            return "the bag has no topics"
        return "topics: " + ", ".join(f"{t.name} ({t.msgtype}, {t.count})"
                                      for t in topics.values())

    def require(self, topic: str, msgtypes: tuple[str, ...], option: str) -> str:
        """The message type of ``topic``, checked to be one of ``msgtypes``.

        Raises :class:`InputError` naming the bag, the option and the topic, and listing the
        topics present, when the bag has no such topic, it is of another type, or empty.
        """
        topics = self.topics
        if topic not in topics:
            raise InputError(f"{self.path}: no topic {topic!r} ({option}); "
                             f"{self.describe_topics()}")
        t = topics[topic]
        if t.msgtype not in msgtypes:
            raise InputError(f"{self.path}: topic {topic!r} ({option}) holds {t.msgtype}, not "
                             f"{' or '.join(msgtypes)}; {self.describe_topics()}")
        if t.count == 0:
            raise InputError(f"{self.path}: topic {topic!r} ({option}) has no messages")
        return t.msgtype

    def of_type(self, *msgtypes: str) -> list[str]:
        """The names of the topics holding one of ``msgtypes``."""
        return [t.name for t in self.topics.values() if t.msgtype in msgtypes]

    def messages(self, topic: str) -> Iterator[tuple[int, Any]]:
        """``(time recorded in ns, message)`` of every message on ``topic``, in bag order."""
        reader = self._open_reader()
        conns = [c for c in reader.connections if c.topic == topic]
        errors = _bag_errors()
        try:
            for conn, t, raw in reader.messages(connections=conns):
                yield int(t), reader.deserialize(raw, conn.msgtype)
        except errors as exc:
            raise InputError(f"{self.path}: cannot read topic {topic!r} "
                             f"({first_line(exc)})") from None


def extract_hint(path: str | Path) -> str:
    """The ``paretocal extract`` command for the bag at ``path``, topics filled in when the bag
    has one topic of each kind (else placeholders, and the candidates)."""
    image, cloud, note = "TOPIC", "TOPIC", ""
    try:
        with Bag(path) as bag:
            images = bag.of_type(IMAGE, COMPRESSED_IMAGE)
            clouds = bag.of_type(POINT_CLOUD2)
    except ParetocalError as exc:
        note = "; install paretocal[bags]" if INSTALL in str(exc) else ""
    else:
        image = images[0] if len(images) == 1 else image
        cloud = clouds[0] if len(clouds) == 1 else cloud
        parts = [f"{what} topics: {', '.join(names) or 'none'}"
                 for what, names in (("image", images), ("cloud", clouds)) if len(names) != 1]
        note = f"; {'; '.join(parts)}" if parts else ""
    return (f"paretocal extract {path} --out DIR --image-topic {image} --cloud-topic {cloud}"
            f"{note}")


# --- messages -> arrays ---------------------------------------------------------------------------


def stamp_ns(msg) -> int:
    """The header stamp of ``msg`` in nanoseconds (0 when the message has none)."""
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None:
        return 0
    sec = getattr(stamp, "sec", getattr(stamp, "secs", 0))
    nsec = getattr(stamp, "nanosec", getattr(stamp, "nsecs", 0))
    return int(sec) * 1_000_000_000 + int(nsec)


def _bytes(data) -> np.ndarray:
    """A message's ``data`` (bytes or a uint8 array) as a flat uint8 array (no copy)."""
    return np.frombuffer(data, np.uint8) if isinstance(data, (bytes, bytearray, memoryview)) \
        else np.asarray(data, np.uint8).reshape(-1)


def image_array(msg, where: str = "image") -> np.ndarray:
    """A ``sensor_msgs/Image`` as the array OpenCV writes.

    Parameters
    ----------
    msg : sensor_msgs/Image
        ``height``, ``width``, ``encoding`` (one of :data:`IMAGE_ENCODINGS`, any case),
        ``is_bigendian``, ``step`` (bytes per row, padding allowed) and ``data``.
    where : str
        What the image is called in error messages (the bag and topic).

    Returns
    -------
    ndarray, shape (H, W) or (H, W, 3) or (H, W, 4), uint8 or uint16
        Grey images as (H, W) (16-bit kept), colour in OpenCV's order (BGR, BGRA); Bayer and
        YUV 4:2:2 images converted to BGR. Pixel values are as stored.

    Raises
    ------
    InputError
        For an unsupported encoding (naming it), or data shorter than ``step * height`` or a
        ``step`` shorter than a row.
    """
    enc = str(msg.encoding)
    if enc.lower() not in IMAGE_ENCODINGS:
        raise InputError(f"{where}: image encoding {quote(enc)} is not supported (supported: "
                         f"{', '.join(IMAGE_ENCODINGS)}; or CompressedImage JPEG/PNG)")
    kind, ch, conversion = IMAGE_ENCODINGS[enc.lower()]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    itemsize = np.dtype(kind).itemsize
    row = w * ch * itemsize
    data = _bytes(msg.data)
    if h <= 0 or w <= 0:
        raise InputError(f"{where}: the image is empty ({w} x {h} pixels)")
    if step < row or data.size < step * h:
        raise InputError(f"{where}: image data is inconsistent: {data.size} bytes, step {step}, "
                         f"{h} rows of {w} pixels of {ch * itemsize} bytes ({enc})")
    rows = data[:step * h].reshape(h, step)[:, :row]
    order = ">" if msg.is_bigendian and itemsize > 1 else "<"
    img = np.ascontiguousarray(rows).view(np.dtype(order + kind)).reshape(h, w, ch)
    img = img.astype(np.dtype(kind).newbyteorder("="), copy=False)
    if ch == 1:
        img = img[:, :, 0]
    if conversion is not None:
        img = cv2.cvtColor(img, conversion)
    return np.ascontiguousarray(img)


def compressed_image(msg, where: str = "image", size: tuple[int, int] | None = None
                     ) -> tuple[bytes, str, np.ndarray]:
    """A ``sensor_msgs/CompressedImage``: its file bytes, their suffix and the decoded image.

    The bytes are kept as they are (written unchanged, the image decodes to the same pixels).
    ``size`` (width, height), the camera's: an image of another size is refused from its
    header, before it is decoded (``where`` names the message in errors).

    Returns
    -------
    data : bytes
        The JPEG or PNG file.
    suffix : str
        ``.jpg`` or ``.png``, from the data itself.
    image : ndarray
        The decoded image as OpenCV reads the file (any depth and channel count).

    Raises
    ------
    InputError
        For another format (``compressedDepth``, video codecs; naming the ``format`` field),
        data that does not decode, or an image of more pixels than an image may have or of
        another size than ``size``.
    """
    fmt = str(getattr(msg, "format", ""))
    data = _bytes(msg.data).tobytes()
    if "compresseddepth" in fmt.lower():
        suffix = None
    elif data.startswith(_PNG):
        suffix = ".png"
    elif data.startswith(_JPEG):
        suffix = ".jpg"
    else:
        suffix = None
    if suffix is None:
        raise InputError(f"{where}: compressed image format {quote(fmt)} is not supported (JPEG and "
                         "PNG are)")
    check_image_size(where, image_header_size(data), size, against=_THE_CAMERA)
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None or img.size == 0:
        raise InputError(f"{where}: cannot decode the compressed image ({quote(fmt)}, {len(data)} "
                         "bytes; corrupt or truncated)")
    check_image_size(where, (img.shape[1], img.shape[0]), size, against=_THE_CAMERA)
    return data, suffix, img


def cloud_array(msg, where: str = "cloud") -> np.ndarray:
    """A ``sensor_msgs/PointCloud2`` as a record array holding every field.

    Parameters
    ----------
    msg : sensor_msgs/PointCloud2
        ``height``, ``width``, ``fields`` (name, offset, datatype, count), ``is_bigendian``,
        ``point_step``, ``row_step`` and ``data``: any field order, offsets, padding between
        fields or points (``point_step``) and rows (``row_step``), either byte order.
    where : str
        What the cloud is called in error messages (the bag and topic).

    Returns
    -------
    ndarray, shape (height * width,), structured
        One record per point in storage order (an organised cloud row by row, NaN points kept),
        the fields in the message's order with their names and types (``count > 1``: a
        sub-array), in native byte order and without padding. Values are as stored: ``x, y, z``
        in the cloud's units (metres in ROS), intensity, ring and time as the driver wrote them
        (:func:`paretocal.io.clouds.read_cloud` interprets them by name).

    Raises
    ------
    InputError
        Naming the field: an unknown datatype, a field beyond ``point_step``, a repeated name;
        or data shorter than the header says.
    """
    h, w, step = int(msg.height), int(msg.width), int(msg.point_step)
    row_step = int(msg.row_step)
    order = ">" if msg.is_bigendian else "<"
    names, formats, offsets = [], [], []
    for f in msg.fields:
        name = str(f.name)
        if int(f.datatype) not in POINT_FIELD_TYPES:
            raise InputError(f"{where}: PointCloud2 field {quote(name)} has datatype {f.datatype}, "
                             "not one of 1..8 (INT8 .. FLOAT64)")
        if not name or name in names:
            raise InputError(f"{where}: PointCloud2 field name {quote(name)} is empty or repeated")
        count = max(int(f.count), 1)
        base = np.dtype(order + POINT_FIELD_TYPES[int(f.datatype)])
        # Checked before the field's type is made: a count of 10**9 must not reach numpy.
        nbytes = count * base.itemsize
        if int(f.offset) < 0 or int(f.offset) + nbytes > step:
            raise InputError(f"{where}: PointCloud2 field {quote(name)} at offset {f.offset} "
                             f"({f'{count} x {base.itemsize}' if count > 1 else nbytes} bytes) "
                             f"lies beyond point_step {step}")
        ftype = np.dtype((base, (count,))) if count > 1 else base
        names.append(name)
        formats.append(ftype)
        offsets.append(int(f.offset))
    stored = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": step})
    data = _bytes(msg.data)
    if h * w and (row_step < w * step or data.size < row_step * (h - 1) + w * step):
        raise InputError(f"{where}: PointCloud2 data is inconsistent: {data.size} bytes for "
                         f"{h} rows of {w} points, point_step {step}, row_step {row_step}")
    if h * w:
        rows = np.lib.stride_tricks.as_strided(data, (h, w * step), (row_step, 1),
                                               writeable=False)
        points = np.ascontiguousarray(rows).reshape(-1).view(stored)
    else:
        points = np.zeros(0, stored)
    packed = np.dtype([(n, f.newbyteorder("=") if not f.shape
                        else np.dtype((f.base.newbyteorder("="), f.shape)))
                       for n, f in zip(names, formats)])
    out = np.empty(len(points), packed)
    for n in names:
        out[n] = points[n]
    return out


def camera_from_info(msg, where: str = "camera_info") -> dict:
    """A ``sensor_msgs/CameraInfo`` as the ``camera`` section of calib.yaml.

    Returns
    -------
    dict
        ``model`` (``pinhole`` for ``plumb_bob`` and ``rational_polynomial``, ``fisheye`` for
        ``equidistant``), ``K`` (3 x 3 list, pixels), ``width`` and ``height`` (pixels), and
        ``D`` (OpenCV's order, as in the message) unless every coefficient is 0 (an ideal
        pinhole). ``R`` and ``P`` are not used: points are projected into the raw image through
        the lens model.

    Raises
    ------
    InputError
        For an all-zero ``K`` (an uncalibrated camera), a size of 0, or an unknown distortion
        model with nonzero coefficients.
    """
    K = np.asarray(getattr(msg, "k", None) if hasattr(msg, "k") else msg.K, np.float64)
    D = np.asarray(getattr(msg, "d", None) if hasattr(msg, "d") else msg.D, np.float64)
    D = D.reshape(-1)
    model = str(msg.distortion_model).strip()
    width, height = int(msg.width), int(msg.height)
    if K.size != 9 or not K.any():
        raise InputError(f"{where}: K is {'all zero' if K.size == 9 else f'{K.size} values'} "
                         "(an uncalibrated camera); calibrate the intrinsics first, or pass "
                         "--calib with the camera")
    if width <= 0 or height <= 0:
        raise InputError(f"{where}: the image size is {width} x {height}")
    if model.lower() in CAMERA_MODELS:
        kind = CAMERA_MODELS[model.lower()]
    elif not D.any():
        kind = "pinhole"
    else:
        raise InputError(f"{where}: distortion_model {quote(model)} is not supported (supported: "
                         f"{', '.join(CAMERA_MODELS)})")
    cam = {"model": kind, "K": K.reshape(3, 3).tolist(), "width": width, "height": height}
    if D.any():
        cam["D"] = D.tolist()
    return cam


# --- pairing -------------------------------------------------------------------------------------


@dataclass
class Pairing:
    """Images paired with clouds by header stamp (:func:`pair_by_stamp`).

    Attributes
    ----------
    pairs : list of (int, int)
        ``(image index, cloud index)`` of the pairs kept (after ``every`` and ``limit``), in
        the order of the images' stamps; indices into the stamp arrays given.
    dt : ndarray, shape (len(pairs),), float64
        Cloud stamp minus image stamp of each pair kept, seconds.
    matched : int
        Pairs within ``max_dt`` before ``every`` and ``limit``.
    images_dropped, clouds_dropped : list of int
        Indices of the images and clouds without a partner within ``max_dt``.
    max_dt : float
        The tolerance used, seconds.
    max_dt_rule : str
        Where it comes from, in words.
    nearest_dt : float
        The smallest ``|dt|`` between any image and any cloud, seconds (inf without clouds).
    """

    pairs: list[tuple[int, int]]
    dt: np.ndarray
    matched: int
    images_dropped: list[int]
    clouds_dropped: list[int]
    max_dt: float
    max_dt_rule: str
    nearest_dt: float


def default_max_dt(cloud_ns) -> float:
    """Half the median period of the cloud stamps (ns), in seconds: the largest offset at which
    the nearest cloud is still unambiguous.

    Raises :class:`SettingsError` (asking for ``--max-dt``) with fewer than two distinct stamps.
    """
    cs = np.unique(np.asarray(cloud_ns, np.int64))
    if len(cs) < 2:
        raise SettingsError(f"--max-dt: the cloud topic has {len(cs)} distinct stamp(s), too few "
                            "to estimate its period (the default tolerance is half of it); pass "
                            "--max-dt SECONDS")
    return float(np.median(np.diff(cs))) / 2e9


def pair_by_stamp(image_ns, cloud_ns, max_dt: float | None = None, every: int = 1,
                  limit: int | None = None) -> Pairing:
    """Pair each image with the nearest cloud in stamp, within a tolerance.

    Each image takes the cloud nearest in stamp; the pair is kept when ``|dt| <= max_dt``.
    A cloud is used at most once: when it is the nearest of several images, the image closest
    to it keeps it and the others are dropped. ``every`` then keeps every ``every``-th pair
    (in image stamp order, from the first) and ``limit`` at most that many.

    Parameters
    ----------
    image_ns, cloud_ns : array_like of int
        Header stamps in nanoseconds (any order).
    max_dt : float, optional
        Tolerance in seconds; default :func:`default_max_dt` (half the cloud period).
    every : int
    limit : int, optional

    Returns
    -------
    Pairing
    """
    img = np.asarray(image_ns, np.int64).reshape(-1)
    cld = np.asarray(cloud_ns, np.int64).reshape(-1)
    if max_dt is None:
        max_dt, rule = default_max_dt(cld), "half the median cloud period"
    else:
        rule = "--max-dt"
    if len(img) == 0 or len(cld) == 0:
        return Pairing([], np.zeros(0), 0, list(range(len(img))), list(range(len(cld))),
                       max_dt, rule, float("inf"))
    order = np.argsort(cld, kind="stable")
    cs = cld[order]
    # The nearest cloud of each image: the one just after it or just before (ties: before).
    after = np.minimum(np.searchsorted(cs, img), len(cs) - 1)
    before = np.maximum(after - 1, 0)
    earlier = np.abs(img - cs[before]) <= np.abs(cs[after] - img)
    nearest = order[np.where(earlier, before, after)]
    dt_ns = cld[nearest] - img
    tol = round(max_dt * 1e9)
    taken: dict[int, int] = {}
    for i in np.lexsort((np.arange(len(img)), np.abs(dt_ns))):
        if abs(int(dt_ns[i])) > tol:
            break
        taken.setdefault(int(nearest[i]), int(i))
    matched = sorted(((i, c) for c, i in taken.items()), key=lambda p: (int(img[p[0]]), p[0]))
    kept = matched[::max(int(every), 1)][:limit]
    return Pairing(
        pairs=kept, dt=np.array([(cld[c] - img[i]) / 1e9 for i, c in kept], np.float64),
        matched=len(matched),
        images_dropped=sorted(set(range(len(img))) - {i for i, _ in matched}),
        clouds_dropped=sorted(set(range(len(cld))) - {c for _, c in matched}),
        max_dt=float(max_dt), max_dt_rule=rule, nearest_dt=float(np.abs(dt_ns).min()) / 1e9)
