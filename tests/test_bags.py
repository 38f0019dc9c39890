"""ROS bags (``paretocal extract``): bags of all three kinds (ROS1 .bag, ROS2 sqlite3 .db3 and
.mcap) written here with rosbags' own writers from the sample KITTI frames, extracted, and
compared with the frames they were made from and with a generic folder written directly."""

from __future__ import annotations

import importlib.util
import inspect
import json
import os
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from paretocal.io import load_frames, read_extrinsic, write_extrinsic
from paretocal.io.bags import (camera_from_info, cloud_array, compressed_image, image_array,
                               pair_by_stamp)

from .helpers import bad_cli as bad, run_cli as run, run_with_stdout_closed, without_progress

if (os.environ.get("PARETOCAL_REQUIRE_OPTIONAL") == "1"
        and importlib.util.find_spec("rosbags") is None):
    # CI installs every extra: a missing rosbags there is a failure, not a skip.
    pytest.fail("rosbags is not installed and PARETOCAL_REQUIRE_OPTIONAL=1", pytrace=False)

needs_rosbags = pytest.mark.skipif(importlib.util.find_spec("rosbags") is None,
                                   reason="rosbags is not installed: install paretocal[bags] "
                                          "(pip install -e .[bags])")

FAST = ["--pop", "16", "--gens", "3", "--no-polish", "--no-figures", "--checkpoint-every", "0",
        "--quiet"]
T0 = 1_317_046_776_000_000_000          # the first stamp, ns
PERIOD = 100_000_000                     # 10 Hz, ns
KINDS = ("ros1", "sqlite3", "mcap")


# --- building messages and bags ------------------------------------------------------------------


def cloud_bytes(rec: np.ndarray, offsets: dict, step: int, bigendian: bool = False,
                height: int = 1, row_pad: int = 0):
    """A PointCloud2's payload for the record array ``rec``: each field at ``offsets[name]``
    in ``step``-byte points of either byte order, ``height`` rows each followed by ``row_pad``
    filler bytes. Returns ``(rows (height, width * step + row_pad) uint8, width, [(name,
    offset, datatype code)])``."""
    codes = {"i1": 1, "u1": 2, "i2": 3, "u2": 4, "i4": 5, "u4": 6, "f4": 7, "f8": 8}
    names = list(rec.dtype.names)
    order = ">" if bigendian else "<"
    stored = np.dtype({"names": names, "offsets": [offsets[n] for n in names],
                       "formats": [rec.dtype[n].newbyteorder(order) for n in names],
                       "itemsize": step})
    arr = np.zeros(len(rec), stored)
    for n in names:
        arr[n] = rec[n]
    width = len(rec) // height
    rows = np.hstack([arr.view(np.uint8).reshape(height, width * step),
                      np.full((height, row_pad), 0xAB, np.uint8)])
    return rows, width, [(n, offsets[n], codes[rec.dtype[n].str[1:]]) for n in names]


@pytest.fixture(scope="module")
def frames(data):
    return load_frames(data / "kitti_raw" / "2011_09_26", frames="0:3")


def records(frame) -> np.ndarray:
    """The frame's sweep as PointXYZIRT-like records: x, y, z, intensity float32, ring uint16
    (a new ring where the azimuth wraps, as KITTI stores its scan) and time float32 seconds."""
    p = frame.points
    az = np.arctan2(p[:, 1], p[:, 0])
    ring = np.minimum(np.cumsum(np.diff(az, prepend=az[0]) > np.pi), 255)
    out = np.empty(len(p), [("x", "f4"), ("y", "f4"), ("z", "f4"), ("intensity", "f4"),
                            ("ring", "u2"), ("time", "f4")])
    for j, c in enumerate(("x", "y", "z", "intensity")):
        out[c] = p[:, j]
    out["ring"] = ring
    out["time"] = ((np.pi - az) / (2 * np.pi) * 0.1).astype(np.float32)
    return out


class Msgs:
    """Message constructors of one ROS generation (rosbags' typestore types)."""

    def __init__(self, ros1: bool):
        from rosbags.typesys import Stores, get_typestore

        self.ros1 = ros1
        self.store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        self.t = self.store.types

    def header(self, ns: int, frame_id: str = "sensor"):
        extra = {"seq": 0} if self.ros1 else {}
        stamp = self.t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        return self.t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id, **extra)

    def image(self, ns, pixels: np.ndarray, encoding: str, bigendian=False, pad=0):
        h, w = pixels.shape[:2]
        row = pixels.reshape(h, -1)
        if pixels.dtype.itemsize > 1:
            row = row.astype(pixels.dtype.newbyteorder(">" if bigendian else "<"))
        raw = row.view(np.uint8).reshape(h, -1)
        raw = np.hstack([raw, np.full((h, pad), 7, np.uint8)])
        return self.t["sensor_msgs/msg/Image"](
            header=self.header(ns, "camera"), height=h, width=w, encoding=encoding,
            is_bigendian=int(bigendian), step=raw.shape[1], data=raw.reshape(-1).copy())

    def compressed(self, ns, data: bytes, fmt: str):
        return self.t["sensor_msgs/msg/CompressedImage"](
            header=self.header(ns, "camera"), format=fmt, data=np.frombuffer(data, np.uint8).copy())

    def cloud(self, ns, rec: np.ndarray, layout: dict | None = None, bigendian=False,
              point_step=None, height=1, row_pad=0):
        """``rec`` as a PointCloud2; ``layout`` maps a field name to its offset (default packed
        in ``rec``'s order), ``point_step`` adds padding after each point, ``row_pad`` after
        each row of an organised cloud (``height`` rows)."""
        PF = self.t["sensor_msgs/msg/PointField"]
        offsets = layout or {n: rec.dtype.fields[n][1] for n in rec.dtype.names}
        step = point_step or rec.dtype.itemsize
        rows, width, specs = cloud_bytes(rec, offsets, step, bigendian, height, row_pad)
        fields = [PF(name=n, offset=o, datatype=d, count=1) for n, o, d in specs]
        return self.t["sensor_msgs/msg/PointCloud2"](
            header=self.header(ns, "lidar"), height=height, width=width, fields=fields,
            is_bigendian=bigendian, point_step=step, row_step=width * step + row_pad,
            data=rows.reshape(-1).copy(), is_dense=True)

    def info(self, ns, camera, model="plumb_bob", D=None):
        D = np.zeros(5) if D is None else np.asarray(D, float)
        R, P = np.eye(3).reshape(-1), np.hstack([camera.K, np.zeros((3, 1))]).reshape(-1)
        mats = ({"D": D, "K": camera.K.reshape(-1), "R": R, "P": P} if self.ros1 else
                {"d": D, "k": camera.K.reshape(-1), "r": R, "p": P})
        roi = self.t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0,
                                                          width=0, do_rectify=False)
        return self.t["sensor_msgs/msg/CameraInfo"](
            header=self.header(ns, "camera"), height=camera.height, width=camera.width,
            distortion_model=model, binning_x=0, binning_y=0, roi=roi, **mats)


def write_bag(path: Path, kind: str, topics: dict[str, list],
              empty: dict[str, str] | None = None) -> Path:
    """A bag of ``kind`` (ros1, sqlite3, mcap) at ``path`` holding ``topics``: name -> list of
    messages (recorded at their header stamps), and ``empty``: name -> message type of
    connections without messages. Returns the path to pass to extract."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2

    msgs = Msgs(kind == "ros1")
    stamped = sorted(((_stamp(m), name, m) for name, ms in topics.items() for m in ms),
                     key=lambda x: x[0])
    if kind == "ros1":
        writer = Writer1(path)
    else:
        from rosbags.rosbag2 import StoragePlugin

        kw = {"storage_plugin": StoragePlugin.SQLITE3 if kind == "sqlite3" else StoragePlugin.MCAP}
        if "version" in inspect.signature(Writer2.__init__).parameters:
            kw["version"] = 9
        writer = Writer2(path, **kw)
    with writer:
        conns = {name: writer.add_connection(name, ms[0].__msgtype__, typestore=msgs.store)
                 for name, ms in topics.items()}
        for name, msgtype in (empty or {}).items():
            writer.add_connection(name, msgtype, typestore=msgs.store)
        for ns, name, m in stamped:
            raw = (msgs.store.serialize_ros1(m, m.__msgtype__) if kind == "ros1"
                   else msgs.store.serialize_cdr(m, m.__msgtype__))
            writer.write(conns[name], ns, raw)
    if kind == "ros1":
        return path
    return path / f"{path.name}.{'db3' if kind == 'sqlite3' else 'mcap'}"   # the file itself


def _stamp(m) -> int:
    return m.header.stamp.sec * 10**9 + m.header.stamp.nanosec


def rig_bag(tmp_path: Path, kind: str, frames, image="bgr8", layout=None, **cloud_kw) -> Path:
    """A bag of the frames: images at 10 Hz, each cloud 3 ms after its image, CameraInfo."""
    msgs = Msgs(kind == "ros1")
    images, clouds = [], []
    for k, f in enumerate(frames):
        ns = T0 + k * PERIOD
        if image == "bgr8":
            images.append(msgs.image(ns, f.image, "bgr8"))
        elif image == "rgb8":
            images.append(msgs.image(ns, f.image[:, :, ::-1], "rgb8", pad=5))
        elif image == "png":
            images.append(msgs.compressed(ns, cv2.imencode(".png", f.image)[1].tobytes(),
                                          "bgr8; png compressed bgr8"))
        clouds.append(msgs.cloud(ns + 3_000_000, records(f), layout, **cloud_kw))
    info = [msgs.info(T0, frames[0].camera)]
    ext = ".bag" if kind == "ros1" else ""
    return write_bag(tmp_path / f"rig_{kind}{ext}", kind, {
        "/camera/image": images, "/lidar/points": clouds, "/camera/camera_info": info})


def direct_folder(root: Path, frames) -> Path:
    """The generic folder of the same frames, written without a bag."""
    (root / "images").mkdir(parents=True)
    (root / "points").mkdir()
    cam = frames[0].camera
    (root / "calib.yaml").write_text(yaml.safe_dump({"camera": {
        "K": cam.K.tolist(), "width": cam.width, "height": cam.height}}))
    for f in frames:
        cv2.imwrite(str(root / "images" / f"{f.name}.png"), f.image)
        np.save(root / "points" / f"{f.name}.npy", records(f))
    return root


# --- conversions ---------------------------------------------------------------------------------


class Ns:
    """A stand-in message: any attributes."""

    def __init__(self, **kw):
        self.__dict__.update(kw)


def _image_msg(pixels, encoding, bigendian=False, pad=0):
    h, w = pixels.shape[:2]
    row = pixels.reshape(h, -1)
    if pixels.dtype.itemsize > 1:
        row = row.astype(pixels.dtype.newbyteorder(">" if bigendian else "<"))
    raw = np.hstack([row.view(np.uint8).reshape(h, -1), np.zeros((h, pad), np.uint8)])
    return Ns(height=h, width=w, encoding=encoding, is_bigendian=int(bigendian),
              step=raw.shape[1], data=raw.tobytes())


class TestImages:
    rng = np.random.default_rng(3)
    bgr = rng.integers(0, 256, (6, 5, 3), dtype=np.uint8)
    grey16 = rng.integers(0, 65536, (6, 5), dtype=np.uint16)

    @pytest.mark.parametrize("encoding, pixels, expect", [
        ("bgr8", bgr, bgr), ("rgb8", bgr[:, :, ::-1], bgr), ("8UC3", bgr, bgr),
        ("mono8", bgr[:, :, 0], bgr[:, :, 0]), ("8UC1", bgr[:, :, 1], bgr[:, :, 1]),
        ("mono16", grey16, grey16), ("16UC1", grey16, grey16),
        ("rgba8", np.dstack([bgr[:, :, ::-1], bgr[:, :, :1]]), np.dstack([bgr, bgr[:, :, :1]])),
        ("bgra8", np.dstack([bgr, bgr[:, :, :1]]), np.dstack([bgr, bgr[:, :, :1]])),
        ("rgb16", np.dstack([grey16] * 3)[:, :, ::-1], np.dstack([grey16] * 3)),
    ])
    @pytest.mark.parametrize("bigendian, pad", [(False, 0), (True, 3)])
    def test_encodings_give_the_stored_pixels(self, encoding, pixels, expect, bigendian, pad):
        img = image_array(_image_msg(np.ascontiguousarray(pixels), encoding, bigendian, pad))
        assert img.dtype == expect.dtype
        np.testing.assert_array_equal(img, expect)

    def test_bayer_and_yuv_are_converted_to_bgr(self):
        mosaic = self.bgr[:, :4, 0].copy()
        img = image_array(_image_msg(mosaic, "bayer_rggb8"))
        np.testing.assert_array_equal(img, cv2.cvtColor(mosaic, cv2.COLOR_BayerBG2BGR))
        yuv = self.bgr[:, :4, :2].copy()
        assert image_array(_image_msg(yuv, "yuv422")).shape == (6, 4, 3)

    def test_unsupported_encoding_and_short_data_are_named(self):
        from paretocal.errors import InputError

        msg = _image_msg(np.zeros((2, 2), np.float32).view(np.uint8), "32FC1")
        with pytest.raises(InputError, match="image encoding '32FC1' is not supported"):
            image_array(msg, "bag: topic '/depth'")
        short = _image_msg(self.bgr, "bgr8")
        short.data = short.data[:-1]
        with pytest.raises(InputError, match="image data is inconsistent"):
            image_array(short)

    def test_compressed_bytes_are_kept(self):
        from paretocal.errors import InputError

        for ext, suffix in ((".png", ".png"), (".jpg", ".jpg")):
            data = cv2.imencode(ext, self.bgr)[1].tobytes()
            got, sfx, img = compressed_image(Ns(format="jpeg" if ext == ".jpg" else "png",
                                                data=np.frombuffer(data, np.uint8)))
            assert got == data and sfx == suffix
            np.testing.assert_array_equal(img, cv2.imdecode(np.frombuffer(data, np.uint8), -1))
        with pytest.raises(InputError, match="compressed image format 'h264' is not supported"):
            compressed_image(Ns(format="h264", data=b"\x00\x00\x01"))
        depth = b"\x00" * 12 + cv2.imencode(".png", self.grey16)[1].tobytes()
        with pytest.raises(InputError, match="'16UC1; compressedDepth png' is not supported"):
            compressed_image(Ns(format="16UC1; compressedDepth png", data=depth))


class TestClouds:
    rec = np.zeros(7, [("x", "f4"), ("y", "f4"), ("z", "f4"), ("intensity", "f4"),
                       ("ring", "u2"), ("time", "f8")])
    rng = np.random.default_rng(5)
    for _c in ("x", "y", "z", "intensity", "time"):
        rec[_c] = rng.normal(size=7)
    rec["ring"] = rng.integers(0, 64, 7)

    def _msg(self, rec, offsets, step, bigendian=False, height=1, row_pad=0):
        rows, w, specs = cloud_bytes(rec, offsets, step, bigendian, height, row_pad)
        fields = [Ns(name=n, offset=o, datatype=d, count=1) for n, o, d in specs]
        return Ns(height=height, width=w, fields=fields, is_bigendian=bigendian, point_step=step,
                  row_step=w * step + row_pad, data=rows.tobytes())

    def test_packed_layout(self):
        offs = {n: self.rec.dtype.fields[n][1] for n in self.rec.dtype.names}
        got = cloud_array(self._msg(self.rec, offs, self.rec.dtype.itemsize))
        assert got.dtype == self.rec.dtype
        np.testing.assert_array_equal(got, self.rec)

    @pytest.mark.parametrize("bigendian", [False, True])
    def test_any_order_offsets_padding_and_rows(self, bigendian):
        # Time first, the ring in the middle, x y z last; gaps between fields, 48-byte points,
        # an organised cloud of 1 row x 7 (and 7 rows x 1 with padding after each row).
        offs = {"time": 0, "ring": 10, "intensity": 16, "x": 24, "y": 28, "z": 32}
        for height, pad in ((1, 0), (7, 5)):
            got = cloud_array(self._msg(self.rec, offs, 48, bigendian, height, pad))
            assert got.dtype.names == self.rec.dtype.names
            for n in self.rec.dtype.names:
                assert got.dtype[n] == self.rec.dtype[n]
                np.testing.assert_array_equal(got[n], self.rec[n])

    def test_bad_fields_are_named(self):
        from paretocal.errors import InputError

        offs = {n: self.rec.dtype.fields[n][1] for n in self.rec.dtype.names}
        msg = self._msg(self.rec, offs, self.rec.dtype.itemsize)
        msg.fields[4].datatype = 9
        with pytest.raises(InputError, match="field 'ring' has datatype 9"):
            cloud_array(msg)
        msg = self._msg(self.rec, offs, self.rec.dtype.itemsize)
        msg.fields[5].offset = 22
        with pytest.raises(InputError, match="field 'time' at offset 22 .* beyond point_step 26"):
            cloud_array(msg)
        msg = self._msg(self.rec, offs, self.rec.dtype.itemsize)
        msg.data = msg.data[:-1]
        with pytest.raises(InputError, match="PointCloud2 data is inconsistent"):
            cloud_array(msg)


def test_camera_info_models():
    K = [700.0, 0, 600, 0, 710, 180, 0, 0, 1]
    cam = camera_from_info(Ns(k=K, d=[0.0] * 5, distortion_model="plumb_bob", width=1242,
                              height=375))
    assert cam == {"model": "pinhole", "K": np.reshape(K, (3, 3)).tolist(), "width": 1242,
                   "height": 375}
    cam = camera_from_info(Ns(K=K, D=[0.1, -0.02, 0.001, 0.002], distortion_model="equidistant",
                              width=640, height=480))
    assert cam["model"] == "fisheye" and cam["D"] == [0.1, -0.02, 0.001, 0.002]
    cam = camera_from_info(Ns(k=K, d=list(range(1, 9)), distortion_model="rational_polynomial",
                              width=640, height=480))
    assert cam["model"] == "pinhole" and len(cam["D"]) == 8
    from paretocal.errors import InputError

    with pytest.raises(InputError, match="K is all zero"):
        camera_from_info(Ns(k=[0.0] * 9, d=[], distortion_model="", width=640, height=480))
    with pytest.raises(InputError, match="distortion_model 'double_sphere' is not supported"):
        camera_from_info(Ns(k=K, d=[0.1, 0.2], distortion_model="double_sphere", width=6,
                            height=4))


class TestPairing:
    def test_nearest_cloud_within_half_the_cloud_period(self):
        clouds = T0 + PERIOD * np.arange(5)
        images = T0 + PERIOD // 3 * np.arange(15) + 1_000_000      # a 30 Hz camera
        p = pair_by_stamp(images, clouds)
        assert p.max_dt == 0.05 and p.max_dt_rule == "half the median cloud period"
        # Each cloud goes to the image nearest to it: the images 1 ms after clouds 0..4.
        assert p.pairs == [(0, 0), (3, 1), (6, 2), (9, 3), (12, 4)]
        # (the camera's period is 33333333 ns: it drifts 1 ns per cloud)
        np.testing.assert_allclose(p.dt, (np.arange(5) - 1_000_000) / 1e9, rtol=0, atol=1e-12)
        assert len(p.images_dropped) == 10 and p.clouds_dropped == [] and p.matched == 5

    def test_tolerance_every_and_limit(self):
        clouds = T0 + PERIOD * np.arange(6)
        images = clouds + np.array([0, 10, 20, 60, 0, 5]) * 1_000_000
        p = pair_by_stamp(images, clouds, max_dt=0.05)
        assert [i for i, _ in p.pairs] == [0, 1, 2, 4, 5]
        # Image 3 is 60 ms after cloud 3 and 40 ms before cloud 4, which image 4 (0 ms) keeps.
        assert p.images_dropped == [3] and p.clouds_dropped == [3]
        p = pair_by_stamp(images, clouds, max_dt=0.05, every=2, limit=2)
        assert p.pairs == [(0, 0), (2, 2)] and p.matched == 5
        p = pair_by_stamp(images, clouds, max_dt=0.005)
        assert p.pairs == [(0, 0), (4, 4), (5, 5)]

    def test_one_cloud_needs_max_dt(self):
        from paretocal.errors import SettingsError

        with pytest.raises(SettingsError, match="pass --max-dt"):
            pair_by_stamp([T0], [T0])
        assert pair_by_stamp([T0], [T0 + 1], max_dt=0.01).pairs == [(0, 0)]


# --- bags of the three kinds ---------------------------------------------------------------------


@needs_rosbags
@pytest.mark.parametrize("kind, image", [("ros1", "rgb8"), ("sqlite3", "bgr8"), ("mcap", "png")])
def test_each_kind_extracts_the_same_frames(tmp_path, capfd, frames, kind, image):
    bag = rig_bag(tmp_path, kind, frames, image)
    out = tmp_path / "frames"
    code, stdout, err = run(capfd, "extract", bag, "--out", out, "--image-topic", "/camera/image",
                            "--cloud-topic", "/lidar/points")
    assert code == 0, err
    assert "3 frames from 3 images and 3 clouds" in stdout and "camera from " in stdout
    assert "no T_cam_lidar" in stdout
    report = json.loads((out / "extract.json").read_text())
    assert report["counts"]["pairs_kept"] == 3 and report["max_dt_s"] == 0.05
    assert report["camera_from"] == "/camera/camera_info"
    assert [f["dt_ms"] for f in report["frames"]] == pytest.approx([3.0] * 3)
    names = sorted(p.name for p in (out / "images").iterdir())
    assert names == [f"{k:06d}_{T0 + k * PERIOD}.png" for k in range(3)]
    got = load_frames(out)
    ref = load_frames(direct_folder(tmp_path / "direct", frames))
    for g, r, f in zip(got, ref, frames):
        np.testing.assert_array_equal(g.image, f.image)                   # pixel-identical
        np.testing.assert_array_equal(np.load(g.points_path), records(f))  # every field
        np.testing.assert_array_equal(g.points, r.points)
        np.testing.assert_array_equal(g.ring, r.ring)
        np.testing.assert_array_equal(g.time, r.time)
        assert g.point_fields == r.point_fields | {"warnings": g.point_fields["warnings"]}
        assert g.camera.K.tolist() == f.camera.K.tolist() == r.camera.K.tolist()
        assert (g.camera.model, g.camera.D, g.size) == (r.camera.model, r.camera.D,
                                                        r.size)
    assert not list(tmp_path.glob(".frames.*"))           # no staging folder left


@needs_rosbags
def test_a_rosbag2_metadata_alias_bomb_is_refused(tmp_path, capfd, frames):
    """A rosbag2 folder whose metadata.yaml starts with a "billion laughs" was read (rosbags'
    own YAML reader); it is read first by the reader of calib.yaml, which refuses it."""
    from .test_bad_input import _alias_bomb

    folder = rig_bag(tmp_path, "sqlite3", frames[:1]).parent
    meta = folder / "metadata.yaml"
    meta.write_text(_alias_bomb(meta.read_text()))
    bad(capfd, "extract", folder, "--out", tmp_path / "o", "--image-topic", "/camera/image",
        "--cloud-topic", "/lidar/points", "--max-dt", "0.05",
        expect=f"{meta}: its YAML aliases expand it to more than 1,000,000 values")
    assert not (tmp_path / "o").exists()


@needs_rosbags
def test_other_cloud_layout_and_mono16(tmp_path, capfd, frames):
    """A big-endian organised cloud with time first and 40-byte points, and 16-bit grey images:
    the same fields and the 16-bit pixels come out."""
    msgs = Msgs(False)
    layout = {"time": 0, "ring": 6, "intensity": 8, "x": 20, "y": 24, "z": 28}
    f = frames[0]
    rec = records(f)[: (len(f.points) // 4) * 4]
    grey = cv2.cvtColor(f.image, cv2.COLOR_BGR2GRAY).astype(np.uint16) * 257 + 3
    bag = write_bag(tmp_path / "b", "mcap", {
        "/img": [msgs.image(T0, grey, "mono16", bigendian=True)],
        "/pts": [msgs.cloud(T0, rec, layout, bigendian=True, point_step=40, height=4, row_pad=6)],
        "/info": [msgs.info(T0, f.camera)]})
    out = tmp_path / "out"
    code, _, err = run(capfd, "extract", bag.parent, "--out", out, "--image-topic", "/img",
                       "--cloud-topic", "/pts", "--camera-info-topic", "/info", "--max-dt", "0.01")
    assert code == 0, err
    (png,) = (out / "images").iterdir()
    np.testing.assert_array_equal(cv2.imread(str(png), cv2.IMREAD_UNCHANGED), grey)
    (npy,) = (out / "points").iterdir()
    got = np.load(npy)
    assert got.dtype.names == rec.dtype.names
    for n in rec.dtype.names:
        np.testing.assert_array_equal(got[n], rec[n])


@needs_rosbags
@pytest.mark.slow
def test_extracted_bag_calibrates_exactly_as_the_folder(tmp_path, capfd, frames):
    bag = rig_bag(tmp_path, "ros1", frames, "bgr8")
    init = tmp_path / "init.yaml"
    write_extrinsic(init, frames[0].T_ref)
    out = tmp_path / "frames"
    code, stdout, err = run(capfd, "extract", bag, "--out", out, "--image-topic", "/camera/image",
                            "--cloud-topic", "/lidar/points", "--init", init)
    assert code == 0, err
    assert "calib.yaml holds T_cam_lidar" in stdout
    np.testing.assert_allclose(yaml.safe_load((out / "calib.yaml").read_text())["T_cam_lidar"],
                               frames[0].T_ref, atol=1e-12)
    direct = direct_folder(tmp_path / "direct", frames)
    T = []
    for src in (out, direct):
        run_dir = tmp_path / f"run_{src.name}"
        code, _, err = run(capfd, "calibrate", src, "--init", init, "--out", run_dir, *FAST)
        assert code in (0, 3), err
        T.append(read_extrinsic(run_dir / "extrinsic.yaml"))
    assert np.array_equal(T[0], T[1])


@needs_rosbags
def test_every_limit_and_dropped_messages_are_reported(tmp_path, capfd, frames):
    msgs = Msgs(True)
    f = frames[0]
    rec = records(f)
    # Six images at 10 Hz; clouds 2 ms after all but the fourth, whose cloud is empty; one
    # extra cloud where there is no image.
    images = [msgs.image(T0 + k * PERIOD, f.image, "bgr8") for k in range(6)]
    clouds = [msgs.cloud(T0 + k * PERIOD + 2_000_000, rec) for k in (0, 1, 2, 4, 5)]
    clouds += [msgs.cloud(T0 + 3 * PERIOD, rec[:0]), msgs.cloud(T0 + 7 * PERIOD, rec)]
    bag = write_bag(tmp_path / "b.bag", "ros1", {"/img": images, "/pts": clouds,
                                                 "/info": [msgs.info(T0, f.camera)]})
    out = tmp_path / "out"
    code, stdout, err = run(capfd, "extract", bag, "--out", out, "--image-topic", "/img",
                            "--cloud-topic", "/pts", "--every", "2", "--limit", "2")
    assert code == 0, err
    r = json.loads((out / "extract.json").read_text())
    assert r["counts"] == {"images": 6, "clouds": 7, "pairs_matched": 5, "pairs_kept": 2,
                           "pairs_skipped": 3, "images_dropped": 1, "clouds_dropped": 2}
    assert r["dropped"] == {"image_stamps_ns": [T0 + 3 * PERIOD],
                            "cloud_stamps_ns": [T0 + 3 * PERIOD, T0 + 7 * PERIOD]}
    assert [x["image_stamp_ns"] for x in r["frames"]] == [T0, T0 + 2 * PERIOD]
    assert "2 frames from 6 images and 7 clouds: 5 pairs within 50 ms" in stdout
    assert "3 skipped by --every/--limit; dropped 1 images and 2 clouds" in stdout


@needs_rosbags
def test_without_topics_the_bags_only_image_and_cloud_topics_are_used(tmp_path, capfd, frames):
    """A bag with one (compressed) image topic and one PointCloud2 topic needs neither option:
    extract says which it used and writes the frames."""
    bag = rig_bag(tmp_path, "mcap", frames, "png")
    out = tmp_path / "frames"
    code, stdout, err = run(capfd, "extract", bag, "--out", out)
    assert code == 0, err
    assert ("paretocal: using --image-topic /camera/image and --cloud-topic /lidar/points "
            "(the bag's only topics of those kinds)") in stdout
    report = json.loads((out / "extract.json").read_text())
    assert report["topics"]["image"] == "/camera/image" and report["counts"]["pairs_kept"] == 3


# --- bad bags ------------------------------------------------------------------------------------


@pytest.fixture
def small_bag(tmp_path, frames):
    """A ROS1 bag of one frame with an extra depth image topic and a CameraInfo."""
    if importlib.util.find_spec("rosbags") is None:
        pytest.skip("rosbags is not installed: install paretocal[bags]")
    msgs = Msgs(True)
    f = frames[0]
    h, w = f.image.shape[:2]
    return write_bag(tmp_path / "s.bag", "ros1", {
        "/img": [msgs.image(T0, f.image, "bgr8")],
        "/depth": [msgs.image(T0, np.zeros((h, w), np.float32), "32FC1")],
        "/pts": [msgs.cloud(T0 + PERIOD, records(f)), msgs.cloud(T0 + 2 * PERIOD, records(f))],
        "/info": [msgs.info(T0, f.camera)]})


def _extract(bag, out, *extra):
    return ("extract", bag, "--out", out, "--image-topic", "/img", "--cloud-topic", "/pts",
            *extra)


class TestBadBags:
    def test_missing_topic_lists_the_topics(self, tmp_path, capfd, small_bag):
        bad(capfd, "extract", small_bag, "--out", tmp_path / "o", "--image-topic", "/cam",
            "--cloud-topic", "/pts",
            expect=(f"{small_bag}: no topic '/cam' (--image-topic); topics: ",
                    "/img (sensor_msgs/msg/Image, 1)", "/pts (sensor_msgs/msg/PointCloud2, 2)"))
        bad(capfd, "extract", small_bag, "--out", tmp_path / "o", "--image-topic", "/img",
            "--cloud-topic", "/img",
            expect="topic '/img' (--cloud-topic) holds sensor_msgs/msg/Image, not "
                   "sensor_msgs/msg/PointCloud2")
        assert not (tmp_path / "o").exists()

    def test_without_topics_the_topics_are_listed(self, tmp_path, capfd, small_bag):
        """Two image topics: extract cannot choose; it lists every topic with its type and
        message count on stdout, and says on one line which options to pass, with the
        candidates; nothing is written."""
        code, stdout, err = run(capfd, "extract", small_bag, "--out", tmp_path / "o")
        assert code == 2, err
        listing = stdout.strip().splitlines()
        assert listing[0] == f"paretocal: the topics of {small_bag}:"
        rows = [line.split() for line in listing[1:]]
        assert rows == [["image", "/depth", "sensor_msgs/msg/Image", "1", "message"],
                        ["image", "/img", "sensor_msgs/msg/Image", "1", "message"],
                        ["point", "cloud", "/pts", "sensor_msgs/msg/PointCloud2", "2", "messages"],
                        ["camera", "info", "/info", "sensor_msgs/msg/CameraInfo", "1", "message"]]
        (line,) = without_progress(err)
        assert line == (f"paretocal: error: {small_bag}: which topics to extract? pass "
                        "--image-topic TOPIC (image topics: /depth, /img); camera info topics: "
                        "/info; the bag's topics are listed on stdout")
        assert not (tmp_path / "o").exists()

    def test_with_stdout_closed_the_error_line_is_kept(self, tmp_path, small_bag):
        """The topics listed on a closed stdout (``extract ... | head -0``): the listing is
        lost, the exit-2 line saying which option to pass is not (it was: exit 1, no line)."""
        code, err = run_with_stdout_closed("extract", small_bag, "--out", tmp_path / "o")
        assert code == 2, err
        (line,) = without_progress(err)
        assert line.startswith(f"paretocal: error: {small_bag}: which topics to extract?")
        assert not (tmp_path / "o").exists()

    def test_no_pairs_within_the_tolerance_gives_the_nearest(self, tmp_path, capfd, small_bag):
        bad(capfd, *_extract(small_bag, tmp_path / "o"),
            expect=(f"{small_bag}: no image on '/img' has a cloud on '/pts' within 50 ms (half "
                    "the median cloud period); the nearest are 100 ms apart",
                    "pass a larger --max-dt"))
        assert not (tmp_path / "o").exists()

    def test_unsupported_encoding_names_it_and_the_topic(self, tmp_path, capfd, small_bag):
        bad(capfd, "extract", small_bag, "--out", tmp_path / "o", "--image-topic", "/depth",
            "--cloud-topic", "/pts", "--max-dt", "0.2",
            expect=(f"{small_bag}: topic '/depth', image 0", "image encoding '32FC1' is not "
                    "supported"))
        assert not (tmp_path / "o").exists() and not list(tmp_path.glob(".o.*"))

    def test_not_a_bag(self, tmp_path, capfd, small_bag):
        fake = tmp_path / "fake.bag"
        fake.write_text("hello\n")
        bad(capfd, *_extract(fake, tmp_path / "o"),
            expect=f"{fake}: not a readable ROS bag (File magic is invalid.)")
        bad(capfd, *_extract(tmp_path / "none.mcap", tmp_path / "o"),
            expect=f"{tmp_path / 'none.mcap'}: bag not found")
        bad(capfd, *_extract(small_bag.with_suffix(".txt"), tmp_path / "o"), expect="bag not found")
        bad(capfd, *_extract(tmp_path, tmp_path / "o"),
            expect=f"{tmp_path}: not a ROS bag (expected a ROS1 .bag file")

    def test_no_camera_info_and_non_empty_out(self, tmp_path, capfd, frames, small_bag):
        msgs = Msgs(True)
        bag = write_bag(tmp_path / "n.bag", "ros1", {
            "/img": [msgs.image(T0, frames[0].image, "bgr8")],
            "/pts": [msgs.cloud(T0, records(frames[0]))]})
        bad(capfd, *_extract(bag, tmp_path / "o", "--max-dt", "0.1"),
            expect=("cannot tell which CameraInfo topic gives the camera of '/img' (CameraInfo "
                    "topics: none); pass --camera-info-topic TOPIC, or --calib FILE"))
        calib = tmp_path / "calib.yaml"
        cam = frames[0].camera
        calib.write_text(yaml.safe_dump({"camera": {"K": cam.K.tolist(), "width": cam.width,
                                                    "height": cam.height}}))
        code, stdout, err = run(capfd, *_extract(bag, tmp_path / "o", "--max-dt", "0.1",
                                                 "--calib", calib))
        assert code == 0 and "camera from --calib" in stdout, err
        bad(capfd, *_extract(bag, tmp_path / "o", "--max-dt", "0.1", "--calib", calib),
            expect=f"--out {tmp_path / 'o'}: the folder is not empty")

    def test_an_empty_camera_info_topic_is_named(self, tmp_path, capfd, frames):
        msgs = Msgs(True)
        bag = write_bag(tmp_path / "e.bag", "ros1", {
            "/img": [msgs.image(T0, frames[0].image, "bgr8")],
            "/pts": [msgs.cloud(T0, records(frames[0]))]},
            empty={"/info": "sensor_msgs/msg/CameraInfo"})
        bad(capfd, *_extract(bag, tmp_path / "o", "--max-dt", "0.1"),
            expect=(f"{bag}: topic '/info': the CameraInfo topic holds no message; pass "
                    "--camera-info-topic TOPIC with messages, or --calib FILE"))
        assert not (tmp_path / "o").exists()

    def test_bad_options(self, tmp_path, capfd, small_bag):
        out = tmp_path / "o"
        bad(capfd, *_extract(small_bag, out, "--every", "0"), expect="--every 0: must be at least 1")
        bad(capfd, *_extract(small_bag, out, "--limit", "0"), expect="--limit 0: must be at least 1")
        bad(capfd, *_extract(small_bag, out, "--max-dt", "-1"),
            expect="--max-dt -1.0: must be a positive number of seconds")
        calib = tmp_path / "c.yaml"
        calib.write_text("foo: 1\n")
        bad(capfd, *_extract(small_bag, out, "--calib", calib),
            expect=f"{calib}: --calib needs a 'camera' section")
        calib.write_text("camera: {K: [[700, 0, 600], [0, 700, 180], [0, 0, 1]], width: 1242, "
                         "height: 375}\n")
        bad(capfd, *_extract(small_bag, out, "--calib", calib, "--camera-info-topic", "/info"),
            expect="give either --camera-info-topic or --calib (with its camera), not both")
        line = bad(capfd, "extract", small_bag, "--out", out, "--cloud-topic", "/pts",
                   expect=(f"{small_bag}: which topics to extract? pass --image-topic TOPIC "
                           "(image topics: /depth, /img); camera info topics: /info"))
        assert "--cloud-topic" not in line
        assert not out.exists()

    def test_an_interrupt_leaves_no_folder(self, tmp_path, capfd, small_bag, monkeypatch):
        import paretocal.extract

        def stop(*a, **k):
            raise KeyboardInterrupt

        monkeypatch.setattr(paretocal.extract, "cloud_array", stop)   # after the image is written
        code, _, err = run(capfd, *_extract(small_bag, tmp_path / "o", "--max-dt", "0.2"))
        assert code == 130
        assert without_progress(err) == ["paretocal: interrupted; nothing was written to --out (the partial "
                                          "extraction was removed); run the same command again"]
        assert sorted(p.name for p in tmp_path.iterdir()) == ["s.bag"]

    def test_calibrate_a_bag_says_to_extract_it_first(self, tmp_path, capfd, small_bag):
        bad(capfd, "calibrate", small_bag, "--out", tmp_path / "run",
            expect=(f"{small_bag}: a ROS bag; extract its frames to a folder first (paretocal "
                    f"extract {small_bag} --out DIR --image-topic TOPIC --cloud-topic /pts; image "
                    "topics: /depth, /img) and pass that folder"))

    def test_without_rosbags_extract_says_how_to_install(self, tmp_path, capfd, monkeypatch):
        for name in [m for m in sys.modules if m == "rosbags" or m.startswith("rosbags.")]:
            monkeypatch.delitem(sys.modules, name)
        monkeypatch.setitem(sys.modules, "rosbags", None)
        bag = tmp_path / "x.bag"
        bag.write_bytes(b"#ROSBAG V2.0\n")
        bad(capfd, *_extract(bag, tmp_path / "o"),
            expect="reading ROS bags needs the rosbags package: install paretocal[bags]")
        bad(capfd, "calibrate", bag, "--out", tmp_path / "run",
            expect="--cloud-topic TOPIC; install paretocal[bags])")
