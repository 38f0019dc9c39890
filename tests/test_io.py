import json

import cv2
import numpy as np
import pytest

from paretocal.camera import project
from paretocal.errors import InputError, SettingsError
from paretocal.io import detect_source, load_frames, read_extrinsic, select_frames, write_extrinsic
from paretocal.io.images import read_image
from paretocal.io.clouds import read_points

from .helpers import write_generic


class TestKittiRaw:
    def test_loads_all_sample_frames(self, raw_frames):
        assert len(raw_frames) == 20
        f = raw_frames[0]
        assert f.image.shape == (375, 1242, 3) and f.image.dtype == np.uint8
        assert f.points.dtype == np.float32 and f.points.shape[1] == 4
        assert 100_000 < len(f.points) < 130_000
        assert f.T_ref is not None and f.camera.width == 1242

    def test_drive_and_date_folders_agree(self, raw_date):
        a = detect_source(raw_date)
        b = detect_source(raw_date / "2011_09_26_drive_sample_sync")
        assert a.layout == b.layout == "kitti_raw"
        assert [f.name for f in a.frames] == [f.name for f in b.frames]

    def test_camera_without_images_fails_clearly(self, raw_date):
        # Only image_02 is in the sample: other cameras have calibration but no images.
        with pytest.raises(InputError, match="image_00"):
            detect_source(raw_date, camera_index=0)

    def test_bad_camera_index(self, raw_date):
        with pytest.raises(SettingsError, match="--camera"):
            detect_source(raw_date, camera_index=7)


class TestKittiObject:
    def test_loads(self, object_dir, data):
        for src in (object_dir, data / "kitti_object"):
            fr = load_frames(src)
            assert [f.name for f in fr] == ["000001"]
            assert fr[0].points.shape == (120268, 4)
            assert fr[0].image.shape[:2] == (375, 1242)


class TestGenericFolder:
    @pytest.mark.parametrize("suffix", [".bin", ".npy"])
    def test_round_trip_from_kitti(self, tmp_path, raw_frames, suffix):
        root = write_generic(tmp_path / "rig", raw_frames[:3], suffix)
        fr = load_frames(root)
        assert [f.name for f in fr] == [f.name for f in raw_frames[:3]]
        np.testing.assert_array_equal(fr[1].points, raw_frames[1].points)
        np.testing.assert_allclose(fr[0].T_ref, raw_frames[0].T_ref, atol=1e-9)

    def test_npy_without_intensity(self, tmp_path, raw_frames):
        root = write_generic(tmp_path / "rig", raw_frames[:1], ".npy")
        p = root / "points" / f"{raw_frames[0].name}.npy"
        np.save(p, raw_frames[0].points[:, :3])
        fr = load_frames(root)
        assert fr[0].points.shape[1] == 4 and not fr[0].points[:, 3].any()

    def test_distortion_is_kept_in_the_camera_not_undone_in_the_image(self, tmp_path,
                                                                      raw_frames):
        D = [-0.3, 0.1, 0.001, 0.0005, 0.0]
        root = write_generic(tmp_path / "rig", raw_frames[:1], D=D)
        fr = load_frames(root)
        np.testing.assert_array_equal(fr[0].image, raw_frames[0].image)   # as stored
        cam = fr[0].camera
        assert cam.model == "pinhole" and cam.D == tuple(D) and not cam.ideal
        np.testing.assert_array_equal(cam.K, raw_frames[0].camera.K)
        # Projection goes through the lens model: OpenCV's projectPoints.
        p = raw_frames[0].points[:5000, :3].astype(np.float64)
        uv, _, vis = project(p, cam, fr[0].T_ref)
        T = fr[0].T_ref
        expect, _ = cv2.projectPoints(p[vis], cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], cam.K,
                                      np.array(D))
        assert vis.sum() > 500
        np.testing.assert_allclose(uv[vis], expect[:, 0], atol=1e-6)

    def test_image_size_mismatch(self, tmp_path, raw_frames):
        root = write_generic(tmp_path / "rig", raw_frames[:1])
        img = root / "images" / f"{raw_frames[0].name}.png"
        cv2.imwrite(str(img), raw_frames[0].image[:100])
        with pytest.raises(InputError, match=r"1242x100 but the calibration says 1242x375"):
            load_frames(root)

    def test_frames_that_do_not_pair(self, tmp_path, raw_frames):
        root = write_generic(tmp_path / "rig", raw_frames[:1])
        (root / "points" / f"{raw_frames[0].name}.bin").rename(root / "points" / "other.bin")
        with pytest.raises(InputError, match="share no file stem"):
            load_frames(root)

    @pytest.mark.parametrize("edit, what", [
        (lambda c: c.pop("camera"), "missing 'camera'"),
        (lambda c: c["camera"].pop("K"), "missing camera.K"),
        (lambda c: c["camera"].update(K=[[1, 0], [0, 1]]), "3x3"),
        (lambda c: c.update(T_cam_lidar=[[1, 0, 0, 0]] * 3 + [[0, 0, 0, 1]]), "not a rotation"),
        # A typo is named as an unknown key with the keys allowed, not as a missing one.
        (lambda c: c["camera"].update(widht=c["camera"].pop("width")),
         r"calib.yaml: camera: unknown key\(s\) widht \(expected K, width, height, model, D, "
         r"xi, mask\)$"),
        (lambda c: c.update(T_cam_lidr=c.pop("T_cam_lidar")),
         r"calib.yaml: unknown key\(s\) T_cam_lidr \(expected camera, camera_info, "
         r"T_cam_lidar, lidar_pose, points, mask, init_error, credit, board\)$"),
    ])
    def test_malformed_calib(self, tmp_path, raw_frames, edit, what):
        import yaml

        root = write_generic(tmp_path / "rig", raw_frames[:1])
        calib = yaml.safe_load((root / "calib.yaml").read_text())
        edit(calib)
        (root / "calib.yaml").write_text(yaml.safe_dump(calib))
        with pytest.raises(InputError, match=what):
            load_frames(root)


class TestImages:
    @pytest.mark.parametrize("hot", [True, False])
    def test_16_bit_image_with_a_hot_pixel_keeps_its_edges(self, tmp_path, raw_frames, hot):
        """A KITTI frame as a 12-bit camera stores it in a 16-bit PNG (values 0..4080), with
        one hot pixel at 65535: the scale follows the image, not that pixel."""
        from paretocal.features.image import edge_map
        from paretocal.stage import MIN_EDGE_PIXELS

        grey = cv2.cvtColor(raw_frames[0].image, cv2.COLOR_BGR2GRAY)
        deep = grey.astype(np.uint16) * 16
        if hot:
            deep[100, 600] = 65535
        path = tmp_path / "deep.png"
        cv2.imwrite(str(path), deep)
        img = read_image(path)
        assert img.dtype == np.uint8 and img.shape == (*grey.shape, 3)
        # The frame's own range maps onto 0..255 (as the 8-bit original has it), not 0..16.
        assert np.percentile(img, 99) > 0.8 * np.percentile(grey, 99)
        edges = int(np.count_nonzero(edge_map(img)))
        expect = int(np.count_nonzero(edge_map(grey)))
        assert edges > max(MIN_EDGE_PIXELS, expect // 2), (edges, expect)

    def test_flat_16_bit_image_is_black_not_an_error(self, tmp_path):
        path = tmp_path / "flat.png"
        cv2.imwrite(str(path), np.full((20, 30), 1000, np.uint16))
        assert not read_image(path).any()


class TestPoints:
    def test_truncated_bin(self, tmp_path):
        p = tmp_path / "x.bin"
        p.write_bytes(b"\0" * 33)
        with pytest.raises(InputError, match="not a multiple of 16"):
            read_points(p)

    def test_empty(self, tmp_path):
        p = tmp_path / "x.bin"
        p.write_bytes(b"")
        with pytest.raises(InputError, match="empty"):
            read_points(p)

    def test_nan_points_dropped_with_count(self, tmp_path, caplog):
        pts = np.ones((10, 4), np.float32)
        pts[3, 1] = np.nan
        pts[5, 0] = np.inf
        p = tmp_path / "x.bin"
        pts.tofile(p)
        assert len(read_points(p)) == 8
        assert "dropped 2 points" in caplog.text


class TestSelectFrames:
    names = [f"{i:010d}" for i in range(20)]

    @pytest.mark.parametrize("spec, expect", [
        (None, list(range(20))), ("0:3", [0, 1, 2]), ("0,3,7", [0, 3, 7]),
        ("0000000005", [5]), ("-1", [19]), ("18:", [18, 19]), ("2,0:2", [2, 0, 1]),
    ])
    def test_specs(self, spec, expect):
        assert select_frames(self.names, spec) == expect

    @pytest.mark.parametrize("spec", ["40", "abc", "30:40", "0:50", "-21:"])
    def test_bad(self, spec):
        with pytest.raises(SettingsError, match="--frames"):
            select_frames(self.names, spec)


class TestExtrinsicFiles:
    def test_yaml_and_json_round_trip(self, tmp_path, raw_frames):
        T = raw_frames[0].T_ref
        write_extrinsic(tmp_path / "e.yaml", T)
        np.testing.assert_allclose(read_extrinsic(tmp_path / "e.yaml"), T, atol=1e-9)
        (tmp_path / "e.json").write_text(json.dumps({"T_cam_lidar": T.tolist()}))
        np.testing.assert_allclose(read_extrinsic(tmp_path / "e.json"), T, atol=1e-12)

    def test_missing_key(self, tmp_path):
        (tmp_path / "e.yaml").write_text("foo: 1\n")
        with pytest.raises(InputError, match=r"no extrinsic found \(keys: foo\)"):
            read_extrinsic(tmp_path / "e.yaml")
