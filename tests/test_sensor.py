"""The LiDAR's pose in a vehicle frame, estimated from one sweep, against the exact pose of
KITTI sweeps moved into vehicle frames at run time (and the aiMotive rig's factory pose)."""

from dataclasses import replace

import numpy as np
import pytest

from paretocal.config import Settings
from paretocal.lidar.rings import MIN_PURITY, MIN_RINGS, recover_rings
from paretocal.lidar.sensor import estimate_sensor_pose
from paretocal.pipeline import locate_lidar
from paretocal.testing import decimate, firing_order, kitti_truth, ring_accuracy, \
    to_vehicle_frame, vehicle_pose


@pytest.fixture(scope="module")
def sweep(raw_frames):
    return kitti_truth(raw_frames[0].points)


def _axis_errors(est, truth):
    """Angle between the axes (deg) and the horizontal distance between them (m)."""
    zt, ze = truth[:3, 2], est.pose[:3, 2]
    angle = np.degrees(np.arccos(np.clip(zt @ ze, -1.0, 1.0)))
    d = est.pose[:3, 3] - truth[:3, 3]
    return angle, np.linalg.norm(d - (d @ zt) * zt)


@pytest.mark.parametrize("name,make", [
    ("vehicle frame", lambda v: to_vehicle_frame(v)),
    ("16 beams, firing order", lambda v: to_vehicle_frame(firing_order(decimate(v, 4)))),
    ("tilted 3 deg, 2 m up", lambda v: to_vehicle_frame(
        v, vehicle_pose((0.5, -1.5, 1.9), (30.0, 3.0, 2.0)))),
])
def test_axis_found_and_rings_recovered_about_it(sweep, name, make):
    w = make(sweep)
    est = estimate_sensor_pose(w.points, rng=1)
    assert est is not None and est.ok, name
    angle, offset = _axis_errors(est, w.sensor_pose)
    # A beam spacing is 0.4 deg on the HDL-64 and 1.6 deg at 16 beams: the axis must be far
    # finer than that for the rings to separate.
    assert angle < 0.05 and offset < 0.02, (name, angle, offset)
    r = recover_rings(est.to_sensor(w.points))
    assert r.purity >= MIN_PURITY
    assert ring_accuracy(r.ring, w.ring) >= 0.99, name


def test_about_a_wrong_origin_rings_are_not_plausible(sweep):
    w = to_vehicle_frame(sweep)
    r = recover_rings(w.points)
    assert r.purity < MIN_PURITY or r.n_rings < MIN_RINGS
    assert r.notes


def test_unstructured_cloud_gives_no_pose(rng):
    pts = rng.uniform(-30, 30, (20000, 3))
    pts[:, 2] = rng.uniform(-2, 5, len(pts))
    est = estimate_sensor_pose(pts, rng=0)
    assert est is None or not est.ok


def test_same_seed_same_estimate(sweep):
    w = to_vehicle_frame(sweep)
    a = estimate_sensor_pose(w.points, rng=5)
    b = estimate_sensor_pose(w.points, rng=5)
    np.testing.assert_array_equal(a.pose, b.pose)


def test_locate_lidar_sources(raw_frames, sweep):
    s = Settings()
    frames = raw_frames[:1]
    out, info, _ = locate_lidar(frames, s)
    assert info["source"] == "cloud origin" and out[0].sensor_pose is None
    w = to_vehicle_frame(sweep)
    moved = [replace(frames[0], points=w.points, ring=None, sensor_pose=None)]
    out, info, _ = locate_lidar(moved, s)
    assert info["source"] == "estimated" and info["purity"] >= MIN_PURITY
    angle, offset = _axis_errors(type("E", (), {"pose": out[0].sensor_pose}), w.sensor_pose)
    assert angle < 0.05 and offset < 0.02
    given = [replace(moved[0], sensor_pose=w.sensor_pose)]
    assert locate_lidar(given, s)[1]["source"] == "calib.yaml"


def test_aimotive_pose_from_the_sweep(data):
    from paretocal.io.layouts import load_frames

    folder = data / "aimotive" / "front_pinhole"
    if not folder.is_dir():
        pytest.skip("aiMotive sample not present")
    frame = load_frames(folder, "0")[0]
    est = estimate_sensor_pose(frame.points, rng=0)
    assert est is not None and est.ok and est.n_lines >= 64
    # The dataset's factory pose of the Pandar64 in the vehicle frame.
    truth = np.eye(4)
    truth[:3, 2] = [0.003489, -0.004620, 0.999983]
    truth[:3, 3] = [1.1574, 0.0013, 1.6823]
    angle, offset = _axis_errors(est, truth)
    assert angle < 0.05 and offset < 0.02


@pytest.mark.parametrize("seed", [1, 14])
def test_an_unlucky_subsample_is_retried(raw_frames, seed):
    # Frame 8 in firing order: with these seeds the first subsample leaves the axis 0.16-0.17
    # deg off (66 % and 58 % of the returns explained); the retry finds the pose. (2 of seeds
    # 0-19 need the retry, all 20 are found.)
    w = to_vehicle_frame(firing_order(kitti_truth(raw_frames[8].points)))
    est = estimate_sensor_pose(w.points, rng=seed)
    assert est.ok
    angle, offset = _axis_errors(est, w.sensor_pose)
    assert angle < 0.05 and offset < 0.02


def test_a_pose_that_cannot_be_found_is_said(raw_frames, sweep, monkeypatch, caplog):
    import paretocal.lidar.sensor as sensor
    from paretocal.pipeline import warn_unlocated

    w = to_vehicle_frame(sweep)
    moved = [replace(raw_frames[0], points=w.points, ring=None, sensor_pose=None)]
    monkeypatch.setattr(sensor, "estimate_sensor_pose", lambda *a, **k: None)
    out, info, _ = locate_lidar(moved, Settings())
    assert info["source"] == "unknown" and out[0].sensor_pose is None
    assert info["purity_at_origin"] < MIN_PURITY and "ground plane" in info["reason"]
    with caplog.at_level("WARNING", logger="paretocal"):
        warn_unlocated(moved, info)
    assert any(str(moved[0].points_path) in r.getMessage() and "lidar_pose" in r.getMessage()
               for r in caplog.records)
