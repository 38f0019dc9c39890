import numpy as np
import pytest

from paretocal.camera import project
from paretocal.io.layouts import detect_source
from paretocal.io.readers import read_kitti_calib


def _kitti_uv(P, R_rect, Tr, pts):
    """KITTI's own projection: x ~ P_rect @ R_rect @ Tr_velo_to_cam @ X."""
    R4 = np.eye(4)
    R4[:3, :3] = R_rect
    X = np.column_stack([pts[:, :3], np.ones(len(pts))]).T
    x = P @ R4 @ Tr @ X
    return (x[:2] / x[2]).T, x[2]


class TestKittiProjection:
    @pytest.mark.parametrize("cam", [0, 1, 2, 3])
    def test_raw_matches_kitti_formula(self, raw_date, raw_frames, cam):
        c2c = read_kitti_calib(raw_date / "calib_cam_to_cam.txt")
        v2c = read_kitti_calib(raw_date / "calib_velo_to_cam.txt")
        P = c2c[f"P_rect_0{cam}"].reshape(3, 4)
        Tr = np.eye(4)
        Tr[:3, :3] = v2c["R"].reshape(3, 3)
        Tr[:3, 3] = v2c["T"]
        # The loader's camera and extrinsic for camera `cam` (images of camera 2 stand in: only
        # the geometry is compared).
        from paretocal.io.layouts import _camera_from_P, _rect4

        camera, B = _camera_from_P(P, 1242, 375)
        T = B @ _rect4(c2c["R_rect_00"].reshape(3, 3)) @ Tr
        pts = raw_frames[0].points
        uv, z, vis = project(pts, camera, T)
        uv_k, w = _kitti_uv(P, c2c["R_rect_00"].reshape(3, 3), Tr, pts)
        front = w > 1.0
        np.testing.assert_allclose(uv[front], uv_k[front], atol=1e-6)
        assert vis.sum() > 10_000

    def test_raw_loader_extrinsic(self, raw_date, raw_frames):
        c2c = read_kitti_calib(raw_date / "calib_cam_to_cam.txt")
        v2c = read_kitti_calib(raw_date / "calib_velo_to_cam.txt")
        Tr = np.eye(4)
        Tr[:3, :3] = v2c["R"].reshape(3, 3)
        Tr[:3, 3] = v2c["T"]
        f = raw_frames[0]
        uv, z, vis = project(f.points, f.camera, f.T_ref)
        uv_k, w = _kitti_uv(c2c["P_rect_02"].reshape(3, 4), c2c["R_rect_00"].reshape(3, 3), Tr,
                            f.points)
        np.testing.assert_allclose(uv[vis], uv_k[vis], atol=1e-4)
        # About 16k of a sweep's points land in the colour image (data/README.md).
        assert 14_000 < vis.sum() < 20_000

    def test_object_matches_kitti_formula(self, object_dir):
        from paretocal.io import load_frames

        f = load_frames(object_dir)[0]
        c = read_kitti_calib(object_dir / "calib" / "000001.txt")
        Tr = np.vstack([c["Tr_velo_to_cam"].reshape(3, 4), [0, 0, 0, 1]])
        uv, z, vis = project(f.points, f.camera, f.T_ref)
        uv_k, w = _kitti_uv(c["P2"].reshape(3, 4), c["R0_rect"].reshape(3, 3), Tr, f.points)
        np.testing.assert_allclose(uv[vis], uv_k[vis], atol=1e-4)

    def test_visibility_rules(self):
        from paretocal.camera import Camera

        cam = Camera(K=np.array([[100.0, 0, 4.5], [0, 100, 4.5], [0, 0, 1]]), width=10, height=10)
        pts = np.array([[0, 0, 1.0], [0, 0, 0.05], [0, 0, -1.0], [1.0, 0, 1.0],
                        [-0.045, -0.045, 1.0]])
        uv, z, vis = project(pts, cam, np.eye(4))
        # In front and inside; too close; behind; outside; exactly the top-left pixel centre.
        assert vis.tolist() == [True, False, False, False, True]
        np.testing.assert_allclose(uv[4], [0.0, 0.0], atol=1e-12)


def test_source_detection_on_object_parent(data):
    assert detect_source(data / "kitti_object").layout == "kitti_object"
