"""The recording's motion against a result (paretocal.crosscheck): on the KITTI drive the
reference agrees and a rotation off across the direction of travel does not; a rig standing
still says so; the record round-trips through result.json."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from paretocal.crosscheck import (MIN_BAND_DEG, MotionAgreement, motion_agreement,
                                  motion_tolerance_deg, recording_motion)


@pytest.fixture(scope="module")
def kitti_motion(raw_frames):
    return recording_motion(raw_frames, seed=0)


def _turned(T: np.ndarray, axis_cam: np.ndarray, deg: float) -> np.ndarray:
    """``T`` with the camera turned by ``deg`` about ``axis_cam`` (camera frame)."""
    out = T.copy()
    out[:3, :3] = Rotation.from_rotvec(np.radians(deg) * axis_cam).as_matrix() @ T[:3, :3]
    return out


def test_the_reference_agrees_with_the_motion(raw_frames, kitti_motion):
    m = kitti_motion
    assert m.moves and not m.standing and m.travel_m > 5 * m.need_m
    a = motion_agreement(m, raw_frames[0].T_ref)
    assert a.applied and a.agree and a.directions >= 3, a
    # The motion's rotation lies within a degree of the reference (0.4 deg measured).
    assert a.change_deg < 1.0 and a.tolerance_deg == motion_tolerance_deg(a.residual_deg)


def test_a_rotation_off_across_the_travel_disagrees(raw_frames, kitti_motion):
    """Three degrees of pitch (about the camera's x, across the direction of travel, its z)
    are seen; three degrees about the direction of travel are not the motion's to judge."""
    T = raw_frames[0].T_ref
    off = motion_agreement(kitti_motion, _turned(T, np.array([1.0, 0.0, 0.0]), 3.0))
    assert off.applied and not off.agree and off.change_deg > 2.5, off
    about = motion_agreement(kitti_motion, _turned(T, np.array([0.0, 0.0, 1.0]), 3.0))
    assert about.applied and about.agree and about.change_deg < 1.0, about


def test_a_standing_rig_shows_one_view(data):
    """PandaSet frames 00-06: the car stands in traffic."""
    from paretocal.io import load_frames

    root = data / "pandaset" / "front"
    if not root.is_dir():
        pytest.skip(f"PandaSet sample not found at {root}")
    frames = load_frames(root, "0:4")
    m = recording_motion(frames)
    assert m.standing and not m.moves and m.pairs == [] and m.camera == []
    a = motion_agreement(m, frames[0].T_ref)
    assert not a.applied and a.standing and a.agree and "barely moves" in a.reason
    # The LiDAR alone tells it too (what a result flagged already is looked at for).
    lidar = recording_motion(frames, camera=False)
    assert lidar.standing and not lidar.camera_measured
    assert motion_agreement(lidar, frames[0].T_ref).standing


def test_the_lidar_alone_sees_a_moving_rig_but_gives_no_rotation(raw_frames):
    m = recording_motion(raw_frames, seed=0, camera=False)
    assert m.moves and not m.camera_measured and m.pairs == [] and m.camera == []
    a = motion_agreement(m, raw_frames[0].T_ref)
    assert not a.applied and a.agree and not a.standing, a
    assert "only the LiDAR's motion was measured" in a.reason


def test_sweeps_with_too_few_points_fail_the_odometry_not_the_run(raw_frames):
    """A frame whose cloud is all but empty (a dropped sweep) is a failed pair of the
    odometry, never an exception out of the verdict."""
    from dataclasses import replace

    frames = [raw_frames[0], replace(raw_frames[1], points=raw_frames[1].points[:5]),
              raw_frames[2]]
    m = recording_motion(frames, camera=False)
    assert m.failed == 2 and not m.standing and not m.moves
    assert "odometry failed on 2 of 2" in motion_agreement(m, raw_frames[0].T_ref).reason


def test_the_record_round_trips():
    a = MotionAgreement(True, travel_m=4.04, need_m=0.42, directions=9, residual_deg=0.62,
                        change_deg=2.5, tolerance_deg=1.5, seconds=2.6)
    doc = a.to_dict()
    assert doc["agree"] is False and MotionAgreement.from_dict(doc) == a
    empty = MotionAgreement(False, reason="one pair").to_dict()
    assert empty["change_deg"] is None and MotionAgreement.from_dict(empty).agree


def test_the_tolerance_follows_the_pairs():
    assert motion_tolerance_deg(0.2) == MIN_BAND_DEG
    assert motion_tolerance_deg(1.0) == pytest.approx(2.0)
    assert motion_tolerance_deg(float("nan")) == MIN_BAND_DEG


def test_the_motions_angle_is_known_to_its_vectors_scatter():
    """The 95 % spread of the angle: residual / sqrt(2 k - p) per observed axis, times
    sqrt(chi2_p(0.95)); three directions that disagree by 0.56 deg (KITTI frames 1 to 6):
    +-0.68 deg, shrinking with more vectors; nothing without a fit."""
    three = MotionAgreement(True, directions=3, residual_deg=0.556, change_deg=1.51,
                            tolerance_deg=1.5)
    assert three.spread_deg == pytest.approx(2.4477 * 0.556 / 2.0, rel=1e-3)
    nine = MotionAgreement(True, directions=9, residual_deg=0.556)
    assert nine.spread_deg == pytest.approx(three.spread_deg / 2)          # sqrt(4 / 16)
    turning = MotionAgreement(True, directions=3, turns=2, residual_deg=0.556)
    assert turning.spread_deg == pytest.approx(2.7955 * 0.556 / np.sqrt(7), rel=1e-3)
    assert np.isnan(MotionAgreement(False, reason="one pair").spread_deg)


def test_too_few_frames_are_refused(raw_frames):
    with pytest.raises(ValueError, match="at least 3 frames"):
        recording_motion(raw_frames[:2])
