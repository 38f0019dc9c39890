"""Ego-motion of both sensors (paretocal.egomotion): synthetic scenes with known motion, and the
real drives (KITTI: camera and LiDAR directions of travel agree; PandaSet: standing frames)."""

from __future__ import annotations

import importlib.util
import math
import os

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paretocal.camera import Camera
from paretocal.egomotion import (
    camera_odometry,
    compare_motion,
    in_camera,
    lidar_odometry,
    pose_from_rays,
    rotation_angle_deg,
)
from paretocal.lidar.registration import register_pair

from .conftest import data_dir
from .test_motion import HEIGHT, _box_hits, _pole_hits, street_scene

HAS_KISS = importlib.util.find_spec("kiss_icp") is not None
if os.environ.get("PARETOCAL_REQUIRE_OPTIONAL") == "1" and not HAS_KISS:
    # CI installs every extra: a missing kiss-icp there is a failure, not a skip.
    pytest.fail("kiss-icp is not installed and PARETOCAL_REQUIRE_OPTIONAL=1", pytrace=False)


def _angle(a, b) -> float:
    return math.degrees(math.acos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def rigid_scan(scene, T_world_sensor, *, noise=0.01, seed=0, n_az=900, max_range=80.0):
    """One sweep of a 32-beam LiDAR standing still at ``T_world_sensor`` (z up), in its frame."""
    rng = np.random.default_rng(seed)
    elev = np.radians(np.linspace(-25.0, 12.0, 32))
    az = np.linspace(0, 2 * np.pi, n_az, endpoint=False)
    A, E = np.meshgrid(az, elev, indexing="ij")
    dirs = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
    R, p = T_world_sensor[:3, :3], T_world_sensor[:3, 3]
    dw = dirs @ R.T
    o = np.broadcast_to(p, dw.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(dw[:, 2] < 0, -p[2] / dw[:, 2], np.inf)
    r = np.minimum(r, _box_hits(o, dw, scene["lo"], scene["hi"]))
    r = np.minimum(r, _pole_hits(o, dw, scene["poles"], scene["pole_r"], scene["pole_h"]))
    keep = r < max_range
    return dirs[keep] * (r[keep] + rng.normal(0, noise, keep.sum()))[:, None]


def pose(yaw_deg=0.0, xyz=(0.0, 0.0, HEIGHT)):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix()
    T[:3, 3] = xyz
    return T


@pytest.fixture(scope="module")
def street():
    return street_scene(np.random.default_rng(3))


# ----------------------------------------------------------------------------- LiDAR, synthetic

def test_register_pair_recovers_a_known_motion(street):
    A, B = pose(0.0, (0, 0, HEIGHT)), pose(2.0, (1.5, 0.2, HEIGHT))
    src, tgt = rigid_scan(street, B, seed=1), rigid_scan(street, A, seed=2)
    reg = register_pair(src, tgt, points=8000)
    truth = np.linalg.inv(A) @ B                   # T_A <- B
    assert np.linalg.norm(reg.T[:3, 3] - truth[:3, 3]) < 0.02
    assert rotation_angle_deg(reg.T[:3, :3].T @ truth[:3, :3]) < 0.05
    # the covariances are positive definite; the sandwich is not smaller than the naive one
    # along the weakest direction
    for C in (reg.covariance, reg.covariance_hessian):
        assert np.all(np.linalg.eigvalsh(0.5 * (C + C.T)) > 0)
    assert reg.blocks > 30
    # evaluating at a given pose does not move it
    ev = register_pair(src, tgt, reg.T, refine=False, points=8000)
    assert np.array_equal(ev.T, reg.T) and ev.iterations == 0


def test_lidar_odometry_chain_and_standstill(street):
    truth = [pose(0.0, (0, 0, HEIGHT)), pose(0.0, (0, 0, HEIGHT)), pose(1.0, (1.2, 0.05, HEIGHT)),
             pose(2.5, (2.5, 0.15, HEIGHT))]
    clouds = [rigid_scan(street, T, seed=10 + k) for k, T in enumerate(truth)]
    lo = lidar_odometry(clouds, method="own", points=8000)
    assert lo.method == "own" and lo.note == ""
    # pair 0 stands (two sweeps from one pose, independent noise): said so in words
    assert lo.standing.tolist() == [True, False, False]
    assert "standing" in lo.reasons[0] and lo.reasons[1] == ""
    assert np.isnan(lo.directions[0]).all()
    for k in range(3):
        rel = np.linalg.inv(truth[k]) @ truth[k + 1]
        assert np.linalg.norm(lo.pair_poses[k, :3, 3] - rel[:3, 3]) < 0.02
    # the chain: sweep 3 in sweep 0's frame, and its direction through relative()
    T03 = np.linalg.inv(truth[0]) @ truth[3]
    assert np.linalg.norm(lo.poses[3, :3, 3] - T03[:3, 3]) < 0.04
    d, why = lo.judge(0, 3)
    assert why == "" and _angle(d, T03[:3, 3]) < 1.0
    _, C = lo.relative(0, 3)
    assert np.all(np.diag(C) >= np.diag(lo.covariance[2]))
    # the direction's uncertainty covers the actual error
    for k in (1, 2):
        rel = np.linalg.inv(truth[k]) @ truth[k + 1]
        err = _angle(lo.pair_poses[k, :3, 3], rel[:3, 3])
        assert err < max(4 * lo.direction_sigma_deg[k], 0.2)


def test_lidar_odometry_rejects_bad_input():
    with pytest.raises(ValueError):
        lidar_odometry([np.zeros((100, 3))])
    with pytest.raises(ValueError):
        lidar_odometry([np.zeros((100, 3))] * 2, method="icp")


@pytest.mark.skipif(not HAS_KISS, reason="kiss-icp is not installed (optional extra 'odometry')")
def test_kiss_icp_poses_on_the_synthetic_street(street):
    truth = [pose(0.5 * k, (0.8 * k, 0.02 * k * k, HEIGHT)) for k in range(5)]
    clouds = [rigid_scan(street, T, seed=20 + k) for k, T in enumerate(truth)]
    lo = lidar_odometry(clouds, method="kiss-icp", voxel=0.5)
    assert lo.method == "kiss-icp"
    for k in range(4):
        rel = np.linalg.inv(truth[k]) @ truth[k + 1]
        assert np.linalg.norm(lo.pair_poses[k, :3, 3] - rel[:3, 3]) < 0.05
        assert rotation_angle_deg(lo.pair_poses[k, :3, :3].T @ rel[:3, :3]) < 0.1
    assert np.isfinite(lo.covariance).all()


def test_missing_kiss_icp_falls_back_with_a_reason(street, monkeypatch, caplog):
    import paretocal.egomotion as eg

    monkeypatch.setattr(eg, "_kiss_available", lambda: "kiss-icp is not installed (test)")
    clouds = [rigid_scan(street, pose(0, (0.5 * k, 0, HEIGHT)), seed=k) for k in range(2)]
    lo = lidar_odometry(clouds, method="kiss-icp", points=5000)
    assert lo.method == "own"
    assert "not installed" in lo.note and "own registration" in lo.note
    assert "not installed" in caplog.text


# ----------------------------------------------------------------------------- camera, synthetic

def _scene_points(rng, n=600):
    """Points 4-40 m ahead of the first camera, spread over a 90-degree view."""
    z = rng.uniform(4, 40, n)
    return np.stack([rng.uniform(-0.9, 0.9, n) * z, rng.uniform(-0.4, 0.5, n) * z, z], 1)


def _rays(camera: Camera, Xc, rng, noise_px):
    uv, ok = camera.project_camera_points(Xc)
    uv = uv + rng.normal(0, noise_px, uv.shape)
    return camera.unproject(uv), ok


CAMERAS = {
    "radtan": Camera(K=np.array([[1170.8, 0, 640], [0, 1001.2, 352], [0, 0, 1]]),
                     D=np.array([-0.3007, 0.0842, 0.00203, 0.00061, 0.0]), width=1280, height=704),
    "mei": Camera(K=np.array([[575.2, 0, 641.9], [0, 501.3, 344.7], [0, 0, 1]]),
                  D=np.array([0.03364, -0.08421, 0, 0, 0]), width=1280, height=704, model="mei",
                  xi=1.02221),
}


@pytest.mark.parametrize("model", sorted(CAMERAS))
def test_visual_odometry_recovers_a_known_motion(model):
    """Exact oracle: the camera moves 1.5 m mostly forward and turns 3 degrees; matches are
    the true projections through the lens model with 0.3 px noise and 10 % outliers."""
    cam = CAMERAS[model]
    rng = np.random.default_rng(5)
    X1 = _scene_points(rng)
    R12 = Rotation.from_euler("yxz", [3.0, 0.5, -0.3], degrees=True).as_matrix()
    c2 = np.array([0.2, -0.05, 1.5])                  # later centre in camera 1
    X2 = (X1 - c2) @ R12                              # R12^T (X - c2)
    r1, ok1 = _rays(cam, X1, rng, 0.3)
    r2, ok2 = _rays(cam, X2, rng, 0.3)
    ok = ok1 & ok2 & np.isfinite(r1).all(1) & np.isfinite(r2).all(1) & (r1[:, 2] > 0.17) & (r2[:, 2] > 0.17)
    r1, r2 = r1[ok], r2[ok]
    bad = rng.random(len(r1)) < 0.1
    r2[bad] = r2[rng.permutation(np.flatnonzero(bad))]
    f = 0.5 * (cam.K[0, 0] + cam.K[1, 1])
    p = pose_from_rays(r1, r2, f, seed=1)
    assert p.ok, p.reason
    err = _angle(p.direction, c2)
    assert err < 2.0                                    # 0.3 px on a 540 px focal length
    assert err < 4 * p.direction_sigma_deg + 0.1        # the bootstrap covers the error
    rerr = rotation_angle_deg(p.R.T @ R12)
    assert rerr < 0.2 and rerr < 4 * p.rotation_sigma_deg + 0.01
    assert p.inliers > 0.7 * (~bad).sum()          # 1 px at the Mei lens's edge is more


def test_pure_rotation_gives_no_direction():
    cam = CAMERAS["radtan"]
    rng = np.random.default_rng(6)
    X1 = _scene_points(rng)
    R12 = Rotation.from_euler("y", 2.0, degrees=True).as_matrix()
    r1, _ = _rays(cam, X1, rng, 0.3)
    r2, _ = _rays(cam, X1 @ R12, rng, 0.3)
    ok = np.isfinite(r1).all(1) & np.isfinite(r2).all(1)
    p = pose_from_rays(r1[ok], r2[ok], 1086.0, seed=1)
    assert not p.ok and np.isnan(p.direction).all()
    assert "too little parallax" in p.reason
    assert p.rotation_ok and rotation_angle_deg(p.R.T @ R12) < 0.05


def test_compare_motion_through_the_extrinsic(street):
    """A LiDAR motion mapped through X is what the camera sees: zero disagreement."""
    truth = [pose(0.0), pose(1.0, (1.5, 0.1, HEIGHT))]
    clouds = [rigid_scan(street, T, seed=30 + k) for k, T in enumerate(truth)]
    lo = lidar_odometry(clouds, method="own", points=8000)
    X = np.array([[0, -1, 0, 0.1], [0, 0, -1, -0.2], [1, 0, 0, -0.3], [0, 0, 0, 1.0]])
    Tc = in_camera(np.linalg.inv(truth[0]) @ truth[1], X)
    from paretocal.egomotion import CameraPair
    cp = CameraPair(i=0, j=1, R=Tc[:3, :3], direction=Tc[:3, 3] / np.linalg.norm(Tc[:3, 3]),
                    matches=100, inliers=100, direction_sigma_deg=0.5, rotation_sigma_deg=0.01,
                    parallax_px=10, noise_px=0.3, ok=True, rotation_ok=True, reason="")
    ag = compare_motion(lo, [cp], X)
    assert ag.direction_deg[0] < 1.0 and ag.rotation_deg[0] < 0.05
    assert ag.summary()["direction_deg"]["n"] == 1


# ----------------------------------------------------------------------------- real data

@pytest.fixture(scope="module")
def kitti():
    root = data_dir() / "kitti_raw" / "2011_09_26"
    if not root.is_dir():
        pytest.skip(f"KITTI raw sample not found at {root}")
    from paretocal.io.layouts import load_frames
    return load_frames(root, "0:11")


@pytest.fixture(scope="module")
def kitti_motion(kitti):
    lo = lidar_odometry([f.points[:, :3] for f in kitti], method="own", points=8000)
    cams = camera_odometry([f.image for f in kitti], kitti[0].camera, pairs=[(0, 10)],
                           bootstrap=20)
    return lo, cams


def test_kitti_directions_of_travel_agree(kitti, kitti_motion):
    """Frames 0 and 10 (2.2 m apart): the camera's direction of travel and the LiDAR's, mapped
    through the reference, agree. benchmarks/egomotion.py measured 0.12-1.23 deg (median 0.68)
    over the ten 10-frame pairs of the drive, with bootstrap spreads of 0.57-1.35 deg; the bound
    is the worst pair plus the largest spread, 2.6 deg. The relative rotations agree within
    0.04-0.24 deg there; bound 0.4 deg."""
    lo, cams = kitti_motion
    assert not lo.standing.any()
    assert cams[0].ok, cams[0].reason
    ag = compare_motion(lo, cams, kitti[0].T_ref)
    assert ag.direction_deg[0] < 2.6
    assert ag.rotation_deg[0] < 0.4


def test_image_features_extracted_beforehand_give_the_same_pairs(kitti, kitti_motion):
    """The wide start extracts the images' features while the LiDAR's odometry runs: given
    to ``camera_odometry``, they give the very pair it finds on its own."""
    from paretocal.egomotion import image_features

    _, (alone,) = kitti_motion
    images = [f.image for f in kitti]
    feats = image_features(images, kitti[0].camera, [0, 10])
    assert set(feats) == {0, 10} and feats[0][0].shape[1] == 3
    (given,) = camera_odometry(images, kitti[0].camera, pairs=[(0, 10)], bootstrap=20,
                               image_feats=feats)
    np.testing.assert_array_equal(given.R, alone.R)
    np.testing.assert_array_equal(given.direction, alone.direction)
    assert (given.inliers, given.direction_sigma_deg) == (alone.inliers,
                                                           alone.direction_sigma_deg)


@pytest.fixture(scope="module")
def pandaset():
    root = data_dir() / "pandaset" / "front"
    if not root.is_dir():
        pytest.skip(f"PandaSet sample not found at {root}")
    from paretocal.io.layouts import load_frames
    return load_frames(root, "0:13")


def test_pandaset_standing_frames_give_no_direction(pandaset):
    """Frames 00-08 (indices 0-4): the car stands in traffic (pandaset/README.md). The LiDAR
    resolves its creep (benchmarks/egomotion.py: 0.3-6.5 cm per 0.2 s pair over frames 00-24,
    sub-millimetre uncertainty), so these pairs are not standing for the LiDAR, but the camera
    resolves no direction in any of them (too little parallax, or a bootstrap spread of 15-43
    deg): no pair gives a direction of travel, and each says why."""
    sel = pandaset[:5]
    lo = lidar_odometry([f.points[:, :3] for f in sel], method="own", points=8000)
    assert np.all(lo.translation_m < 0.1)
    cams = camera_odometry([f.image for f in sel], sel[0].camera, bootstrap=20)
    ag = compare_motion(lo, cams, sel[0].T_ref)
    assert np.isnan(ag.direction_deg).all()
    assert all(ag.reasons) and all(not c.ok and c.reason for c in cams)
    # the rotation is still given (rotation-only fit when there is no parallax)
    assert all(c.rotation_ok for c in cams)
    assert np.nanmax(ag.rotation_deg) < 0.2


def test_standing_lidar_pair_in_words(pandaset):
    """The same sweep twice (independent voxel subsamples): standing, said in words."""
    pts = pandaset[0].points[:, :3]
    lo = lidar_odometry([pts, pts], method="own", points=8000, seed=1)
    assert lo.standing.all() and lo.reasons[0].startswith("standing")


# ----------------------------------------------------------------------------- rotation from motion

def _odometry(pair_poses, sigma_t=0.002, sigma_r=1e-4):
    """LiDAR odometry holding the given pair poses with a small covariance."""
    from paretocal.egomotion import _finish
    cov = np.tile(np.diag([sigma_t ** 2] * 3 + [sigma_r ** 2] * 3), (len(pair_poses), 1, 1))
    return _finish("own", np.array(pair_poses), cov, np.zeros(len(pair_poses)), 1e-3, "")


def _camera_pairs(pair_poses, X, flip=(), dir_sigma=0.3):
    """What the camera sees of those motions through X (exact), some directions reversed."""
    from paretocal.egomotion import CameraPair
    out = []
    for k, T in enumerate(pair_poses):
        Tc = in_camera(T, X)
        d = Tc[:3, 3] / np.linalg.norm(Tc[:3, 3])
        out.append(CameraPair(i=k, j=k + 1, R=Tc[:3, :3], direction=-d if k in flip else d,
                              matches=200, inliers=200, direction_sigma_deg=dir_sigma,
                              rotation_sigma_deg=0.02, parallax_px=20, noise_px=0.3, ok=True,
                              rotation_ok=True, reason=""))
    return out


def _step(yaw_deg, forward=2.0, pitch_deg=0.0):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("zy", [yaw_deg, pitch_deg], degrees=True).as_matrix()
    T[:3, 3] = [forward * math.cos(math.radians(yaw_deg / 2)),
                forward * math.sin(math.radians(yaw_deg / 2)), 0.0]
    return T


X_TRUE = np.array([[0, -1, 0, 0.1], [0, 0, -1, -0.4], [1, 0, 0, -0.8], [0, 0, 0, 1.0]])
X_TRUE[:3, :3] = Rotation.from_euler("xyz", [2.0, -3.0, 1.0], degrees=True).as_matrix() @ \
    X_TRUE[:3, :3]


def _off(R, deg, axis):
    return Rotation.from_rotvec(np.radians(deg) * np.asarray(axis, float)).as_matrix() @ R


def test_a_drive_with_turns_gives_the_whole_rotation():
    """Straight steps and 12 deg turns: the directions and the turn axes pin all three angles,
    from an initial rotation 15 deg off, the lever arm taken off with a translation 10 cm off."""
    from paretocal.egomotion import rotation_from_motion
    poses = [_step(0.0), _step(12.0), _step(0.5), _step(-12.0), _step(0.0, pitch_deg=0.5)]
    lo, cams = _odometry(poses), _camera_pairs(poses, X_TRUE)
    R0 = _off(X_TRUE[:3, :3], 15.0, [0.6, 0.0, 0.8])
    mr = rotation_from_motion(lo, cams, R0, X_TRUE[:3, 3] + 0.1, t_sigma_m=0.1)
    assert mr.free_axis is None and mr.turns >= 2 and mr.directions == 5
    assert rotation_angle_deg(mr.R @ X_TRUE[:3, :3].T) < 0.3
    assert np.all(np.isfinite(mr.sigma_deg)) and mr.change_deg == pytest.approx(15.0, abs=0.5)


def test_a_straight_drive_leaves_the_angle_about_the_direction_of_travel():
    """No turn: the two angles across the direction of travel come from the motion, the one
    about it stays the initial one; a camera direction with the wrong sign is dropped."""
    from paretocal.egomotion import rotation_from_motion
    poses = [_step(0.0), _step(0.0, 1.5), _step(0.0, 2.5), _step(0.0)]
    lo = _odometry(poses)
    cams = _camera_pairs(poses, X_TRUE, flip=(2,))
    d_cam = X_TRUE[:3, :3] @ np.array([1.0, 0.0, 0.0])       # travel, camera frame
    across = np.cross(d_cam, [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    R0 = _off(_off(X_TRUE[:3, :3], 8.0, across), 6.0, d_cam)   # 8 deg across, 6 deg about
    mr = rotation_from_motion(lo, cams, R0, X_TRUE[:3, 3])
    assert mr.reversed == 1 and "sign is wrong" in " ".join(mr.reasons)
    assert mr.directions == 3 and mr.turns == 0
    assert mr.free_axis is not None and _angle(mr.free_axis, d_cam) < 1.0
    assert "not observed" in " ".join(mr.reasons)
    err = Rotation.from_matrix(mr.R @ X_TRUE[:3, :3].T).as_rotvec()
    along = float(np.degrees(err @ d_cam))
    assert abs(along) == pytest.approx(6.0, abs=0.3)             # the initial angle, kept
    assert np.degrees(np.linalg.norm(err - np.radians(along) * d_cam)) < 0.2


def test_noisy_parallel_directions_keep_the_initial_angle_about_them():
    """Sixteen straight steps whose camera directions scatter by about a degree (visual
    odometry with short baselines): the fit across them would turn the rotation about the
    direction of travel at random (by 154 deg on KITTI pairs 4 frames apart); the initial
    angle about it is kept exactly, and the two angles across it still come from the motion."""
    from paretocal.egomotion import rotation_from_motion
    rng = np.random.default_rng(3)
    poses = [_step(0.0) for _ in range(16)]
    for T in poses:                               # the LiDAR's directions scatter too
        T[:3, 3] += rng.normal(0.0, 0.02, 3)
    lo = _odometry(poses)
    cams = _camera_pairs(poses, X_TRUE)
    for k, c in enumerate(cams):
        # One poor pair among good ones: the prior's weight follows the poorest.
        c.direction_sigma_deg = 8.0 if k == 0 else 0.3
        d = c.direction + rng.normal(0.0, math.radians(0.5), 3)
        c.direction = d / np.linalg.norm(d)
    d_cam = X_TRUE[:3, :3] @ np.array([1.0, 0.0, 0.0])
    across = np.cross(d_cam, [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    R0 = _off(_off(X_TRUE[:3, :3], 12.0, across), 20.0, d_cam)
    mr = rotation_from_motion(lo, cams, R0, X_TRUE[:3, 3])
    assert mr.free_axis is not None
    err = Rotation.from_matrix(mr.R @ X_TRUE[:3, :3].T).as_rotvec()
    along = float(np.degrees(err @ mr.free_axis))
    assert abs(along) == pytest.approx(20.0, abs=1.0)
    assert np.degrees(np.linalg.norm(err - np.radians(along) * mr.free_axis)) < 1.0


def test_no_motion_keeps_the_initial_rotation_and_says_why():
    from paretocal.egomotion import rotation_from_motion
    poses = [_step(0.0, forward=0.0)]
    lo = _odometry(poses)
    cams = _camera_pairs([_step(0.0)], X_TRUE)
    cams[0].ok, cams[0].rotation_ok = False, False
    mr = rotation_from_motion(lo, cams, X_TRUE[:3, :3])
    assert not mr.usable and np.allclose(mr.R, X_TRUE[:3, :3]) and mr.reasons


def test_kitti_rotation_from_the_direction_of_travel(kitti, kitti_motion):
    """From a rotation 10 deg off across the direction of travel, frames 0 and 10 bring the two
    angles across it back within the directions' agreement (bound as above, 2.6 deg); the
    drive goes straight, so the angle about the direction is left as it was."""
    from paretocal.egomotion import rotation_from_motion
    lo, cams = kitti_motion
    X = kitti[0].T_ref
    d_cam = cams[0].direction
    across = np.cross(d_cam, [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    R0 = _off(X[:3, :3], 10.0, across)
    mr = rotation_from_motion(lo, cams, R0, X[:3, 3], t_sigma_m=0.25)
    assert mr.free_axis is not None and mr.directions == 1
    err = Rotation.from_matrix(mr.R @ X[:3, :3].T).as_rotvec()
    across_err = err - (err @ mr.free_axis) * mr.free_axis
    assert np.degrees(np.linalg.norm(across_err)) < 2.6
    assert rotation_angle_deg(R0 @ X[:3, :3].T) > 9.9
