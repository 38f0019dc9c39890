"""Per-point fields of point cloud files (:func:`paretocal.io.clouds.read_cloud`): intensity
aliases, ring numbers, per-point time and its unit, ``.npy`` record arrays and the declared
layouts of ``.bin`` files. Test files are written at run time from the KITTI sample or synthetic
arrays by the writers of tests/test_formats.py."""

from __future__ import annotations

import logging
import re
import warnings

import numpy as np
import pytest

from paretocal.errors import InputError
from paretocal.io.clouds import (BIN_LAYOUTS, INTENSITY_FIELDS, RING_FIELDS, TIME_FIELDS, read_cloud,
                                 read_points)

from .test_formats import err_for, pcd_bytes, ply_bytes, xyzi_cols

AIMOTIVE_PCD = "aimotive/points/0033643.pcd"

CONTAINERS = [("pcd", "ascii"), ("pcd", "binary"), ("pcd", "binary_compressed"),
              ("ply", "ascii"), ("ply", "binary_little_endian"), ("ply", "binary_big_endian")]


def write(tmp_path, container, cols, name="cloud"):
    """``cols`` as a .pcd or .ply file of the given encoding; returns the path."""
    suffix, data = container
    p = tmp_path / f"{name}.{suffix}"
    p.write_bytes(pcd_bytes(cols, data) if suffix == "pcd" else ply_bytes(cols, data))
    return p


@pytest.fixture(scope="module")
def sub(raw_frames):
    """500 points of a real KITTI sweep."""
    return np.ascontiguousarray(raw_frames[0].points[::200][:500])


def nuscenes_records(points, n=None):
    """A KITTI sweep as nuScenes records: x, y, z, intensity 0..255, ring (floats)."""
    n = len(points) if n is None else n
    return np.column_stack([points[:n, :3], np.round(points[:n, 3] * 255),
                            np.arange(n) % 32]).astype(np.float32)


# --- field types in every container ----------------------------------------------------------------

# Raw time values per type, each with the span of one sweep in the unit the rule must find.
TIMES = {
    "u1": (lambda n: np.linspace(0, 200, n).astype(np.uint8), "ms"),            # 200 ms
    "u2": (lambda n: np.linspace(0, 60000, n).astype(np.uint16), "us"),         # 60 ms
    "i4": (lambda n: (np.arange(n) * 200_003).astype(np.int32), "ns"),          # ~100 ms
    "f4": (lambda n: (np.arange(n) * 2e-4).astype(np.float32), "s"),            # ~100 ms
    "f8": (lambda n: 4833.12 + np.arange(n) * 2.0001e-4, "s"),                  # epoch seconds
}
DIVISOR = {"s": 1, "ms": 1e3, "us": 1e6, "ns": 1e9}


class TestFieldTypes:
    @pytest.mark.parametrize("container", CONTAINERS, ids="-".join)
    @pytest.mark.parametrize("kind", list(TIMES))
    def test_ring_and_time_read_back_exactly(self, tmp_path, sub, container, kind):
        n = len(sub)
        ring = (np.arange(n) % 64).astype(kind)
        raw_time, unit = TIMES[kind]
        t = raw_time(n)
        p = write(tmp_path, container, xyzi_cols(sub) + [("ring", ring), ("time", t)])
        c = read_cloud(p)
        np.testing.assert_array_equal(c.points, sub)
        assert c.ring.dtype == np.int16 and c.time.dtype == np.float64
        np.testing.assert_array_equal(c.ring, np.arange(n) % 64)
        np.testing.assert_array_equal(c.time, t.astype(np.float64) / DIVISOR[unit])
        assert c.fields["ring"] == "ring" and c.fields["time"] == "time"
        assert c.fields["time_unit"] == unit and c.fields["format"] == container[0]
        assert c.fields["layout"] is None and c.fields["warnings"] == []

    @pytest.mark.parametrize("container", CONTAINERS[:3], ids="-".join)   # PLY has no int64
    def test_64_bit_integer_time_and_signed_ring(self, tmp_path, sub, container):
        n = len(sub)
        t = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 150_000   # epoch ns
        p = write(tmp_path, container, xyzi_cols(sub) + [("ring", (np.arange(n) % 32)
                                                          .astype(np.int8)), ("timestamp", t)])
        c = read_cloud(p)
        assert c.fields["time_unit"] == "ns"
        np.testing.assert_array_equal(c.time, t.astype(np.float64) / 1e9)
        np.testing.assert_array_equal(c.ring, np.arange(n) % 32)

    def test_ring_field_with_count_2_is_refused(self, tmp_path, sub):
        good = pcd_bytes(xyzi_cols(sub) + [("ring", np.zeros(len(sub), np.uint8))])
        bad = good.replace(b"COUNT 1 1 1 1 1", b"COUNT 1 1 1 1 2")
        p = tmp_path / "c.pcd"
        p.write_bytes(bad)
        with pytest.raises(InputError, match=err_for(p, "field 'ring' has COUNT 2, expected 1")):
            read_cloud(p)

    def test_read_points_is_the_clouds_points(self, tmp_path, sub):
        p = write(tmp_path, ("pcd", "binary"), xyzi_cols(sub) + [("ring", np.zeros(len(sub),
                                                                                  np.uint8))])
        np.testing.assert_array_equal(read_points(p), read_cloud(p).points)


# --- field names ----------------------------------------------------------------------------------


class TestFieldNames:
    def test_the_documented_orders(self):
        assert INTENSITY_FIELDS == ("intensity", "reflectivity", "signal", "i", "reflectance")
        assert RING_FIELDS == ("ring", "laser_id", "channel", "line")
        assert TIME_FIELDS == ("time", "t", "timestamp", "offset_time")

    @pytest.mark.parametrize("container", [("pcd", "binary"), ("ply", "ascii")], ids="-".join)
    @pytest.mark.parametrize("alias", ["reflectivity", "signal", "i", "reflectance", "SIGNAL"])
    def test_intensity_aliases_are_picked_and_named(self, tmp_path, sub, container, alias):
        refl = (np.arange(len(sub)) % 250).astype(np.uint16)
        p = write(tmp_path, container, xyzi_cols(sub, None) + [(alias, refl)])
        c = read_cloud(p)
        assert c.fields["intensity"] == alias                 # the file's own spelling
        np.testing.assert_array_equal(c.points[:, 3], refl)
        assert not any("intensity" in w for w in c.fields["warnings"])

    def test_first_alias_in_the_list_wins_not_first_in_the_file(self, tmp_path, sub):
        n = len(sub)
        cols = xyzi_cols(sub, None) + [
            ("signal", np.full(n, 7, np.uint16)), ("reflectivity", np.full(n, 3, np.uint16)),
            ("line", np.full(n, 9, np.uint8)), ("laser_id", np.full(n, 5, np.uint8)),
            ("offset_time", np.zeros(n, np.uint32)), ("t", np.linspace(0, 0.1, n))]
        c = read_cloud(write(tmp_path, ("pcd", "binary"), cols))
        assert (c.fields["intensity"], c.fields["ring"], c.fields["time"]) == \
            ("reflectivity", "laser_id", "t")
        assert (c.points[:, 3] == 3).all() and (c.ring == 5).all()
        np.testing.assert_array_equal(c.time, np.linspace(0, 0.1, n))

    @pytest.mark.parametrize("ring_name, time_name", [("laser_id", "offset_time"),
                                                      ("channel", "timestamp"),
                                                      ("Line", "T")])
    def test_ring_and_time_aliases(self, tmp_path, sub, ring_name, time_name):
        n = len(sub)
        ring = (np.arange(n) % 6).astype(np.uint8)
        t = (np.arange(n) * 200_000).astype(np.uint32)               # ns, 100 ms
        c = read_cloud(write(tmp_path, ("ply", "binary_little_endian"),
                             xyzi_cols(sub) + [(ring_name, ring), (time_name, t)]))
        assert (c.fields["ring"], c.fields["time"]) == (ring_name, time_name)
        np.testing.assert_array_equal(c.ring, ring)
        np.testing.assert_array_equal(c.time, t / 1e9)

    @pytest.mark.parametrize("container", CONTAINERS, ids="-".join)
    def test_no_intensity_reads_zeros_with_a_warning_and_no_log(self, tmp_path, sub, container,
                                                                caplog):
        caplog.set_level(logging.DEBUG)
        c = read_cloud(write(tmp_path, container, xyzi_cols(sub, None)))
        np.testing.assert_array_equal(c.points[:, :3], sub[:, :3])
        assert (c.points[:, 3] == 0).all()
        assert c.fields["intensity"] is None and c.ring is None and c.time is None
        (w,) = c.fields["warnings"]
        assert w.startswith("no intensity field (looked for intensity, reflectivity, signal, i, "
                            "reflectance)") and "intensity edges are off" in w
        assert caplog.records == []                 # the caller says it once per source

    def test_nan_rows_are_dropped_from_ring_and_time_too(self, tmp_path, caplog):
        n = 12
        xyz = np.arange(3 * n, dtype=np.float32).reshape(n, 3) + 0.25
        xyz[2, 0] = np.nan
        xyz[7, 2] = -np.inf
        ring = np.arange(n, dtype=np.float32)
        ring[2] = np.nan                  # ring and time of a dropped point are not checked
        t = np.arange(n) * 0.01
        t[7] = np.inf
        cols = [(c, xyz[:, j].copy()) for j, c in enumerate("xyz")] + [("ring", ring), ("time", t)]
        c = read_cloud(write(tmp_path, ("pcd", "binary"), cols))
        keep = np.ones(n, bool)
        keep[[2, 7]] = False
        np.testing.assert_array_equal(c.points[:, :3], xyz[keep])
        np.testing.assert_array_equal(c.ring, np.arange(n)[keep])
        np.testing.assert_array_equal(c.time, (np.arange(n) * 0.01)[keep])
        assert "dropped 2 points with NaN or infinite coordinates" in caplog.text


# --- time units -------------------------------------------------------------------------------------


class TestTimeUnits:
    def read(self, tmp_path, sub, t, name="time"):
        return read_cloud(write(tmp_path, ("pcd", "binary"), xyzi_cols(sub) + [(name, t)]))

    @pytest.mark.parametrize("t, unit", [
        ((np.arange(500) * 200_000).astype(np.uint32), "ns"),     # Livox/Ouster: 100 ms in ns
        ((np.arange(500) * 200).astype(np.uint32), "us"),         # 100 ms in us
        ((np.arange(500) // 5).astype(np.uint16), "ms"),          # 99 ms in ms
        (np.arange(500) * 2e-4, "s"),                             # float seconds
        (1.6e9 + np.arange(500) * 2e-4, "s"),                     # float epoch seconds
    ])
    def test_the_span_decides_without_a_warning(self, tmp_path, sub, t, unit):
        c = self.read(tmp_path, sub, t)
        assert c.fields["time_unit"] == unit and c.fields["warnings"] == []
        np.testing.assert_array_equal(c.time, t.astype(np.float64) / DIVISOR[unit])
        assert 0.09 <= np.ptp(c.time) <= 0.11

    def test_float_nanoseconds_are_converted_with_a_note(self, tmp_path, sub):
        t = 1.6e18 + np.arange(500) * 2e5                    # float64 epoch ns, 100 ms
        c = self.read(tmp_path, sub, t, "timestamp")
        assert c.fields["time_unit"] == "ns"
        np.testing.assert_array_equal(c.time, t / 1e9)
        (w,) = c.fields["warnings"]
        assert "'timestamp'" in w and "read as nanoseconds" in w

    def test_float_milliseconds(self, tmp_path, sub):
        t = (np.arange(500) * 0.2).astype(np.float32)         # 100 ms in ms
        c = self.read(tmp_path, sub, t)
        assert c.fields["time_unit"] == "ms"
        np.testing.assert_allclose(np.ptp(c.time), 0.0998, rtol=1e-6)

    def test_integer_span_over_a_second_keeps_nanoseconds_and_warns(self, tmp_path, sub):
        t = np.arange(500, dtype=np.int64) * 6_000_000         # 3 s in ns: no unit fits
        c = self.read(tmp_path, sub, t)
        assert c.fields["time_unit"] == "ns"
        np.testing.assert_array_equal(c.time, t / 1e9)
        (w,) = c.fields["warnings"]
        assert "span 2994000000" in w and "a span of 2.994 s" in w and "nanoseconds" in w

    def test_float_span_below_a_millisecond_keeps_seconds_and_warns(self, tmp_path, sub):
        t = 100.0 + np.arange(500) * 1e-7
        c = self.read(tmp_path, sub, t)
        assert c.fields["time_unit"] == "s"
        np.testing.assert_array_equal(c.time, t)                  # the values are kept
        (w,) = c.fields["warnings"]
        assert "no plausible sweep duration" in w and "read as seconds" in w

    @pytest.mark.parametrize("dtype, unit", [(np.uint32, "nanoseconds"), (np.float64, "seconds")])
    def test_one_time_for_every_point(self, tmp_path, sub, dtype, unit):
        c = self.read(tmp_path, sub, np.full(500, 7, dtype))
        (w,) = c.fields["warnings"]
        assert "every point has the same time" in w and f"read as {unit}" in w

    def test_nan_time_of_a_kept_point_is_an_error(self, tmp_path, sub):
        t = np.arange(500) * 2e-4
        t[10] = np.nan
        p = write(tmp_path, ("ply", "ascii"), xyzi_cols(sub) + [("time", t)])
        with pytest.raises(InputError, match=err_for(p, "field 'time' holds NaN or infinite "
                                                        "times at 1 of 500 points")):
            read_cloud(p)

    def test_aimotive_timestamps_in_seconds_come_out_unchanged(self, data):
        path = data / AIMOTIVE_PCD
        c = read_cloud(path)
        assert len(c.points) == 129715 and len(c.time) == 129715
        assert c.fields == {"intensity": "intensity", "ring": None, "time": "timestamp",
                            "time_unit": "s", "format": "pcd", "layout": None, "warnings": []}
        assert 0.09 <= np.ptp(c.time) <= 0.11
        # The file's own float64 column, read independently of the reader.
        raw = path.read_bytes()
        start = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
        rec = np.frombuffer(raw, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                        ("intensity", "<f4"), ("timestamp", "<f8")],
                            offset=start, count=129715)
        np.testing.assert_array_equal(c.time, rec["timestamp"])
        np.testing.assert_array_equal(c.points[:, 3], rec["intensity"])


# --- ring numbers -----------------------------------------------------------------------------------


class TestRing:
    def test_out_of_range_names_file_field_and_extremes(self, tmp_path, sub):
        ring = (np.arange(len(sub)) % 64).astype(np.int32)
        ring[3], ring[9] = -3, 70000
        p = write(tmp_path, ("pcd", "ascii"), xyzi_cols(sub) + [("ring", ring)], "x")
        with pytest.raises(InputError, match="^" + re.escape(
                f"{p}: field 'ring' holds values outside 0..255 (min -3, max 70000)") + "$"):
            read_cloud(p)

    @pytest.mark.parametrize("value, what", [(256, "outside 0..255 (min 0, max 256)"),
                                             (2.5, "not whole numbers (e.g. 2.5)"),
                                             (np.nan, "NaN or infinite values at 1 of 500 points")])
    def test_bad_values(self, tmp_path, sub, value, what):
        ring = (np.arange(len(sub)) % 64).astype(np.float64)
        ring[17] = value
        p = write(tmp_path, ("ply", "binary_big_endian"), xyzi_cols(sub) + [("channel", ring)])
        with pytest.raises(InputError, match=err_for(p, f"field 'channel' holds .*{re.escape(what)}")):
            read_cloud(p)

    def test_gaps_are_kept(self, tmp_path, sub):
        ring = (2 * (np.arange(len(sub)) % 20)).astype(np.uint16)      # 0, 2, ..., 38
        c = read_cloud(write(tmp_path, ("pcd", "binary_compressed"),
                             xyzi_cols(sub) + [("ring", ring)]))
        np.testing.assert_array_equal(c.ring, ring)
        assert c.ring.max() == 38 and len(np.unique(c.ring)) == 20


# --- .npy -------------------------------------------------------------------------------------------


class TestNpy:
    def record_array(self, sub, shape=None):
        n = len(sub)
        rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                 ("reflectivity", "<u2"), ("ring", "u1"), ("t", "<u4"),
                                 ("near_ir", "<u2"), ("normal", "<f4", (3,))])
        for j, c in enumerate("xyz"):
            rec[c] = sub[:, j]
        rec["reflectivity"] = np.arange(n) % 300
        rec["ring"] = np.arange(n) % 128
        rec["t"] = np.arange(n) * 100_000                          # ns, 50 ms
        return rec if shape is None else rec.reshape(shape)

    @pytest.mark.parametrize("shape", [None, (20, 25)])             # organised: rows of a scan
    def test_record_array(self, tmp_path, sub, shape):
        p = tmp_path / "a.npy"
        rec = self.record_array(sub, shape)
        np.save(p, rec)
        c = read_cloud(p)
        np.testing.assert_array_equal(c.points[:, :3], sub[:, :3])
        np.testing.assert_array_equal(c.points[:, 3], rec["reflectivity"].ravel())
        np.testing.assert_array_equal(c.ring, np.arange(len(sub)) % 128)
        np.testing.assert_array_equal(c.time, np.arange(len(sub)) * 100_000 / 1e9)
        assert c.fields == {"intensity": "reflectivity", "ring": "ring", "time": "t",
                            "time_unit": "ns", "format": "npy", "layout": None, "warnings": []}

    def test_a_version_3_file_is_read(self, tmp_path, sub):
        """numpy writes format 3.0 when a field name is not Latin-1; its header is read too."""
        rec = np.zeros(len(sub), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("强度", "<f4")])
        for j, c in enumerate("xyz"):
            rec[c] = sub[:, j]
        p = tmp_path / "a.npy"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)        # "can only be read by >= 1.17"
            np.save(p, rec)
        assert p.read_bytes()[6:8] == b"\x03\x00"
        np.testing.assert_array_equal(read_cloud(p).points[:, :3], sub[:, :3])
        data = bytearray(p.read_bytes())
        data[6] = 7
        p.write_bytes(bytes(data))
        with pytest.raises(InputError, match=err_for(p, r"\.npy format version 7\.0 is not")):
            read_cloud(p)
        data[6] = 3
        data[12:20] = b"{'nope':"
        p.write_bytes(bytes(data))
        with pytest.raises(InputError, match=err_for(p, "unreadable .npy header")):
            read_cloud(p)

    def test_record_array_with_a_vector_ring_is_refused(self, tmp_path, sub):
        rec = np.zeros(10, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("ring", "u1", (2,))])
        p = tmp_path / "a.npy"
        np.save(p, rec)
        with pytest.raises(InputError, match=err_for(p, "field 'ring' has type .*one real number")):
            read_cloud(p)

    def test_record_array_without_z(self, tmp_path):
        p = tmp_path / "a.npy"
        np.save(p, np.zeros(4, dtype=[("x", "f4"), ("y", "f4"), ("h", "f4")]))
        with pytest.raises(InputError, match=err_for(p, r"no 'z' field \(fields: x, y, h\)")):
            read_cloud(p)

    def test_plain_arrays(self, tmp_path, sub):
        p = tmp_path / "a.npy"
        np.save(p, sub.astype(np.float64))
        c = read_cloud(p)
        np.testing.assert_array_equal(c.points, sub)
        assert c.fields["layout"] is None and c.fields["warnings"] == []
        np.save(p, sub[:, :3])
        c = read_cloud(p)
        assert (c.points[:, 3] == 0).all() and "no intensity field" in c.fields["warnings"][0]

    def test_five_columns_need_a_declared_layout(self, tmp_path, sub):
        rec = nuscenes_records(sub)
        p = tmp_path / "a.npy"
        np.save(p, rec)
        with pytest.raises(InputError, match=err_for(p, r"got shape \(500, 5\); a wider array "
                                                        r"needs a declared layout \(nuscenes")):
            read_cloud(p)
        c = read_cloud(p, "nuscenes")
        np.testing.assert_array_equal(c.points, rec[:, :4])
        np.testing.assert_array_equal(c.ring, np.arange(500) % 32)
        assert c.fields["layout"] == "nuscenes"
        with pytest.raises(InputError, match=err_for(p, "layout 'xyzirt' has 6 columns")):
            read_cloud(p, "xyzirt")


# --- .bin layouts -----------------------------------------------------------------------------------


class TestBinLayouts:
    def test_the_table(self):
        assert BIN_LAYOUTS["kitti"].record_bytes == 16
        assert [n for n, _ in BIN_LAYOUTS["nuscenes"].columns] == ["x", "y", "z", "intensity",
                                                                   "ring"]
        assert BIN_LAYOUTS["nuscenes"].record_bytes == 20
        for name, lay in BIN_LAYOUTS.items():
            assert [n for n, _ in lay.columns][:3] == ["x", "y", "z"], name
            assert lay.dtype.itemsize == lay.record_bytes and lay.note

    def test_nuscenes_file_whose_size_divides_by_16_is_refused(self, tmp_path, raw_frames):
        pts = raw_frames[0].points
        rec = nuscenes_records(pts, len(pts) // 4 * 4)
        p = tmp_path / "n.bin"
        rec.tofile(p)
        assert p.stat().st_size % 16 == 0
        with pytest.raises(InputError, match=err_for(p, "fits layout 'nuscenes' .*declare it "
                                                        r"\(points: \{layout: nuscenes\}")):
            read_cloud(p)
        # The same with a size that does not divide by 16.
        rec[:-1].tofile(p)
        with pytest.raises(InputError, match=err_for(p, "not a multiple of 16.*fits layout "
                                                        "'nuscenes'")):
            read_cloud(p)

    def test_declared_nuscenes_reads_ring_exactly(self, tmp_path, raw_frames):
        pts = raw_frames[0].points
        rec = nuscenes_records(pts)
        rec[5, 0] = np.nan                                   # dropped with its ring
        p = tmp_path / "n.bin"
        rec.tofile(p)
        c = read_cloud(p, "nuscenes")
        keep = np.arange(len(rec)) != 5
        np.testing.assert_array_equal(c.points, rec[keep, :4])
        np.testing.assert_array_equal(c.ring, (np.arange(len(rec)) % 32)[keep])
        assert c.fields["ring"] == "ring" and c.fields["layout"] == "nuscenes"
        assert c.time is None and c.fields["warnings"] == []
        assert read_cloud(p, "NuScenes").fields["layout"] == "nuscenes"

    @pytest.mark.parametrize("keep_every", [20, 24, 120])
    @pytest.mark.parametrize("whole_intensity", [False, True])
    def test_kitti_sweeps_whose_size_fits_other_layouts_still_load(self, tmp_path, raw_frames,
                                                                   keep_every, whole_intensity):
        # The negative control of the layout check: real KITTI sweeps (also with intensities
        # stored as whole numbers 0..255) cut to sizes that nuscenes, xyzit and xyzirt fit too.
        for f in raw_frames[:5]:
            pts = f.points[: len(f.points) // keep_every * keep_every].copy()
            if whole_intensity:
                pts[:, 3] = np.round(pts[:, 3] * 255)
            p = tmp_path / f"{f.name}.bin"
            pts.tofile(p)
            c = read_cloud(p)
            np.testing.assert_array_equal(c.points, pts)
            assert c.fields["layout"] == "kitti" and c.fields["warnings"] == []

    def test_whole_number_clouds_prove_nothing_and_load_as_kitti(self, tmp_path):
        # A grid of whole-metre points: read with 5-value records every "ring" is a whole number
        # 0..255 too, but so are the coordinates, so nothing speaks against the default.
        grid = np.indices((10, 8, 4)).reshape(3, -1).T
        pts = np.column_stack([grid, np.arange(len(grid)) % 7]).astype(np.float32)
        p = tmp_path / "grid.bin"
        pts.tofile(p)
        assert p.stat().st_size % 80 == 0 and len(pts) * 4 // 5 >= 64
        np.testing.assert_array_equal(read_cloud(p).points, pts)

    def test_size_that_fits_no_layout(self, tmp_path, raw_frames):
        p = tmp_path / "x.bin"
        p.write_bytes(raw_frames[0].points[:1000].tobytes() + b"\0" * 4)   # 16004 bytes
        with pytest.raises(InputError, match=err_for(p, "size 16004 bytes is not a multiple of 16")) \
                as info:
            read_cloud(p)
        tried = str(info.value).split("tried ")[1]
        for name, lay in BIN_LAYOUTS.items():
            assert f"{name} {lay.record_bytes}" in tried

    def test_size_that_fits_other_layouts_but_data_that_says_nothing(self, tmp_path, rng):
        p = tmp_path / "x.bin"
        rng.normal(size=(105, 5)).astype(np.float32).tofile(p)      # 2100 bytes, not 16 | 2100
        with pytest.raises(InputError, match=err_for(p, "its size fits layouts nuscenes .*xyzit "
                                                        ".*: declare the one it is")):
            read_cloud(p)

    def test_declared_xyzirt_and_xyz(self, tmp_path, sub):
        n = len(sub)
        t = np.arange(n, dtype=np.float32) * np.float32(2e-4)
        rec = np.column_stack([sub, np.arange(n) % 16, t]).astype(np.float32)
        p = tmp_path / "a.bin"
        rec.tofile(p)
        c = read_cloud(p, "xyzirt")
        np.testing.assert_array_equal(c.ring, np.arange(n) % 16)
        np.testing.assert_array_equal(c.time, t.astype(np.float64))
        assert c.fields["time_unit"] == "s" and c.fields["layout"] == "xyzirt"
        sub[:, :3].tofile(p)
        c = read_cloud(p, "xyz")
        np.testing.assert_array_equal(c.points[:, :3], sub[:, :3])
        assert "no intensity field" in c.fields["warnings"][0]

    def test_declared_layout_with_the_wrong_size(self, tmp_path, sub):
        p = tmp_path / "a.bin"
        sub[:7].tofile(p)                                               # 112 bytes
        with pytest.raises(InputError, match=err_for(p, "size 112 bytes is not a multiple of 20 "
                                                        r"\(layout 'nuscenes'")):
            read_cloud(p, "nuscenes")

    @pytest.mark.parametrize("name", ["velodyne", "", 5])
    def test_unknown_layout_name_lists_the_valid_ones(self, tmp_path, sub, name):
        p = tmp_path / "a.bin"
        sub.tofile(p)
        with pytest.raises(InputError, match=err_for(p, "unknown point layout .* \\(known: "
                                                        "kitti, nuscenes, xyzit, xyzirt, xyz\\)")):
            read_cloud(p, name)

    def test_layout_declared_for_a_pcd_is_ignored_with_a_note(self, tmp_path, sub):
        c = read_cloud(write(tmp_path, ("pcd", "binary"), xyzi_cols(sub)), "nuscenes")
        np.testing.assert_array_equal(c.points, sub)
        assert c.fields["layout"] is None
        (w,) = c.fields["warnings"]
        assert "layout 'nuscenes' ignored" in w
