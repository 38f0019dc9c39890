import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paretocal.errors import InputError
from paretocal.geometry import (apply_correction, check_rigid, correction_matrix,
                                correction_params, euler_zyx, invert, pose_error,
                                rotation_angle_deg, rotation_zyx, transform_points)


class TestRotationZYX:
    def test_matches_scipy_intrinsic_zyx(self, rng):
        ypr = rng.uniform(-80, 80, (50, 3))
        R = rotation_zyx(ypr[:, 0], ypr[:, 1], ypr[:, 2])
        ref = Rotation.from_euler("ZYX", ypr, degrees=True).as_matrix()
        np.testing.assert_allclose(R, ref, atol=1e-12)

    def test_round_trip(self, rng):
        ypr = rng.uniform(-85, 85, (100, 3))
        back = euler_zyx(rotation_zyx(*ypr.T))
        np.testing.assert_allclose(back, ypr, atol=1e-9)

    def test_batch_shape(self):
        assert rotation_zyx(np.zeros((4, 5)), 0, 0).shape == (4, 5, 3, 3)


class TestCorrection:
    def test_zero_correction_returns_T_init(self, rng):
        T_init = correction_matrix(np.r_[rng.normal(size=3), rng.uniform(-30, 30, 3)])
        out = apply_correction(T_init, np.zeros(7))
        np.testing.assert_allclose(out, T_init, atol=1e-15)

    def test_applied_in_lidar_frame(self):
        # A pure translation correction moves LiDAR points before T_init is applied.
        T_init = correction_matrix([0.0, 0.0, 0.0, 90.0, 0.0, 0.0])
        T = apply_correction(T_init, [1.0, 0, 0, 0, 0, 0])
        p = transform_points(T, np.zeros((1, 3)))
        np.testing.assert_allclose(p, [[0.0, 1.0, 0.0]], atol=1e-12)

    def test_params_round_trip(self, rng):
        x = np.column_stack([rng.normal(size=(20, 3)), rng.uniform(-60, 60, (20, 3))])
        np.testing.assert_allclose(correction_params(correction_matrix(x)), x, atol=1e-9)

    def test_invert(self, rng):
        T = correction_matrix(np.r_[rng.normal(size=3), rng.uniform(-60, 60, 3)])
        np.testing.assert_allclose(invert(T) @ T, np.eye(4), atol=1e-12)


class TestPoseError:
    def test_known_offsets(self):
        T_ref = correction_matrix([0.1, -0.2, 0.3, 10, 5, -3])
        T = T_ref @ correction_matrix([0, 0, 0, 0, 0, 1.5])
        T[:3, 3] += [0.03, -0.04, 0.0]
        e = pose_error(T, T_ref)
        assert e["rotation_deg"] == pytest.approx(1.5, abs=1e-9)
        assert e["roll_deg"] == pytest.approx(1.5, abs=1e-9)
        assert e["translation_cm"] == pytest.approx(5.0, abs=1e-9)
        assert e["x_cam_cm"] == pytest.approx(3.0) and e["y_cam_cm"] == pytest.approx(-4.0)

    def test_per_axis_errors_in_the_lidar_frame_are_the_correction_from_the_reference(self):
        """x/y/z_lidar_cm and the angles are the correction's own axes: T_est = T_ref @ D(e),
        whatever the reference's rotation (the camera-frame x/y/z differ from them)."""
        T_ref = correction_matrix([0.1, -0.2, 0.3, 80, -20, 95])      # a LiDAR turned away
        e_true = np.r_[0.02, -0.05, 0.01, 0.4, -0.3, 0.2]              # m, deg
        e = pose_error(T_ref @ correction_matrix(e_true), T_ref)
        got = [e["x_lidar_cm"] / 100, e["y_lidar_cm"] / 100, e["z_lidar_cm"] / 100,
               e["yaw_deg"], e["pitch_deg"], e["roll_deg"]]
        np.testing.assert_allclose(got, e_true, atol=1e-9)
        cam = np.r_[e["x_cam_cm"], e["y_cam_cm"], e["z_cam_cm"]]
        assert np.linalg.norm(cam) == pytest.approx(e["translation_cm"])
        assert not np.allclose(cam, 100 * e_true[:3], atol=0.5)
        batch = pose_error(np.stack([T_ref, T_ref @ correction_matrix(e_true)]), T_ref)
        assert batch["x_lidar_cm"].shape == (2,)
        assert batch["x_lidar_cm"][1] == pytest.approx(2.0)

    def test_small_angles_are_accurate(self):
        R = rotation_zyx(1e-6, 0, 0)
        assert rotation_angle_deg(R) == pytest.approx(1e-6, rel=1e-6)


class TestCheckRigid:
    def test_accepts_3x4(self):
        assert check_rigid(np.eye(4)[:3], "x").shape == (4, 4)

    @pytest.mark.parametrize("bad, what", [
        (np.eye(3), "4x4"),
        (np.diag([1.0, 1.0, 2.0, 1.0]), "not a rotation"),
        (np.diag([1.0, 1.0, -1.0, 1.0]), "not a rotation"),
        (np.full((4, 4), np.nan), "NaN"),
        ([["a"]], "numeric"),
    ])
    def test_rejects(self, bad, what):
        with pytest.raises(InputError, match=what):
            check_rigid(bad, "init.yaml")


def test_decalibrate_returns_the_correction_back():
    from paretocal.geometry import correction_matrix, decalibrate

    T_ref = correction_matrix(np.array([0.3, -0.1, 0.2, 10.0, -5.0, 2.0]))
    T0, p = decalibrate(T_ref, 4.0, 0.15, 7)
    np.testing.assert_allclose(T0 @ correction_matrix(p), T_ref, atol=1e-12)
    assert np.all(np.abs(p[:3]) <= 0.15) and np.all(np.abs(p[3:]) <= 4.0)
    T1, q = decalibrate(T_ref, 4.0, 0.15, 7)                  # the same seed, the same start
    np.testing.assert_array_equal(T0, T1)
