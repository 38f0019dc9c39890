"""A rig that is not KITTI: real KITTI frames turned into a generic folder with .pcd clouds and
a distorted (plumb_bob) camera, calibrated on the distorted images through the lens model; the
calibration must land as it does on the KITTI layout."""

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


def distort(image: np.ndarray, K: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The image a camera with distortion ``dist`` would have taken: each distorted pixel
    samples the pinhole image where its undistorted ray lands (OpenCV's iterative undistortion
    run to convergence: its default five steps are off by up to 2 px at this distortion).
    Returns the image and the mask of the pixels that saw the pinhole image (the rest is the
    black frame a wider lens adds, which the calibration must ignore)."""
    h, w = image.shape[:2]
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pts = np.stack([uu.ravel(), vv.ravel()], 1)[:, None, :]
    stop = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    und = cv2.undistortPoints(pts, K, dist, None, None, K, stop)[:, 0, :]
    mx = und[:, 0].reshape(h, w).astype(np.float32)
    my = und[:, 1].reshape(h, w).astype(np.float32)
    seen = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
    return cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT), seen


@pytest.mark.slow
def test_pcd_and_distorted_camera_calibrate_like_kitti(tmp_path, raw_frames):
    frames = raw_frames[:8]
    root = tmp_path / "rig"
    (root / "images").mkdir(parents=True)
    (root / "points").mkdir()
    K = frames[0].camera.K
    (root / "calib.yaml").write_text(yaml.safe_dump({
        "camera": {"K": K.tolist(), "D": D.tolist(), "width": frames[0].camera.width,
                   "height": frames[0].camera.height, "mask": "mask.png"},
        "T_cam_lidar": frames[0].T_ref.tolist()}))
    for f in frames:
        image, seen = distort(f.image, K, D)
        cv2.imwrite(str(root / "images" / f"{f.name}.png"), image)
        PointCloud.from_xyzi_points(f.points).save(root / "points" / f"{f.name}.pcd",
                                                   Encoding.BINARY_COMPRESSED)
    cv2.imwrite(str(root / "mask.png"), seen.astype(np.uint8) * 255)
    loaded = load_frames(root)
    assert len(loaded) == 8
    np.testing.assert_array_equal(loaded[0].points, frames[0].points)
    # The distorted image is used as it is, through the camera's lens model.
    np.testing.assert_array_equal(loaded[0].image, cv2.imread(str(root / "images" /
                                                                  f"{frames[0].name}.png")))
    assert loaded[0].camera.D == tuple(D)
    np.testing.assert_array_equal(loaded[0].mask, seen)     # the lens reaches every pixel

    T0 = frames[0].T_ref @ correction_matrix(np.array([0.06, -0.04, 0.05, 2.0, -1.5, 1.0]))
    write_extrinsic(tmp_path / "init.yaml", T0)
    out = tmp_path / "run"
    assert main(["calibrate", str(root), "--init", str(tmp_path / "init.yaml"), "--out", str(out),
                 "--pop", "150", "--gens", "40", "--quiet", "--no-figures"]) == 0
    e = pose_error(read_extrinsic(out / "extrinsic.yaml"), frames[0].T_ref)
    assert e["rotation_deg"] < 0.5 and e["translation_cm"] < 6.0, e
