"""Point cloud formats (.pcd, .ply), camera models (fisheye, ROS camera_info) and the exports of
the chosen extrinsic (KITTI calib_velo_to_cam.txt, ROS tf_static.yaml, extrinsic_inverse.yaml)."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path
from types import SimpleNamespace

import cv2
import lzf
import numpy as np
import pytest
import yaml
from pypcd4 import Encoding, PointCloud
from scipy.spatial.transform import Rotation

from paretocal.camera import Camera, project
from paretocal.errors import InputError
from paretocal.geometry import apply_correction, invert
from paretocal.io import detect_source, load_frames, read_extrinsic, write_extrinsic
from paretocal.io.exports import (INVERSE_FILE, KITTI_FILE, TF_FILE, kitti_rect_of,
                                  read_extrinsic_inverse, read_kitti_velo_to_cam, read_tf_static,
                                  write_exports)
from paretocal.io.text import read_kitti_calib
from paretocal.io.clouds import read_points
from paretocal.report.results import write_outputs

# --- writers used by the tests (independent of the readers under test) ---------------------------

_PCD_TYPE = {"f": "F", "u": "U", "i": "I"}


def pcd_bytes(cols: list[tuple[str, np.ndarray]], data: str = "binary", width=None,
              height: int = 1) -> bytes:
    """A PCD file written by hand: one field per column, little endian, PCL's header order.

    ``data`` is ascii (every value written so that it reads back exactly), binary or
    binary_compressed (PCL's field-major LZF block after two uint32 size words).
    """
    n = len(cols[0][1])
    arr = np.zeros(n, dtype=[(f"c{j}", "<" + c.dtype.str[1:]) for j, (_, c) in enumerate(cols)])
    for j, (_, c) in enumerate(cols):
        arr[f"c{j}"] = c
    width = n if width is None else width
    head = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
            f"FIELDS {' '.join(name for name, _ in cols)}\n"
            f"SIZE {' '.join(str(c.dtype.itemsize) for _, c in cols)}\n"
            f"TYPE {' '.join(_PCD_TYPE[c.dtype.kind] for _, c in cols)}\n"
            f"COUNT {' '.join('1' for _ in cols)}\n"
            f"WIDTH {width}\nHEIGHT {height}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n")
    if data == "ascii":
        return (head + _ascii_rows(arr)).encode()
    if data == "binary_compressed":
        raw = b"".join(c.astype("<" + c.dtype.str[1:]).tobytes() for _, c in cols)
        packed = lzf.compress(raw)
        return head.encode() + np.array([len(packed), len(raw)], "<u4").tobytes() + packed
    return head.encode() + arr.tobytes()


def _ascii_rows(arr: np.ndarray) -> str:
    """Records as text lines; repr keeps every float64 (and float32) and integer exact."""
    return "".join(" ".join(map(repr, row)) + "\n" for row in arr.tolist())


_PLY_TYPE = {"f4": "float", "f8": "double", "u1": "uchar", "u2": "ushort", "i4": "int",
             "i1": "char", "i2": "short", "u4": "uint"}


def ply_bytes(cols: list[tuple[str, np.ndarray]], fmt: str = "binary_little_endian",
              face: bool = False, before: bool = False) -> bytes:
    """A PLY file written by hand: a vertex element, optionally a face element after it and (ascii)
    a 'camera' element with a list property before it."""
    n = len(cols[0][1])
    endian = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "<"}[fmt]
    arr = np.zeros(n, dtype=[(name, endian + c.dtype.str[1:]) for name, c in cols])
    for name, c in cols:
        arr[name] = c
    head = ["ply", f"format {fmt} 1.0", "comment written by test_formats"]
    if before:
        head += ["element camera 2", "property list uchar float params"]
    head += [f"element vertex {n}"] + [f"property {_PLY_TYPE[c.dtype.str[1:]]} {name}"
                                        for name, c in cols]
    if face:
        head += ["element face 1", "property list uchar int vertex_indices"]
    head.append("end_header")
    text = "\n".join(head) + "\n"
    if fmt == "ascii":
        pre = "3 1 2 3\n0\n" if before else ""
        return (text + pre + _ascii_rows(arr) + ("3 0 1 2\n" if face else "")).encode()
    tail = b""
    if face:
        tail = np.array([3], endian + "u1").tobytes() + np.array([0, 1, 2], endian + "i4").tobytes()
    return text.encode() + arr.tobytes() + tail


def xyzi_cols(points, intensity: str | None = "intensity"):
    cols = [(c, np.ascontiguousarray(points[:, j])) for j, c in enumerate("xyz")]
    if intensity:
        cols.append((intensity, np.ascontiguousarray(points[:, 3])))
    return cols


def no_intensity(points):
    out = points.copy()
    out[:, 3] = 0
    return out


def err_for(path, what):
    """A match pattern for an InputError that names ``path`` and says ``what``."""
    return re.escape(str(path)) + ".*" + what


@pytest.fixture(scope="module")
def pts(raw_frames):
    """The points of a real KITTI frame."""
    return raw_frames[0].points


# --- point clouds ------------------------------------------------------------------------------


class TestPcd:
    @pytest.mark.parametrize("encoding", [Encoding.ASCII, Encoding.BINARY,
                                          Encoding.BINARY_COMPRESSED])
    @pytest.mark.parametrize("with_intensity", [True, False])
    def test_pypcd4_files_round_trip_a_real_frame(self, tmp_path, pts, encoding, with_intensity):
        if encoding == Encoding.ASCII:
            pts = pts[::8]                  # formatting text is slow: a subset keeps it fast
        pc = (PointCloud.from_xyzi_points(pts) if with_intensity
              else PointCloud.from_xyz_points(pts[:, :3]))
        p = tmp_path / "frame.pcd"
        pc.save(p, encoding)
        if encoding == Encoding.BINARY_COMPRESSED:
            assert b"DATA binary_compressed" in p.read_bytes()[:400]
        got = read_points(p)
        assert got.dtype == np.float32 and got.shape == pts.shape
        np.testing.assert_array_equal(got, pts if with_intensity else no_intensity(pts))

    @pytest.mark.parametrize("name", ["intensity", "i", "reflectance", "Intensity",
                                      "reflectivity", "signal"])
    def test_intensity_field_names_and_other_fields(self, tmp_path, pts, name):
        sub = pts[::50]
        ring = (np.arange(len(sub)) % 64).astype(np.uint16)
        cols = [("ring", ring)] + xyzi_cols(sub, None) + [("t", np.zeros(len(sub), np.float64)),
                                                          (name, sub[:, 3].copy())]
        p = tmp_path / "a.pcd"
        p.write_bytes(pcd_bytes(cols, "binary"))
        np.testing.assert_array_equal(read_points(p), sub)

    def test_uint8_intensity_and_float64_coordinates(self, tmp_path, pts):
        sub = pts[::50]
        inten = (np.arange(len(sub)) % 256).astype(np.uint8)
        cols = [(c, sub[:, j].astype(np.float64)) for j, c in enumerate("xyz")]
        p = tmp_path / "a.pcd"
        p.write_bytes(pcd_bytes(cols + [("intensity", inten)], "binary"))
        got = read_points(p)
        np.testing.assert_array_equal(got[:, :3], sub[:, :3])
        np.testing.assert_array_equal(got[:, 3], inten.astype(np.float32))

    def test_a_compressed_field_of_several_values_keeps_the_fields_after_it(self, tmp_path, pts):
        """binary_compressed as PCL writes it: a field of COUNT 3 (normals) holds its three
        values point by point inside its block; the fields after it read back exactly."""
        sub = pts[::50]
        n = len(sub)
        normal = np.arange(3 * n, dtype=np.float32).reshape(n, 3)
        raw = (b"".join(sub[:, j].astype("<f4").tobytes() for j in range(3))
               + normal.astype("<f4").tobytes() + sub[:, 3].astype("<f4").tobytes())
        packed = lzf.compress(raw)
        head = ("VERSION 0.7\nFIELDS x y z normal intensity\nSIZE 4 4 4 4 4\nTYPE F F F F F\n"
                f"COUNT 1 1 1 3 1\nWIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA binary_compressed\n")
        p = tmp_path / "a.pcd"
        p.write_bytes(head.encode() + np.array([len(packed), len(raw)], "<u4").tobytes() + packed)
        np.testing.assert_array_equal(read_points(p), sub)

    def test_ascii_tolerates_tabs_trailing_blanks_and_header_comments(self, tmp_path):
        text = ("# .PCD v0.7\nVERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
                "WIDTH 3\nHEIGHT 1\n# a comment\nPOINTS 3\nDATA ascii\n"
                "1 2 3 \n4\t5   6\r\n7 8 9\n")
        p = tmp_path / "a.pcd"
        p.write_text(text)
        np.testing.assert_array_equal(read_points(p),
                                      [[1, 2, 3, 0], [4, 5, 6, 0], [7, 8, 9, 0]])

    def test_nan_points_of_an_organised_cloud_are_dropped_like_bin(self, tmp_path, caplog):
        xyz = np.arange(30, dtype=np.float32).reshape(10, 3)
        xyz[2] = np.nan
        xyz[7, 1] = np.inf
        inten = np.ones(10, np.float32)
        inten[4] = np.nan
        p = tmp_path / "a.pcd"
        cols = [(c, xyz[:, j].copy()) for j, c in enumerate("xyz")] + [("intensity", inten)]
        p.write_bytes(pcd_bytes(cols, "binary", width=5, height=2))
        got = read_points(p)
        assert len(got) == 8 and "dropped 2 points" in caplog.text
        assert got[3, 3] == 0.0                       # the NaN intensity (row 4) reads as zero
        # The same cloud as a KITTI .bin gives the same points.
        b = tmp_path / "a.bin"
        np.column_stack([xyz, inten]).astype(np.float32).tofile(b)
        np.testing.assert_array_equal(read_points(b), got)

    def _good(self, pts):
        return pcd_bytes(xyzi_cols(pts[:100]), "binary")

    @pytest.mark.parametrize("make, what", [
        (lambda g: g[:-10], "truncated"),
        (lambda g: g.replace(b"FIELDS x y z intensity", b"FIELDS x y q intensity"),
         "no 'z' field"),
        (lambda g: g.replace(b"DATA binary\n", b"DAT binary\n"), "no 'DATA' line"),
        (lambda g: b"ply\nformat ascii 1.0\n" + g, "not a PCD file"),
        (lambda g: g.replace(b"WIDTH 100", b"WIDTH 99"), "WIDTH 99 x HEIGHT 1 but POINTS 100"),
        (lambda g: g.replace(b"TYPE F F F F", b"TYPE F F F"), "TYPE has 3 entries for 4 FIELDS"),
        (lambda g: g.replace(b"SIZE 4 4 4 4", b"SIZE 4 4 3 4"), "unsupported TYPE F SIZE 3"),
        (lambda g: g.replace(b"DATA binary", b"DATA binary_lzma"), "DATA 'binary_lzma'"),
        (lambda g: g.replace(b"POINTS 100", b"POINTS many"), "POINTS must be"),
    ])
    def test_malformed_binary(self, tmp_path, pts, make, what):
        p = tmp_path / "bad.pcd"
        p.write_bytes(make(self._good(pts)))
        with pytest.raises(InputError, match=err_for(p, what)):
            read_points(p)

    def test_malformed_ascii(self, tmp_path, pts):
        good = pcd_bytes(xyzi_cols(pts[:20]), "ascii")
        p = tmp_path / "bad.pcd"
        p.write_bytes(good.rsplit(b"\n", 3)[0] + b"\n")          # two rows short
        with pytest.raises(InputError, match=err_for(p, "18 rows .* POINTS 20")):
            read_points(p)
        head, _, body = good.partition(b"DATA ascii\n")
        rows = body.split(b"\n")
        rows[3] += b" 1.5"                                        # an extra value in row 3
        p.write_bytes(head + b"DATA ascii\n" + b"\n".join(rows))
        with pytest.raises(InputError, match=err_for(p, "cannot be parsed")):
            read_points(p)

    def test_corrupt_compressed(self, tmp_path, pts):
        p = tmp_path / "c.pcd"
        PointCloud.from_xyzi_points(pts[:2000]).save(p, Encoding.BINARY_COMPRESSED)
        raw = p.read_bytes()
        p.write_bytes(raw[: len(raw) - 200])
        with pytest.raises(InputError, match=err_for(p, "binary_compressed data cannot be decoded")):
            read_points(p)


class TestPly:
    @pytest.mark.parametrize("fmt", ["binary_little_endian", "binary_big_endian", "ascii"])
    def test_real_frame_round_trip(self, tmp_path, pts, fmt):
        if fmt == "ascii":
            pts = pts[::8]
        p = tmp_path / "frame.ply"
        p.write_bytes(ply_bytes(xyzi_cols(pts), fmt, face=True))
        got = read_points(p)
        assert got.dtype == np.float32
        np.testing.assert_array_equal(got, pts)

    def test_no_intensity_double_coordinates(self, tmp_path, pts):
        cols = [(c, pts[:, j].astype(np.float64)) for j, c in enumerate("xyz")]
        p = tmp_path / "a.ply"
        p.write_bytes(ply_bytes(cols))
        np.testing.assert_array_equal(read_points(p), no_intensity(pts))

    def test_uchar_reflectance_and_an_element_before_the_vertices(self, tmp_path, pts):
        sub = pts[::100]
        refl = (np.arange(len(sub)) % 200).astype(np.uint8)
        p = tmp_path / "a.ply"
        p.write_bytes(ply_bytes(xyzi_cols(sub, None) + [("reflectance", refl)], "ascii",
                                face=True, before=True))
        got = read_points(p)
        np.testing.assert_array_equal(got[:, :3], sub[:, :3])
        np.testing.assert_array_equal(got[:, 3], refl)

    @pytest.mark.parametrize("make, what", [
        (lambda g: g[:-7], "truncated"),
        (lambda g: g.replace(b"ply\n", b"plx\n", 1), "not a PLY file"),
        (lambda g: g.replace(b"property float x", b"property float u"), "no 'x' field"),
        (lambda g: g.replace(b"end_header", b"end_hdr"), "no 'end_header'"),
        (lambda g: g.replace(b"binary_little_endian", b"binary_middle_endian"),
         "unsupported PLY format"),
        (lambda g: g.replace(b"property float z", b"property list uchar float z"), "is a list"),
        (lambda g: g.replace(b"element vertex 50", b"element vertex fifty"), "malformed PLY header"),
        (lambda g: g.replace(b"property float y", b"property float32x y"), "unknown type"),
    ])
    def test_malformed(self, tmp_path, pts, make, what):
        p = tmp_path / "bad.ply"
        p.write_bytes(make(ply_bytes(xyzi_cols(pts[:50]))))
        with pytest.raises(InputError, match=err_for(p, what)):
            read_points(p)

    def test_truncated_ascii(self, tmp_path, pts):
        p = tmp_path / "bad.ply"
        p.write_bytes(ply_bytes(xyzi_cols(pts[:50]), "ascii")[:-40])
        with pytest.raises(InputError, match=err_for(p, "(truncated|cannot be parsed)")):
            read_points(p)


# --- generic folders ---------------------------------------------------------------------------


def generic_folder(root, frames, point_writer, camera=None, extra=None):
    """A generic-layout folder built from real frames with the given point cloud writer."""
    (root / "images").mkdir(parents=True)
    (root / "points").mkdir()
    f0 = frames[0]
    calib = {"camera": camera or {"K": f0.camera.K.tolist(), "width": f0.camera.width,
                                  "height": f0.camera.height},
             "T_cam_lidar": f0.T_ref.tolist()}
    calib.update(extra or {})
    (root / "calib.yaml").write_text(yaml.safe_dump(calib))
    for f in frames:
        cv2.imwrite(str(root / "images" / f"{f.name}.png"), f.image)
        point_writer(root / "points", f)
    return root


class TestGenericFolder:
    def test_kitti_frames_as_pcd_and_ply_load_like_the_originals(self, tmp_path, raw_frames):
        frames = raw_frames[:3]

        def writer(folder, f):
            if f is frames[1]:
                (folder / f"{f.name}.ply").write_bytes(ply_bytes(xyzi_cols(f.points)))
            else:
                enc = Encoding.BINARY_COMPRESSED if f is frames[0] else Encoding.BINARY
                PointCloud.from_xyzi_points(f.points).save(folder / f"{f.name}.pcd", enc)

        root = generic_folder(tmp_path / "rig", frames, writer)
        assert detect_source(root).layout == "folder"
        got = load_frames(root)
        assert [f.name for f in got] == [f.name for f in frames]
        for a, b in zip(got, frames):
            np.testing.assert_array_equal(a.points, b.points)
            np.testing.assert_array_equal(a.camera.K, b.camera.K)
            assert (a.camera.width, a.camera.height) == (b.camera.width, b.camera.height)
            np.testing.assert_allclose(a.T_ref, b.T_ref, atol=1e-12)
            np.testing.assert_array_equal(a.image, b.image)
            assert a.kitti_rect is None and b.kitti_rect is not None
        assert got[0].points_path.suffix == ".pcd" and got[1].points_path.suffix == ".ply"

    def test_bad_point_file_in_a_folder_names_it(self, tmp_path, raw_frames):
        def writer(folder, f):
            (folder / f"{f.name}.pcd").write_bytes(b"VERSION 0.7\nFIELDS x y\n")

        root = generic_folder(tmp_path / "rig", raw_frames[:1], writer)
        with pytest.raises(InputError, match=err_for(root / "points" / raw_frames[0].name, "DATA")):
            load_frames(root)


# --- cameras ---------------------------------------------------------------------------------


def _blob_centroids(gray: np.ndarray) -> np.ndarray:
    n, labels = cv2.connectedComponents((gray > 20).astype(np.uint8))
    v, u = np.mgrid[: gray.shape[0], : gray.shape[1]]
    w = gray.astype(np.float64)
    out = []
    for k in range(1, n):
        m = labels == k
        out.append([(w[m] * u[m]).sum() / w[m].sum(), (w[m] * v[m]).sum() / w[m].sum()])
    return np.array(out)


class TestFisheye:
    W, H = 640, 480
    K = np.array([[300.0, 0, 319.5], [0, 300.0, 239.5], [0, 0, 1]])
    D = [0.08, -0.03, 0.01, -0.002]

    def scene(self, rng):
        """Points (LiDAR frame), their camera-frame copy and the extrinsic."""
        gx, gy = np.meshgrid(np.linspace(-0.6, 0.6, 5), np.linspace(-0.45, 0.45, 5))
        z = rng.uniform(2.0, 10.0, gx.size)
        p_cam = np.column_stack([gx.ravel() * z, gy.ravel() * z, z])
        T = np.eye(4)
        T[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]     # KITTI-like LiDAR axes
        T = apply_correction(T, np.array([0.1, -0.05, 0.2, 3.0, -2.0, 1.5]))
        p_lidar = (invert(T) @ np.column_stack([p_cam, np.ones(len(p_cam))]).T).T[:, :3]
        return p_lidar, p_cam, T

    def render(self, p_cam):
        """A distorted fisheye image with a Gaussian dot at each point's projection."""
        uv, _ = cv2.fisheye.projectPoints(p_cam.reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                          self.K, np.array(self.D))
        uv = uv.reshape(-1, 2)
        img = np.zeros((self.H, self.W))
        for a, b in uv:                          # each dot drawn within 6 px (5 sigma)
            u0, v0 = int(a) - 6, int(b) - 6
            v, u = np.mgrid[v0: v0 + 14, u0: u0 + 14]
            img[v0: v0 + 14, u0: u0 + 14] += 255 * np.exp(-((u - a) ** 2 + (v - b) ** 2)
                                                          / (2 * 1.2 ** 2))
        return np.clip(img, 0, 255).astype(np.uint8), uv

    def folder(self, tmp_path, rng, camera_extra):
        p_lidar, p_cam, T = self.scene(rng)
        img, uv_fisheye = self.render(p_cam)
        root = tmp_path / "fish"
        (root / "images").mkdir(parents=True)
        (root / "points").mkdir()
        cv2.imwrite(str(root / "images" / "000000.png"), img)
        pts = np.column_stack([p_lidar, np.ones(len(p_lidar))]).astype(np.float32)
        PointCloud.from_xyzi_points(pts).save(root / "points" / "000000.pcd", Encoding.BINARY)
        camera = {"K": self.K.tolist(), "width": self.W, "height": self.H, **camera_extra}
        (root / "calib.yaml").write_text(yaml.safe_dump({"camera": camera,
                                                         "T_cam_lidar": T.tolist()}))
        return root, uv_fisheye, img

    @pytest.mark.parametrize("model", ["fisheye", "equidistant", "kannala_brandt"])
    def test_dots_land_on_the_fisheye_projection(self, tmp_path, rng, model):
        root, uv_fisheye, raw = self.folder(tmp_path, rng, {"model": model, "D": self.D})
        (frame,) = load_frames(root)
        np.testing.assert_array_equal(frame.camera.K, self.K)
        assert frame.camera.model == "fisheye" and frame.camera.D == tuple(self.D)
        np.testing.assert_array_equal(frame.image, cv2.imread(str(root / "images" /
                                                                  "000000.png")))  # as taken
        uv, _, visible = project(frame.points, frame.camera, frame.T_ref)
        assert visible.all()
        # The camera's projection is OpenCV's fisheye one...
        np.testing.assert_allclose(uv, uv_fisheye, atol=1e-6)
        # ... and the dots the lens drew in the image lie there, within a pixel.
        found = _blob_centroids(frame.image[:, :, 0])
        assert len(found) == len(uv)
        d = np.linalg.norm(found[:, None] - uv[None], axis=2).min(axis=0)
        assert d.max() < 1.0, d
        # A pinhole camera with the same K would put them far away.
        pin = project(frame.points, Camera(self.K, self.W, self.H), frame.T_ref)[0]
        assert np.abs(pin - uv).max() > 20

    def test_fisheye_needs_four_coefficients(self, tmp_path, rng):
        root, _, _ = self.folder(tmp_path, rng, {"model": "fisheye", "D": self.D + [0.0]})
        with pytest.raises(InputError, match=err_for(root / "calib.yaml", "camera.D .*4 fisheye")):
            detect_source(root)

    def test_unknown_model(self, tmp_path, rng):
        root, _, _ = self.folder(tmp_path, rng, {"model": "omnidir"})
        with pytest.raises(InputError, match=err_for(root / "calib.yaml", "camera.model 'omnidir'")):
            detect_source(root)


def _ros_matrix(rows, cols, data):
    return {"rows": rows, "cols": cols, "data": [float(v) for v in np.ravel(data)]}


def camera_info(frame, D, model="plumb_bob"):
    return {"image_width": frame.camera.width, "image_height": frame.camera.height,
            "camera_name": "kitti_cam_02",
            "camera_matrix": _ros_matrix(3, 3, frame.camera.K),
            "distortion_model": model,
            "distortion_coefficients": _ros_matrix(1, len(D), D),
            "rectification_matrix": _ros_matrix(3, 3, np.eye(3)),
            "projection_matrix": _ros_matrix(3, 4, np.column_stack([frame.camera.K, np.zeros(3)]))}


def write_points_bin(folder, f):
    f.points.tofile(folder / f"{f.name}.bin")


class TestCameraInfo:
    D = [-0.3, 0.1, 0.001, 0.0005, 0.02]

    def test_plumb_bob_matches_the_equivalent_calib_yaml(self, tmp_path, raw_frames):
        f = raw_frames[:1]
        cam = {"K": f[0].camera.K.tolist(), "width": f[0].camera.width,
               "height": f[0].camera.height, "D": self.D}
        plain = generic_folder(tmp_path / "plain", f, write_points_bin, camera=cam)
        by_file = generic_folder(tmp_path / "file", f, write_points_bin,
                                 extra={"camera_info": "intrinsics/cam.yaml"})
        calib = yaml.safe_load((by_file / "calib.yaml").read_text())
        del calib["camera"]
        (by_file / "calib.yaml").write_text(yaml.safe_dump(calib))
        (by_file / "intrinsics").mkdir()
        (by_file / "intrinsics" / "cam.yaml").write_text(
            yaml.safe_dump(camera_info(f[0], self.D), sort_keys=False))
        inline = generic_folder(tmp_path / "inline", f, write_points_bin,
                                camera=camera_info(f[0], self.D))
        a, b, c = (detect_source(r).frames[0] for r in (plain, by_file, inline))
        for other in (b, c):
            np.testing.assert_array_equal(other.camera.K, a.camera.K)
            assert (other.camera.width, other.camera.height) == (a.camera.width, a.camera.height)
            assert other.camera.D == a.camera.D == tuple(self.D)
            assert other.camera.model == a.camera.model == "pinhole"
        images = [load_frames(r)[0].image for r in (plain, by_file, inline)]
        np.testing.assert_array_equal(images[1], images[0])
        np.testing.assert_array_equal(images[2], images[0])
        np.testing.assert_array_equal(images[0], f[0].image)      # used as taken

    @pytest.mark.parametrize("form", ["ros1", "ros2", "P only", "file"])
    def test_the_message_form(self, tmp_path, raw_frames, form):
        """sensor_msgs/CameraInfo as rostopic / ros2 topic echo print it: flat K, D, P."""
        f = raw_frames[0]
        K = [float(v) for v in f.camera.K.ravel()]
        P = [float(v) for v in np.column_stack([f.camera.K, np.zeros(3)]).ravel()]
        msg = {"height": f.camera.height, "width": f.camera.width,
               "distortion_model": "plumb_bob", "D": self.D, "K": K, "R": np.eye(3).ravel().tolist(),
               "P": P}
        if form == "ros2":
            msg = {k.lower(): v for k, v in msg.items()}
        if form == "P only":
            msg["K"] = [0.0] * 9
        extra = {"camera_info": "cam.yaml"} if form == "file" else {}
        root = generic_folder(tmp_path / "rig", [f], write_points_bin,
                              camera=None if form == "file" else msg, extra=extra)
        if form == "file":
            calib = yaml.safe_load((root / "calib.yaml").read_text())
            calib.pop("camera", None)
            (root / "calib.yaml").write_text(yaml.safe_dump(calib))
            (root / "cam.yaml").write_text(yaml.safe_dump(msg))
        cam = detect_source(root).frames[0].camera
        np.testing.assert_array_equal(cam.K, f.camera.K)
        assert cam.D == tuple(self.D) and cam.model == "pinhole"
        assert (cam.width, cam.height) == (f.camera.width, f.camera.height)

    def test_the_message_form_names_missing_keys(self, tmp_path, raw_frames):
        msg = {"distortion_model": "plumb_bob", "d": [], "k": [1.0] * 8, "width": 10,
               "height": 10}
        root = generic_folder(tmp_path / "rig", raw_frames[:1], write_points_bin, camera=msg)
        with pytest.raises(InputError, match=r"camera\.k must hold 9 numbers"):
            detect_source(root)

    def test_the_message_form_names_a_ragged_d(self, tmp_path, raw_frames):
        msg = {"distortion_model": "plumb_bob", "d": [[1.0, 2.0], [3.0]], "k": [1.0] * 9,
               "width": 10, "height": 10}
        msg["k"][1] = msg["k"][3] = msg["k"][6] = msg["k"][7] = 0.0
        root = generic_folder(tmp_path / "rig", raw_frames[:1], write_points_bin, camera=msg)
        with pytest.raises(InputError, match=r"camera\.d "):
            detect_source(root)

    def test_equidistant_and_rational_polynomial(self, tmp_path, raw_frames):
        f = raw_frames[:1]
        root = generic_folder(tmp_path / "eq", f, write_points_bin,
                              camera=camera_info(f[0], [0.1, 0.01, 0, 0], "equidistant"))
        fr = detect_source(root).frames[0]
        assert fr.camera.model == "fisheye" and fr.camera.D == (0.1, 0.01, 0, 0)
        root = generic_folder(tmp_path / "rp", f, write_points_bin,
                              camera=camera_info(f[0], [0.1, 0.01, 0, 0, 0, 0.2, 0, 0],
                                                 "rational_polynomial"))
        fr = detect_source(root).frames[0]
        assert fr.camera.model == "pinhole" and len(fr.camera.D) == 8

    @pytest.mark.parametrize("edit, what", [
        (lambda c: c["camera_matrix"].update(data=[1.0] * 8), r"camera_matrix\.data has 8 values"),
        (lambda c: c["camera_matrix"].update(rows=1, cols=9), "camera_matrix must be 3 x 3"),
        (lambda c: c["distortion_coefficients"]["data"].__setitem__(1, float("nan")),
         "distortion_coefficients contains NaN"),
        (lambda c: c.update(distortion_model="kannala"), "distortion_model 'kannala'"),
        (lambda c: c.update(distortion_model="equidistant"), "4 fisheye"),
        (lambda c: c.pop("image_height"), "missing image_height"),
        (lambda c: c.pop("distortion_model"), "distortion_model is missing"),
    ])
    def test_malformed_camera_info_names_file_and_key(self, tmp_path, raw_frames, edit, what):
        root = generic_folder(tmp_path / "rig", raw_frames[:1], write_points_bin,
                              extra={"camera_info": "cam.yaml"})
        calib = yaml.safe_load((root / "calib.yaml").read_text())
        del calib["camera"]
        (root / "calib.yaml").write_text(yaml.safe_dump(calib))
        info = camera_info(raw_frames[0], self.D)
        edit(info)
        (root / "cam.yaml").write_text(yaml.safe_dump(info))
        with pytest.raises(InputError, match=err_for(root / "cam.yaml", what)):
            detect_source(root)

    def test_inline_errors_name_the_camera_section(self, tmp_path, raw_frames):
        info = camera_info(raw_frames[0], self.D)
        info["camera_matrix"]["data"][0] = float("inf")
        root = generic_folder(tmp_path / "rig", raw_frames[:1], write_points_bin, camera=info)
        with pytest.raises(InputError, match=err_for(root / "calib.yaml",
                                                     "camera.camera_matrix contains NaN")):
            detect_source(root)

    def test_missing_file_and_both_sources(self, tmp_path, raw_frames):
        root = generic_folder(tmp_path / "rig", raw_frames[:1], write_points_bin,
                              extra={"camera_info": "nope.yaml"})
        with pytest.raises(InputError, match="either 'camera' or 'camera_info'"):
            detect_source(root)
        calib = yaml.safe_load((root / "calib.yaml").read_text())
        del calib["camera"]
        (root / "calib.yaml").write_text(yaml.safe_dump(calib))
        with pytest.raises(InputError, match=err_for(root / "calib.yaml", "nope.yaml not found")):
            detect_source(root)


# --- exports of the chosen extrinsic ----------------------------------------------------------


@pytest.fixture(scope="module")
def T_est(raw_frames):
    """A calibration result: KITTI's reference moved by a few centimetres and degrees."""
    return apply_correction(raw_frames[0].T_ref, np.array([0.05, -0.03, 0.08, 1.5, -0.8, 0.6]))


def kitti_copy(raw_date, dst, velo_to_cam_text):
    """A KITTI raw date folder with the given calib_velo_to_cam.txt; returns the drive folder."""
    dst.mkdir(parents=True)
    (dst / "calib_cam_to_cam.txt").write_text((raw_date / "calib_cam_to_cam.txt").read_text())
    (dst / "calib_velo_to_cam.txt").write_text(velo_to_cam_text)
    drive = next(p for p in raw_date.iterdir() if p.name.endswith("_sync"))
    (dst / drive.name).symlink_to(drive.resolve(), target_is_directory=True)
    return dst / drive.name


class TestKittiExport:
    def test_kitti_raw_source_writes_tr_that_kitti_tools_turn_back_into_T(
            self, tmp_path, raw_date, raw_frames, T_est):
        rect = kitti_rect_of(raw_frames)
        assert rect is not None
        (path,) = [p for p in write_exports(tmp_path, T_est, rect, "9.9") if p.name == KITTI_FILE]
        text = path.read_text()
        assert text.startswith("calib_time: ") and "Tr_velo_to_cam" in text
        assert [line.split(":")[0] for line in text.splitlines()] == ["calib_time", "R", "T"]
        Tr = read_kitti_velo_to_cam(path)
        # KITTI's own arithmetic: P_rect_02 @ R_rect_00 @ Tr is the projection of T_cam_lidar.
        c2c = read_kitti_calib(raw_date / "calib_cam_to_cam.txt")
        R0 = np.eye(4)
        R0[:3, :3] = c2c["R_rect_00"].reshape(3, 3)
        P = c2c["P_rect_02"].reshape(3, 4) @ R0 @ Tr
        np.testing.assert_allclose(P, raw_frames[0].camera.K @ T_est[:3], rtol=1e-12, atol=1e-9)
        # And paretocal's KITTI loader reads the file back as the same extrinsic.
        drive = kitti_copy(raw_date, tmp_path / "copy" / raw_date.name, text)
        np.testing.assert_allclose(detect_source(drive).frames[0].T_ref, T_est, atol=1e-9)
        assert not np.allclose(Tr, T_est, atol=1e-3)       # it is not T_cam_lidar itself

    def test_exporting_the_reference_reproduces_kittis_own_file(self, tmp_path, raw_date,
                                                                raw_frames):
        write_exports(tmp_path, raw_frames[0].T_ref, kitti_rect_of(raw_frames))
        ours = read_kitti_velo_to_cam(tmp_path / KITTI_FILE)
        theirs = read_kitti_calib(raw_date / "calib_velo_to_cam.txt")
        np.testing.assert_allclose(ours[:3, :3].ravel(), theirs["R"], atol=2e-6)
        np.testing.assert_allclose(ours[:3, 3], theirs["T"], atol=2e-6)

    def test_generic_source_writes_T_itself_and_says_so(self, tmp_path, raw_frames, T_est):
        root = generic_folder(tmp_path / "rig", raw_frames[:2], write_points_bin)
        frames = load_frames(root)
        assert kitti_rect_of(frames) is None
        write_exports(tmp_path / "out", T_est, kitti_rect_of(frames))
        text = (tmp_path / "out" / KITTI_FILE).read_text()
        assert "T_cam_lidar itself" in text.splitlines()[0]
        np.testing.assert_allclose(read_kitti_velo_to_cam(tmp_path / "out" / KITTI_FILE), T_est,
                                   atol=1e-12)

    def test_kitti_rect_needs_every_frame_to_agree(self, raw_frames):
        a, b = SimpleNamespace(kitti_rect=np.eye(4)), SimpleNamespace(kitti_rect=2 * np.eye(4))
        assert kitti_rect_of(None) is None and kitti_rect_of([]) is None
        assert kitti_rect_of([a, b]) is None
        assert kitti_rect_of([a, SimpleNamespace(kitti_rect=None)]) is None
        np.testing.assert_array_equal(kitti_rect_of([a, a]), np.eye(4))

    def test_bad_kitti_file(self, tmp_path):
        p = tmp_path / KITTI_FILE
        p.write_text("calib_time: x\nR: 1 0 0 0 1 0 0 0\nT: 0 0 0\n")
        with pytest.raises(InputError, match=err_for(p, "'R' has 8 values")):
            read_kitti_velo_to_cam(p)


class TestTfStatic:
    def test_round_trip_and_direction(self, tmp_path, T_est):
        write_exports(tmp_path, T_est)
        T, parent, child = read_tf_static(tmp_path / TF_FILE)
        assert (parent, child) == ("camera", "lidar")
        np.testing.assert_allclose(T, T_est, atol=1e-12)
        doc = yaml.safe_load((tmp_path / TF_FILE).read_text())
        tf = doc["transforms"][0]["transform"]
        q = [tf["rotation"][k] for k in "xyzw"]
        ref = Rotation.from_matrix(T_est[:3, :3]).as_quat()
        np.testing.assert_allclose(np.abs(np.dot(q, ref)), 1.0, atol=1e-12)   # same up to sign
        assert q[3] >= 0
        # TF semantics: the transform from parent 'camera' to child 'lidar' carries LiDAR
        # coordinates into camera coordinates, exactly as T_cam_lidar does.
        p_lidar = np.array([12.0, -3.0, 0.5])
        t = [tf["translation"][k] for k in "xyz"]
        np.testing.assert_allclose(Rotation.from_quat(q).apply(p_lidar) + t,
                                   T_est[:3, :3] @ p_lidar + T_est[:3, 3], atol=1e-9)
        assert "T_cam_lidar" in doc["direction"]

    def test_static_transform_publisher_line_gives_the_same_transform(self, tmp_path, T_est):
        write_exports(tmp_path, T_est, parent="cam_front_optical", child="velodyne")
        line = yaml.safe_load((tmp_path / TF_FILE).read_text())["static_transform_publisher"]
        words = shlex.split(line)
        assert words[:4] == ["ros2", "run", "tf2_ros", "static_transform_publisher"]
        args = dict(zip(words[4::2], words[5::2]))
        assert args["--frame-id"] == "cam_front_optical" and args["--child-frame-id"] == "velodyne"
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat([float(args[f"--q{k}"]) for k in "xyzw"]).as_matrix()
        T[:3, 3] = [float(args[f"--{k}"]) for k in "xyz"]
        np.testing.assert_allclose(T, T_est, atol=1e-9)

    @pytest.mark.parametrize("edit, what", [
        (lambda d: d["transforms"][0]["transform"].pop("rotation"), "rotation"),
        (lambda d: d["transforms"][0]["transform"]["rotation"].update(w=3.0), "not a unit"),
        (lambda d: d.pop("transforms"), "missing key 'transforms'"),
    ])
    def test_malformed(self, tmp_path, T_est, edit, what):
        write_exports(tmp_path, T_est)
        doc = yaml.safe_load((tmp_path / TF_FILE).read_text())
        edit(doc)
        (tmp_path / TF_FILE).write_text(yaml.safe_dump(doc))
        with pytest.raises(InputError, match=err_for(tmp_path / TF_FILE, what)):
            read_tf_static(tmp_path / TF_FILE)


class TestInverse:
    def test_inverse_times_T_is_identity(self, tmp_path, T_est):
        write_exports(tmp_path, T_est)
        Ti = read_extrinsic_inverse(tmp_path / INVERSE_FILE)
        np.testing.assert_allclose(Ti @ T_est, np.eye(4), atol=1e-12)
        np.testing.assert_allclose(T_est @ Ti, np.eye(4), atol=1e-12)
        text = (tmp_path / INVERSE_FILE).read_text()
        assert "CAMERA frame into the LIDAR frame" in text
        # As an --init file it is read as what it is: the inverse.
        np.testing.assert_allclose(read_extrinsic(tmp_path / INVERSE_FILE), T_est, atol=1e-12)


class TestInitFormats:
    """--init reads every extrinsic file the tool writes and the usual pose forms."""

    def test_every_file_a_run_writes(self, tmp_path, T_est, raw_frames):
        from paretocal.io.exports import kitti_rect_of

        write_exports(tmp_path / "other", T_est)                       # a non-KITTI source
        write_exports(tmp_path / "kitti", T_est, kitti_rect_of(raw_frames))
        write_extrinsic(tmp_path / "extrinsic.yaml", T_est)
        for name in (INVERSE_FILE, TF_FILE, KITTI_FILE):
            np.testing.assert_allclose(read_extrinsic(tmp_path / "other" / name), T_est,
                                       atol=1e-9)
        np.testing.assert_allclose(read_extrinsic(tmp_path / "kitti" / KITTI_FILE,
                                                  kitti_rect_of(raw_frames)), T_est, atol=1e-9)
        with pytest.raises(InputError, match="only a KITTI source's rectification"):
            read_extrinsic(tmp_path / "kitti" / KITTI_FILE)
        np.testing.assert_allclose(read_extrinsic(tmp_path / "extrinsic.yaml"), T_est, atol=1e-9)

    def test_kittis_own_file_as_a_start(self, tmp_path, raw_date, raw_frames):
        """The library reads an --init file as the command line does: KITTI's own
        calib_velo_to_cam.txt through the source's rectification; refused, naming the file,
        for a source that is not KITTI."""
        from paretocal import read_init

        T = read_init(raw_date / "calib_velo_to_cam.txt", raw_date, 2)
        np.testing.assert_allclose(T, raw_frames[0].T_ref, atol=1e-7)
        # From the loaded frames (as paretocal batch reads a manifest entry's init).
        T = read_init(raw_date / "calib_velo_to_cam.txt", raw_frames)
        np.testing.assert_allclose(T, raw_frames[0].T_ref, atol=1e-7)
        other = tmp_path / "other"
        other.mkdir()
        with pytest.raises(InputError, match="calib_velo_to_cam.txt: holds KITTI's Tr_velo"):
            read_init(raw_date / "calib_velo_to_cam.txt", SimpleNamespace(frames=[], root=other))

    def test_translation_and_quaternion(self, tmp_path, T_est):
        from scipy.spatial.transform import Rotation

        x, y, z, w = Rotation.from_matrix(T_est[:3, :3]).as_quat()
        t = [float(v) for v in T_est[:3, 3]]
        forms = {
            "xyzw": {"T_cam_lidar": {"translation": t, "quaternion_xyzw": [x, y, z, w]}},
            "wxyz": {"T_cam_lidar": {"translation": t, "quaternion_wxyz": [w, x, y, z]}},
            "map": {"T_cam_lidar": {"translation": dict(zip("xyz", t)),
                                    "rotation": {"x": x, "y": y, "z": z, "w": w}}},
        }
        for name, doc in forms.items():
            (tmp_path / f"{name}.json").write_text(json.dumps(doc, default=float))
            np.testing.assert_allclose(read_extrinsic(tmp_path / f"{name}.json"), T_est,
                                       atol=1e-9)
        inv = np.linalg.inv(T_est)
        xi, yi, zi, wi = Rotation.from_matrix(inv[:3, :3]).as_quat()
        (tmp_path / "inv.json").write_text(json.dumps({"T_lidar_cam": {
            "translation": [float(v) for v in inv[:3, 3]],
            "quaternion_xyzw": [xi, yi, zi, wi]}}, default=float))
        np.testing.assert_allclose(read_extrinsic(tmp_path / "inv.json"), T_est, atol=1e-9)

    @pytest.mark.parametrize("doc, words", [
        ({"T_cam_lidar": {"translation": [0, 0, 0], "quaternion": [0, 0, 0, 1]}},
         "ambiguous"),
        ({"T_cam_lidar": {"translation": [0, 0, 0]}}, "needs a rotation"),
        ({"T_cam_lidar": {"translation": [0, 0], "quaternion_xyzw": [0, 0, 0, 1]}},
         "translation must be 3 finite numbers"),
        ({"T_cam_lidar": {"translation": [0, 0, 0], "quaternion_xyzw": [0, 0, 0, 2]}},
         "not a unit quaternion"),
        ({"pose": 1, "frame": "x"}, "no extrinsic found (keys: pose, frame)"),
        ({"transforms": [{"header": {"frame_id": "base"}, "child_frame_id": "imu",
                          "transform": {"translation": {"x": 0, "y": 0, "z": 0},
                                        "rotation": {"x": 0, "y": 0, "z": 0, "w": 1}}}]},
         "no transform between a camera and a LiDAR frame (found base -> imu)"),
    ])
    def test_errors_name_the_keys(self, tmp_path, doc, words):
        (tmp_path / "e.json").write_text(json.dumps(doc))
        with pytest.raises(InputError, match=re.escape(words)):
            read_extrinsic(tmp_path / "e.json")

    def test_tf_in_either_direction(self, tmp_path, T_est):
        from paretocal.io.exports import tf_static_text

        (tmp_path / "a.yaml").write_text(tf_static_text(T_est, "camera_optical", "velodyne"))
        (tmp_path / "b.yaml").write_text(tf_static_text(np.linalg.inv(T_est), "os_sensor",
                                                        "cam0"))
        for name in ("a.yaml", "b.yaml"):
            np.testing.assert_allclose(read_extrinsic(tmp_path / name), T_est, atol=1e-9)


class TestWriteRun:
    def _result(self, T):
        from paretocal.decide import Decision

        front = SimpleNamespace(X=np.array([[0.0] * 6 + [500.0]]), F=np.array([[1.0, 0.5]]),
                                columns={"t_norm": [0.1], "m_norm": [0.2], "ms": [3.0],
                                         "bytes": [1000.0]})
        return SimpleNamespace(T_cam_lidar=T, front=front, chosen=0, n_points=500,
                               decision=Decision(rule="knee", deviation_px=0.0),
                               to_dict=lambda: {"T_cam_lidar": T.tolist(), "version": "0.test"})

    def test_every_run_directory_gets_the_exports(self, tmp_path, raw_frames, T_est):
        out = tmp_path / "run"
        written = write_outputs(self._result(T_est), out, raw_frames[:2], figures=False)
        for name in (KITTI_FILE, TF_FILE, INVERSE_FILE):
            assert out / name in written and (out / name).stat().st_size > 0
        assert "paretocal 0.test" in (out / KITTI_FILE).read_text()
        np.testing.assert_allclose(raw_frames[0].kitti_rect @ read_kitti_velo_to_cam(out / KITTI_FILE),
                                   T_est, atol=1e-9)
        np.testing.assert_allclose(read_tf_static(out / TF_FILE)[0], T_est, atol=1e-12)
        assert not list(out.glob(".*tmp*"))

    def test_without_frames_the_kitti_file_holds_T(self, tmp_path, T_est):
        write_outputs(self._result(T_est), tmp_path, None, figures=False)
        np.testing.assert_allclose(read_kitti_velo_to_cam(tmp_path / KITTI_FILE), T_est,
                                   atol=1e-12)


def test_the_kitti_credit_only_on_kitti_frames(tmp_path, raw_frames):
    from paretocal.report.figures import KITTI_CREDIT, data_credit

    own = load_frames(generic_folder(tmp_path / "rig", raw_frames[:1], write_points_bin))[0]
    assert data_credit(raw_frames[0]) == KITTI_CREDIT and data_credit(own) == ""
    said = load_frames(generic_folder(tmp_path / "said", raw_frames[:1], write_points_bin,
                                      extra={"credit": "data: our fleet, 2026"}))[0]
    assert data_credit(said) == "data: our fleet, 2026"
    with pytest.raises(InputError, match="credit must be a line of text"):
        detect_source(generic_folder(tmp_path / "bad", raw_frames[:1], write_points_bin,
                                     extra={"credit": ["x"]}))


def test_the_docs_calib_examples_load(tmp_path, raw_frames):
    """Every calib.yaml example of *Preparing your data* (docs/preparing-data.md, section
    "calib.yaml for one camera") loads as a folder."""
    text = (Path(__file__).parents[1] / "docs" / "preparing-data.md").read_text(encoding="utf-8")
    part = text[text.index("### calib.yaml for one camera"):text.index("### Camera models")]
    blocks = re.findall(r"```yaml\n(.*?)```", part, re.S)
    assert len(blocks) == 4
    f = raw_frames[0]
    for k, block in enumerate(blocks):
        doc = yaml.safe_load(block)
        doc.setdefault("T_cam_lidar", f.T_ref.tolist())
        cam = doc["camera"]
        root = tmp_path / f"rig{k}"
        (root / "images").mkdir(parents=True)
        (root / "points").mkdir()
        image = cv2.resize(f.image, (cam["width"], cam["height"]))
        cv2.imwrite(str(root / "images" / f"{f.name}.png"), image)
        if "mask" in cam:
            cv2.imwrite(str(root / cam["mask"]), np.full(image.shape[:2], 255, np.uint8))
        write_points_bin(root / "points", f)
        (root / "calib.yaml").write_text(yaml.safe_dump(doc))
        got = detect_source(root).frames[0]
        assert got.camera.model == {"pinhole": "pinhole", "fisheye": "fisheye",
                                    "mei": "mei"}[cam["model"]]


def test_result_files_are_standard_json():
    """result.json, batch records and rig.json hold no NaN or Infinity token (a one-frame
    run's jackknife has no value): such figures are written null."""
    import json

    from paretocal.report.results import dumps

    doc = {"a": float("nan"), "b": np.float32(np.inf), "c": [np.nan, 1.5],
           "d": np.array([1.0, np.nan]), "e": (np.int64(3), "x"), "f": {"g": -np.inf}}

    def refuse(token):
        raise ValueError(token)

    back = json.loads(dumps(doc), parse_constant=refuse)
    assert back == {"a": None, "b": None, "c": [None, 1.5], "d": [1.0, None], "e": [3, "x"],
                    "f": {"g": None}}
