"""benchmarks/accuracy.py: the variant folders and blind copies it calibrates (no calibration)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from paretocal.camera import project
from paretocal.geometry import correction_matrix, invert
from paretocal.io import detect_source, load_frames
from paretocal.io.text import read_mapping

from .helpers import load_benchmark


@pytest.fixture(scope="module")
def acc():
    return load_benchmark("accuracy")


@pytest.fixture(scope="module")
def two_frames(raw_date):
    return load_frames(raw_date, "0,10")


def _start(T_ref):
    return T_ref @ invert(correction_matrix([0.1, -0.05, 0.2, 3.0, -2.0, 1.5]))


@pytest.mark.parametrize("name", ["32beam", "16beam", "firing", "packet", "shuffled", "vehicle",
                                  "16beam+vehicle"])
def test_variant_folder_reads_back(acc, raw_date, two_frames, tmp_path, name):
    folder, T_ref, pose = acc.build_variant(raw_date, name, tmp_path / name, frames="0,10")
    src = detect_source(folder)
    assert src.layout == "folder"
    assert [f.name for f in src.frames] == [f.name for f in two_frames]
    back = load_frames(folder)
    for k, (orig, f) in enumerate(zip(two_frames, back)):
        v = acc.make_variant(orig.points, name, k)
        assert len(f.points) == len(v.points)
        np.testing.assert_array_equal(f.points, v.points)     # in the variant's order
        assert f.image.shape == orig.image.shape
        np.testing.assert_allclose(f.camera.K, orig.camera.K)
        np.testing.assert_allclose(f.T_ref, T_ref, atol=1e-12)
    n64 = len(two_frames[0].points)
    expect = {"32beam": (0.4, 0.6), "16beam": (0.2, 0.3), "16beam+vehicle": (0.2, 0.3)}
    lo, hi = expect.get(name, (1.0, 1.0))
    assert lo * n64 <= len(back[0].points) <= hi * n64
    calib = read_mapping(folder / "calib.yaml")
    if "vehicle" in name:
        assert not np.allclose(pose, np.eye(4))
        np.testing.assert_allclose(calib["lidar_pose"], pose, atol=1e-12)
        if back[0].sensor_pose is not None:          # once the reader takes lidar_pose
            np.testing.assert_allclose(back[0].sensor_pose, pose, atol=1e-9)
    else:
        np.testing.assert_allclose(pose, np.eye(4))
        np.testing.assert_allclose(T_ref, two_frames[0].T_ref, atol=1e-12)
        assert "lidar_pose" not in calib


def test_variants_of_a_generic_folder(acc, two_frames, tmp_path):
    """A generic source's variants: its truth from the ring recovery about the sensor as the
    tool locates it (here KITTI sweeps in a folder: the exact rings), the points as PCD in the
    source's frame, calib.yaml the source's apart from the moved reference."""
    from paretocal.testing import kitti_truth, ring_accuracy

    from .helpers import write_generic

    src = write_generic(tmp_path / "src", two_frames)
    calib = read_mapping(src / "calib.yaml")
    calib.update(init_error=[2.0, 0.05], credit="kept")
    (src / "calib.yaml").write_text(yaml.safe_dump(calib))
    cache = {}
    for name in ("packet", "32beam+shuffled", "vehicle"):
        folder, T_ref, pose = acc.build_variant(src, name, tmp_path / name, cache=cache)
        back = load_frames(folder)
        assert [f.points_path.suffix for f in back] == [".pcd", ".pcd"]
        again = read_mapping(folder / "calib.yaml")
        assert {k: v for k, v in again.items() if k != "T_cam_lidar"} == \
            {k: v for k, v in calib.items() if k != "T_cam_lidar"}    # no lidar_pose added
        np.testing.assert_allclose(again["T_cam_lidar"], T_ref, atol=1e-12)
        for k, (orig, f) in enumerate(zip(two_frames, back)):
            truth = acc.generic_truth([orig])[0]
            assert ring_accuracy(truth.ring, kitti_truth(orig.points).ring) >= 0.99
            v = acc.make_variant(truth, name, k)
            np.testing.assert_array_equal(f.points, v.points)
            assert len(f.points) < 0.6 * len(orig.points) if "32beam" in name else \
                len(f.points) == len(orig.points)
        if name == "vehicle":
            assert not np.allclose(pose, np.eye(4))
            np.testing.assert_allclose(T_ref, two_frames[0].T_ref @ invert(pose), atol=1e-12)
        else:
            np.testing.assert_allclose(pose, np.eye(4))         # located at the cloud's origin
            np.testing.assert_allclose(T_ref, two_frames[0].T_ref, atol=1e-12)


def test_located_pose_is_the_tools(acc, two_frames):
    import dataclasses

    from paretocal.testing import kitti_truth, to_vehicle_frame

    # KITTI's clouds are in the sensor's frame; a pose calib.yaml gives is taken as it is.
    np.testing.assert_array_equal(acc.located_pose(two_frames[:1]), np.eye(4))
    P = to_vehicle_frame(kitti_truth(two_frames[0].points)).sensor_pose
    moved = [dataclasses.replace(two_frames[0], sensor_pose=P)]
    np.testing.assert_array_equal(acc.located_pose(moved), P)


def test_vehicle_reference_keeps_the_pixels(acc, raw_date, two_frames, tmp_path):
    folder, T_veh, pose = acc.build_variant(raw_date, "vehicle", tmp_path / "v", frames="0,10")
    np.testing.assert_allclose(T_veh, two_frames[0].T_ref @ np.linalg.inv(pose), atol=1e-12)
    for orig, f in zip(two_frames, load_frames(folder)):
        uv0, z0, vis0 = project(orig.points, orig.camera, orig.T_ref)
        uv1, z1, vis1 = project(f.points, f.camera, f.T_ref)
        assert vis0.sum() > 5000
        np.testing.assert_array_equal(vis0, vis1)
        np.testing.assert_allclose(uv1[vis1], uv0[vis0], atol=1e-2)
        np.testing.assert_allclose(z1[vis1], z0[vis0], atol=1e-4)


def test_blind_copy_of_a_generic_folder(acc, raw_date, two_frames, tmp_path):
    folder, T_ref, _ = acc.build_variant(raw_date, "generic", tmp_path / "tiny", frames="0,10")
    # Other keys must survive: a mask file (relative path) and the free-text credit line.
    import cv2

    mask = np.full((two_frames[0].camera.height, two_frames[0].camera.width), 255, np.uint8)
    mask[-40:] = 0
    cv2.imwrite(str(folder / "mask.png"), mask)
    calib = read_mapping(folder / "calib.yaml")
    calib["mask"] = "mask.png"
    calib["credit"] = "tiny rig, frames 0 and 10"
    (folder / "calib.yaml").write_text(yaml.safe_dump(calib, sort_keys=False))
    np.testing.assert_allclose(acc.folder_reference(folder), T_ref)
    T0 = _start(T_ref)
    copy = acc.blind_copy_folder(folder, T0, tmp_path / "copy")
    src = detect_source(copy)
    assert src.layout == "folder" and len(src.frames) == 2
    np.testing.assert_allclose(src.frames[0].T_ref, T0, atol=1e-12)
    again = read_mapping(copy / "calib.yaml")
    assert {k: v for k, v in again.items() if k != "T_cam_lidar"} == \
        {k: v for k, v in calib.items() if k != "T_cam_lidar"}
    f = load_frames(copy, "1")[0]
    assert len(f.points) == len(two_frames[1].points)
    assert f.mask is not None and not f.mask[-1].any()
    # The original folder is untouched.
    np.testing.assert_allclose(acc.folder_reference(folder), T_ref)


def test_blind_copy_of_aimotive(acc, data, tmp_path):
    root = data / "aimotive" / "front_pinhole"
    if not root.is_dir():
        pytest.skip("aiMotive sample not present")
    T_ref = acc.folder_reference(root)
    T0 = _start(T_ref)
    copy = acc.blind_copy_folder(root, T0, tmp_path)
    src = detect_source(copy)      # points/ resolved, whether a link or a one-line link file
    assert len(src.frames) == len(list((root / "images").iterdir()))
    np.testing.assert_allclose(src.frames[0].T_ref, T0, atol=1e-12)
    orig = read_mapping(root / "calib.yaml")
    again = read_mapping(copy / "calib.yaml")
    assert {k: v for k, v in again.items() if k != "T_cam_lidar"} == \
        {k: v for k, v in orig.items() if k != "T_cam_lidar"}
    assert again["camera"]["model"] == "pinhole" and len(again["camera"]["D"]) == 5
    assert (copy / "points").resolve() == (data / "aimotive" / "points").resolve()


def test_blind_copy_of_the_pandaset_rig(acc, data, tmp_path):
    """A rig's blind copy moves the LiDAR: every camera's T_cam_lidar is its reference with
    the same correction undone, so the cameras keep their relative poses; the run is
    ``calibrate --joint`` and its first camera's result is compared."""
    from paretocal.io import rig_cameras

    root = data / "pandaset"
    if not (root / "calib.yaml").is_file():
        pytest.skip("PandaSet sample not present")
    assert acc.layout_of(root) == "rig"
    refs = acc.rig_references(root)
    T0 = _start(refs[0])
    G = invert(refs[0]) @ T0
    ds = acc.Dataset("rig", "rig", root, refs[0])
    copy = acc.make_copy(ds, T0, tmp_path)
    moved = [src.frames[0].T_ref for _, src in rig_cameras(copy)]
    assert len(moved) == len(refs) == 3
    np.testing.assert_allclose(moved[0], T0, atol=1e-12)
    for T, R in zip(moved, refs):
        np.testing.assert_allclose(T, R @ G, atol=1e-12)
    np.testing.assert_allclose(moved[1] @ invert(moved[0]), refs[1] @ invert(refs[0]),
                               atol=1e-9)


def test_kitti_blind_copies_and_trial_starts(acc, raw_date, object_dir, tmp_path):
    T_ref = detect_source(raw_date).frames[0].T_ref
    T0 = _start(T_ref)
    drive = acc.blind_copy(raw_date, T0, tmp_path / "raw")
    np.testing.assert_allclose(detect_source(drive).frames[0].T_ref, T0, atol=1e-9)
    obj = acc.blind_copy_object(object_dir, T0, tmp_path / "obj")
    np.testing.assert_allclose(detect_source(obj).frames[0].T_ref, T0, atol=1e-9)
    args = acc.parse_args(["--rot", "5", "--trans", "0.2"])
    starts = [acc.trial_start(k, args, T_ref) for k in range(3)]
    assert all(not np.allclose(s, T_ref) for s in starts)
    np.testing.assert_allclose(acc.trial_start(1, args, T_ref), starts[1])


def test_options_pass_through(acc):
    args = acc.parse_args(["--frames", "0:20:10", "--init-error", "5,0.2",
                           "--extra", "--n-max 500 --rule knee", "--", "--seed", "3"])
    assert acc.calibrate_options(args) == ["--frames", "0:20:10", "--init-error", "5,0.2",
                                           "--n-max", "500", "--rule", "knee", "--seed", "3"]
    args = acc.parse_args(["--rot", "3", "--trans", "0.1", "--init-error", "box"])
    assert acc.calibrate_options(args) == ["--init-error", "3,0.1"]
    assert acc.parse_variants(["32beam,16beam", "vehicle", "16beam"]) == \
        ["32beam", "16beam", "vehicle"]
    with pytest.raises(SystemExit):
        acc.parse_variants(["8beam"])


def test_summary_counts_the_verdicts(acc):
    def row(k, rot, cm, verdict):
        r = {"dataset": "d", "trial": k, "start_deg": 5.0, "start_cm": 20.0, "rot_deg": rot,
             "trans_cm": cm, "n": 100, "verdict": verdict, "reasons": [], "wall_s": 1.0}
        r.update({a: 0.0 for a in acc.AXES})
        return r

    rows = [row(0, 0.2, 2.0, "ok"), row(1, 0.3, 3.5, "unreliable"), row(2, 5.0, 40.0, "ok"),
            row(3, 0.5, 12.0, "unreliable"),
            {"dataset": "d", "trial": 4, "start_deg": 5.0, "start_cm": 20.0, "wall_s": 1.0,
             "exit": 2, "error": "no edges", "rot_deg": None, "trans_cm": None, "n": None,
             "verdict": None, "reasons": [], **{a: None for a in acc.AXES}}]
    s = acc.summary_figures(rows)
    assert s["failed"] == 1 and s["completed"] == 4
    assert s["within"]["1deg_10cm"] == 2 and s["within"]["0.3deg_3cm"] == 1
    v = s["verdict"]
    assert (v["off"], v["off_flagged"], v["off_passed"]) == (2, 1, 1)
    assert (v["correct"], v["correct_flagged"]) == (2, 1)
    args = acc.parse_args([])
    text = acc.summarise(rows, args)
    assert "2 result(s) off" in text and "within 1.0 deg and 10 cm: 2/5" in text


def test_interval_coverage_and_width_ratios(acc):
    """The summary's interval figures: results judged ok only, undetermined axes left out."""
    def row(k, verdict, err, half):
        key = "half_width" if verdict == "ok" else "half_width_not_trusted"
        return {"dataset": "d", "trial": k, "start_deg": 5.0, "start_cm": 20.0, "rot_deg": 0.2,
                "trans_cm": 2.0, "n": 100, "verdict": verdict, "reasons": [], "wall_s": 1.0,
                **{a: 0.0 for a in acc.AXES},
                "interval_error": dict(zip(("x", "y", "z", "yaw", "pitch", "roll"), err)),
                key: dict(zip(("x", "y", "z", "yaw", "pitch", "roll"), half))}

    half = [2.0, 2.0, 2.0, 0.2, 0.2, None]                   # roll undetermined
    rows = [row(0, "ok", [1.0, -1.0, 0.5, 0.1, 0.1, 3.0], half),
            row(1, "ok", [3.0, 0.5, -0.5, -0.05, 0.4, 0.0], half),
            row(2, "unreliable", [30.0, 0, 0, 0, 0, 0], [9.0] * 6)]
    s = acc.summary_figures(rows)
    iv = s["intervals"]
    assert iv["trials"] == 2 and iv["axis_trials"] == 10
    assert iv["coverage"] == pytest.approx(8 / 10)                # x of trial 1, pitch of 1
    assert iv["axes"]["roll"] == {"determined": 0}
    assert iv["axes"]["x"]["covered"] == 1 and iv["axes"]["x"]["median_ratio"] == pytest.approx(
        np.median([2.0, 2.0 / 3.0]))
    assert iv["axes"]["yaw"]["median_half_width_over_p95_error"] == pytest.approx(
        0.2 / np.percentile([0.1, 0.05], 95))
    assert s["intervals_not_trusted"]["coverage"] == pytest.approx(5 / 6)
    text = acc.summarise(rows, acc.parse_args([]))
    assert "95 % intervals, results judged ok (2 results): |error| within the half-width on " \
           "80 % of 10 axis-trials (x 1/2" in text
    # The error on the intervals' axes is the correction from the result to the reference.
    T_ref = correction_matrix([0.1, 0.2, 0.3, 10, 20, 30])
    T = T_ref @ np.linalg.inv(correction_matrix([0.01, 0, 0, 0, 0, 0.5]))
    rec = acc.interval_record({"verdict": "ok", "intervals": {"half_width": {"x": 1.0}}},
                              T, T_ref)
    assert rec["interval_error"]["x"] == pytest.approx(1.0) and rec["half_width"] == {"x": 1.0}
    assert rec["interval_error"]["roll"] == pytest.approx(0.5)
