import math

import cv2
import numpy as np
import pytest

from paretocal.camera import MEI, N_PARAMS, Camera, in_image, project
from paretocal.io.layouts import detect_source
from paretocal.io.text import read_kitti_calib


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


# --- lens models ---------------------------------------------------------------------------------

#: The aiMotive sample's cameras (data/aimotive/*/calib.yaml).
AIM_PIN_K = np.array([[1170.7994384765625, 0.0, 640.0], [0.0, 1001.1844482421875, 352.0],
                      [0.0, 0.0, 1.0]])
AIM_PIN_D = [-0.30073606967926025, 0.08419033139944077, 0.002034867648035288,
             0.0006097130244597793, 0.0]
AIM_MEI_K = np.array([[575.2252458162137, 0.0, 641.9449779750069],
                      [0.0, 501.2711423954533, 344.73654890450604], [0.0, 0.0, 1.0]])
AIM_MEI_D = [0.03364013761086061, -0.08420780755924384, 0.0, 0.0, 0.0]
AIM_MEI_XI = 1.0222136193840399


def _mei_by_hand(p, K, D, xi):
    """The unified model written out with the math module, point by point."""
    k1, k2, p1, p2, k3 = D
    out = []
    for X, Y, Z in p:
        n = math.sqrt(X * X + Y * Y + Z * Z)
        xs, ys, zs = X / n, Y / n, Z / n
        mx, my = xs / (zs + xi), ys / (zs + xi)
        r2 = mx * mx + my * my
        c = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
        xd = mx * c + 2 * p1 * mx * my + p2 * (r2 + 2 * mx * mx)
        yd = my * c + p1 * (r2 + 2 * my * my) + 2 * p2 * mx * my
        out.append((K[0][0] * xd + K[0][2], K[1][1] * yd + K[1][2]))
    return np.array(out)


def _mei():
    return Camera(AIM_MEI_K, 1280, 704, "mei", AIM_MEI_D, xi=AIM_MEI_XI)


class TestLensModels:
    def test_mei_matches_the_formulas_by_hand(self):
        cam = _mei()
        # Ahead, to the side, and one behind the image plane that the wide lens still sees.
        p = np.array([[1.0, 0.5, 2.0], [-3.0, 1.0, 1.0], [2.0, -1.0, -0.2], [0.0, 0.0, 7.0],
                      [0.3, -0.2, 40.0]])
        uv, valid = cam.project_camera_points(p)
        assert valid.all()
        np.testing.assert_allclose(uv, _mei_by_hand(p, AIM_MEI_K, AIM_MEI_D, AIM_MEI_XI),
                                   rtol=0, atol=1e-9)
        np.testing.assert_allclose(uv[3], AIM_MEI_K[:2, 2], atol=1e-12)     # the axis

    @pytest.mark.parametrize("D", [AIM_PIN_D, [-0.28, 0.09, 0.0008, -0.0005],
                                   [0.1, 0.01, 0.001, -0.002, 0.0, 0.2, 0.01, 0.001],
                                   [-0.1, 0.02, 0.001, 0.002, -0.001, 0.0, 0.0, 0.0,
                                    0.001, -0.0005, 0.0007, 0.0002]])
    def test_radtan_matches_opencv(self, rng, D):
        cam = Camera(AIM_PIN_K, 1280, 704, "pinhole", D)
        p = np.column_stack([rng.uniform(-0.5, 0.5, 500), rng.uniform(-0.35, 0.35, 500),
                             np.ones(500)]) * rng.uniform(0.5, 80, (500, 1))
        uv, valid = cam.project_camera_points(p)
        expect, _ = cv2.projectPoints(p, np.zeros(3), np.zeros(3), AIM_PIN_K, np.array(D))
        assert valid.all()
        np.testing.assert_allclose(uv, expect[:, 0], rtol=0, atol=1e-8)

    def test_fisheye_matches_opencv(self, rng):
        K = np.array([[300.0, 0, 319.5], [0, 310.0, 239.5], [0, 0, 1]])
        D = [0.08, -0.03, 0.01, -0.002]
        cam = Camera(K, 640, 480, "fisheye", D)
        p = np.column_stack([rng.uniform(-2, 2, 500), rng.uniform(-2, 2, 500),
                             rng.uniform(0.2, 3, 500)])
        uv, valid = cam.project_camera_points(p)
        expect, _ = cv2.fisheye.projectPoints(p[:, None, :], np.zeros(3), np.zeros(3), K,
                                              np.array(D))
        assert valid.all()
        np.testing.assert_allclose(uv, expect[:, 0], rtol=0, atol=1e-8)

    @pytest.mark.parametrize("make", [
        lambda: Camera(AIM_PIN_K, 1280, 704, "pinhole", AIM_PIN_D),
        lambda: Camera(np.array([[400.0, 1.5, 330], [0, 420, 250], [0, 0, 1]]), 640, 480,
                       "pinhole", [0.1, 0.01, 0.001, -0.002, 0.0, 0.2, 0.01, 0.001,
                                   0.001, -0.0005, 0.0007, 0.0002]),
        lambda: Camera(AIM_PIN_K, 1280, 704),
        lambda: Camera(np.array([[300.0, 0, 319.5], [0, 310.0, 239.5], [0, 0, 1]]), 640, 480,
                       "fisheye", [0.08, -0.03, 0.01, -0.002]),
        _mei,
        lambda: Camera(AIM_MEI_K, 1280, 704, "mei", [0.0, 0.0, 0.001, -0.002], xi=0.8),
    ], ids=["radtan", "rational-prism-skew", "ideal", "fisheye", "mei", "mei-xi<1"])
    def test_unproject_inverts_project(self, make, rng):
        cam = make()
        v, u = np.mgrid[0:cam.height:3, 0:cam.width:3].astype(np.float64)
        uv = np.stack([u.ravel(), v.ravel()], axis=1) + rng.uniform(0, 1, (u.size, 2))
        ray = cam.unproject(uv)
        ok = np.isfinite(ray).all(axis=1)
        assert ok.mean() > 0.85
        np.testing.assert_allclose(np.linalg.norm(ray[ok], axis=1), 1.0, atol=1e-12)
        back, valid = cam.project_camera_points(ray[ok] * rng.uniform(0.5, 50, (ok.sum(), 1)))
        assert valid.all()
        assert np.abs(back - uv[ok]).max() < 1e-6
        # And from points: a valid point's pixel unprojects to the point's direction.
        p = rng.normal(size=(2000, 3)) * [1, 1, 0.5] + [0, 0, 1.0]
        uvp, vp = cam.project_camera_points(p)
        keep = vp & in_image(uvp, cam.width, cam.height)
        r = cam.unproject(uvp[keep])
        d = p[keep] / np.linalg.norm(p[keep], axis=1, keepdims=True)
        assert keep.sum() > 100 and np.abs(r - d).max() < 1e-9

    def test_mei_fold_back_is_invalid(self):
        cam = _mei()
        # The distortion turns back where 1 + 3 k1 r^2 + 5 k2 r^4 = 0 (aimotive/README.md:
        # r = 1.29, about 106 degrees off the axis).
        k1, k2 = AIM_MEI_D[:2]
        s = (-3 * k1 - math.sqrt(9 * k1 * k1 - 20 * k2)) / (10 * k2)
        assert cam.r_limit == pytest.approx(math.sqrt(s), rel=1e-12)
        assert cam.r_limit == pytest.approx(1.29, abs=0.005)
        # 115 degrees off the axis, in the horizontal plane: beyond the limit, where the lens
        # formula would put the point back inside the image, among valid pixels.
        a = math.radians(115)
        p = np.array([[math.sin(a), 0.0, math.cos(a)], [math.sin(1.7), 0.0, math.cos(1.7)]])
        folded = _mei_by_hand(p[:1], AIM_MEI_K, AIM_MEI_D, AIM_MEI_XI)[0]
        assert 0 <= folded[0] <= 1279 and 0 <= folded[1] <= 703
        uv, valid = cam.project_camera_points(p)
        assert valid.tolist() == [False, True]          # 1.7 rad = 97 deg is inside the limit
        assert np.isnan(uv[0]).all()
        # No valid pixel is reached twice: the fold-back pixel unprojects to the valid ray.
        ray = cam.unproject(folded[None])[0]
        assert np.isfinite(ray).all() and math.degrees(math.acos(ray[2])) < 106

    @pytest.mark.parametrize("tiny", [5e-324, 1e-300, -1e-300])
    def test_a_vanishing_coefficient_never_folds(self, tiny):
        """A subnormal or tiny highest coefficient puts the fold-back at infinity, with no
        floating-point warning (found by tests/test_fuzz.py)."""
        K = np.array([[700.0, 0, 600], [0, 700.0, 180], [0, 0, 1]])
        assert Camera(K, 1242, 375, "pinhole", (0.0, 0.0, 0.0, 0.0, tiny)).r_limit > 1e40
        assert Camera(K, 1242, 375, "fisheye", (0.0, 0.0, 0.0, tiny)).r_limit > 1.0

    def test_radtan_and_fisheye_fold_back_are_invalid(self):
        K = np.array([[500.0, 0, 500], [0, 500, 500], [0, 0, 1]])
        cam = Camera(K, 1000, 1000, "pinhole", [-0.4, 0.0, 0.0, 0.0])
        assert cam.r_limit == pytest.approx(1 / math.sqrt(1.2), rel=1e-12)   # 1 - 1.2 r^2 = 0
        p = np.array([[1.2, 0.0, 1.0], [0.85, 0.0, 1.0]])
        uv, valid = cam.project_camera_points(p)
        assert valid.tolist() == [False, True]
        assert 0 <= 500 + 500 * 1.2 * (1 - 0.4 * 1.44) <= 999           # where it would fold
        fish = Camera(K, 1000, 1000, "fisheye", [-0.1, 0.0, 0.0, 0.0])
        assert fish.r_limit == pytest.approx(math.sqrt(1 / 0.3), rel=1e-12)
        p = np.array([[math.sin(2.2), 0.0, math.cos(2.2)], [math.sin(1.7), 0.0, math.cos(1.7)]])
        assert fish.project_camera_points(p)[1].tolist() == [False, True]
        # Beyond the limit the image holds nothing the lens can see: those pixels are masked.
        assert not cam.valid_pixels.all() and cam.valid_pixels[500, 500]
        corner = cam.unproject(np.array([[0.0, 0.0], [999.0, 999.0]]))
        assert np.isnan(corner).all()

    def test_valid_pixels_of_the_mei_sample(self):
        cam = _mei()
        vp = cam.valid_pixels
        assert vp.shape == (704, 1280) and 0.8 < vp.mean() < 0.95
        assert vp[345, 642] and not vp[0, 0] and not vp[703, 1279]
        assert Camera(AIM_PIN_K, 1280, 704, "pinhole", AIM_PIN_D).valid_pixels.all()

    def test_kernel_row_and_validation(self):
        cam = _mei()
        row = cam.kernel_params()
        assert row.shape == (N_PARAMS,) and row[0] == MEI and row[6] == AIM_MEI_XI
        assert row[19] == pytest.approx(cam.r_limit ** 2)
        assert Camera(AIM_PIN_K, 1280, 704, "pinhole", [0, 0, 0, 0, 0]).ideal
        with pytest.raises(ValueError, match="xi"):
            Camera(AIM_MEI_K, 1280, 704, "mei", AIM_MEI_D, xi=-1.0)
        with pytest.raises(ValueError, match="tilted"):
            Camera(AIM_PIN_K, 1280, 704, "pinhole", [0.0] * 13 + [0.01])
        with pytest.raises(ValueError, match="model"):
            Camera(AIM_PIN_K, 1280, 704, "omnidir")
        assert {cam: 1}[cam] == 1                                # hashable (by identity)

    def test_project_with_distortion_returns_depth_and_visibility(self):
        cam = Camera(AIM_PIN_K, 1280, 704, "pinhole", AIM_PIN_D)
        pts = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, -5.0], [100.0, 0.0, 1.0]])
        uv, z, vis = project(pts, cam, np.eye(4))
        assert z.tolist() == [5.0, -5.0, 1.0] and vis.tolist() == [True, False, False]
        np.testing.assert_allclose(uv[0], [640.0, 352.0])


@pytest.mark.parametrize("make", [
    lambda: Camera(AIM_PIN_K, 1280, 704, "pinhole", AIM_PIN_D),
    lambda: Camera(np.array([[300.0, 0, 319.5], [0, 310.0, 239.5], [0, 0, 1]]), 640, 480,
                   "fisheye", [0.08, -0.03, 0.01, -0.002]),
    _mei,
], ids=["radtan", "fisheye", "mei"])
def test_project_a_batch_of_extrinsics_equals_one_at_a_time(make, rng):
    """``project`` with (C, 4, 4) extrinsics gives, per candidate, what one extrinsic gives."""
    from paretocal.geometry import decalibrate

    cam = make()
    pts = rng.uniform([-20, -20, -3], [20, 20, 3], size=(500, 3))
    T0 = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])  # x ahead
    Ts = np.stack([decalibrate(T0, 10, 0.5, k)[0] for k in range(4)])
    uv, z, vis = project(pts, cam, Ts)
    assert uv.shape == (4, 500, 2) and z.shape == vis.shape == (4, 500)
    assert vis.any(axis=1).all()
    for c, T in enumerate(Ts):
        uv1, z1, vis1 = project(pts, cam, T)
        np.testing.assert_array_equal(vis[c], vis1)
        np.testing.assert_allclose(z[c], z1, rtol=0, atol=1e-12)
        np.testing.assert_allclose(uv[c], uv1, rtol=0, atol=1e-9)
    uv34, _, _ = project(pts, cam, Ts[:, :3, :])
    np.testing.assert_array_equal(uv34, uv)


def test_a_mounted_camera_projects_through_its_mount(rng):
    """A camera with a mount M projects at ``M @ T`` (one extrinsic and a batch); the mount is
    validated, read-only and written by ``to_dict``."""
    import dataclasses

    from paretocal.errors import InputError
    from paretocal.geometry import decalibrate

    cam = Camera(AIM_PIN_K, 1280, 704, "pinhole", AIM_PIN_D)
    T0 = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
    M = decalibrate(np.eye(4), 30, 0.5, 3)[0]
    mounted = dataclasses.replace(cam, mount=M)
    pts = rng.uniform([-20, -20, -3], [20, 20, 3], size=(300, 3))
    Ts = np.stack([decalibrate(T0, 10, 0.5, k)[0] for k in range(3)])
    uv, z, vis = project(pts, mounted, Ts)
    uv1, z1, vis1 = project(pts, cam, M @ Ts)
    np.testing.assert_array_equal(vis, vis1)
    np.testing.assert_allclose(uv, uv1, rtol=1e-12, atol=1e-9)    # far outside: large u, v
    np.testing.assert_allclose(z, z1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(project(pts, mounted, Ts[:, :3])[0], uv, rtol=1e-12, atol=1e-9)
    assert cam.to_dict().get("mount") is None
    np.testing.assert_allclose(mounted.to_dict()["mount"], M)
    assert not mounted.mount.flags.writeable
    with pytest.raises(InputError, match="mount"):
        Camera(AIM_PIN_K, 1280, 704, mount=np.eye(3))
