"""A rig that is not KITTI: real KITTI frames turned into a generic folder with .pcd clouds and
a distorted (plumb_bob) camera; the calibration must land as it does on the KITTI layout."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml
from pypcd4 import Encoding, PointCloud

from paretocal.cli import main
from paretocal.geometry import correction_matrix, pose_error
from paretocal.io import load_frames, read_extrinsic, write_extrinsic

D = np.array([-0.28, 0.09, 0.0008, -0.0005, -0.015])    # a typical wide-angle plumb_bob


def distort(image: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """The image a camera with distortion ``dist`` would have taken: each distorted pixel
    samples the pinhole image where its undistorted ray lands."""
    h, w = image.shape[:2]
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pts = np.stack([uu.ravel(), vv.ravel()], 1)[:, None, :]
    und = cv2.undistortPoints(pts, K, dist, P=K)[:, 0, :]
    mx = und[:, 0].reshape(h, w).astype(np.float32)
    my = und[:, 1].reshape(h, w).astype(np.float32)
    return cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


@pytest.mark.slow
def test_pcd_and_distorted_camera_calibrate_like_kitti(tmp_path, raw_frames):
    frames = raw_frames[:8]
    root = tmp_path / "rig"
    (root / "images").mkdir(parents=True)
    (root / "points").mkdir()
    K = frames[0].camera.K
    (root / "calib.yaml").write_text(yaml.safe_dump({
        "camera": {"K": K.tolist(), "D": D.tolist(), "width": frames[0].camera.width,
                   "height": frames[0].camera.height},
        "T_cam_lidar": frames[0].T_ref.tolist()}))
    for f in frames:
        cv2.imwrite(str(root / "images" / f"{f.name}.png"), distort(f.image, K, D))
        PointCloud.from_xyzi_points(f.points).save(root / "points" / f"{f.name}.pcd",
                                                   Encoding.BINARY_COMPRESSED)
    loaded = load_frames(root)
    assert len(loaded) == 8
    np.testing.assert_array_equal(loaded[0].points, frames[0].points)
    # Undistortion on load gives back the pinhole image (up to two resamplings at the border).
    diff = np.abs(loaded[0].image.astype(int) - frames[0].image.astype(int))
    assert np.median(diff[40:-40, 40:-40]) <= 3

    T0 = frames[0].T_ref @ correction_matrix(np.array([0.06, -0.04, 0.05, 2.0, -1.5, 1.0]))
    write_extrinsic(tmp_path / "init.yaml", T0)
    out = tmp_path / "run"
    assert main(["calibrate", str(root), "--init", str(tmp_path / "init.yaml"), "--out", str(out),
                 "--pop", "150", "--gens", "40", "--quiet", "--no-figures"]) == 0
    e = pose_error(read_extrinsic(out / "extrinsic.yaml"), frames[0].T_ref)
    assert e["rotation_deg"] < 0.5 and e["translation_cm"] < 6.0, e
