"""Sparse depth maps: the z-buffer rule, KITTI's 16-bit encoding, the files and the command."""

import numpy as np
import pytest

from paretocal.camera import Camera, project
from paretocal.cli import main
from paretocal.depth import depth_map, read_kitti_png, to_kitti_png, write_depth


def _cam():
    return Camera(K=np.array([[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]]), width=64,
                  height=48)


def test_nearest_return_wins_and_empty_pixels_are_zero():
    cam = _cam()
    # Camera frame = LiDAR frame: two returns on one pixel (5 m and 3 m), one elsewhere, one
    # behind the camera and one outside the image.
    pts = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, 3.0], [0.3, 0.1, 2.0], [0.0, 0.0, -4.0],
                    [10.0, 0.0, 1.0]])
    d = depth_map(pts, cam, np.eye(4))
    assert d.dtype == np.float32 and d.shape == (48, 64)
    uv, _, _ = project(pts, cam, np.eye(4))
    u0, v0 = np.rint(uv[0]).astype(int)
    assert d[v0, u0] == pytest.approx(3.0)
    u2, v2 = np.rint(uv[2]).astype(int)
    assert d[v2, u2] == pytest.approx(2.0)
    assert np.count_nonzero(d) == 2


def test_kitti_encoding_round_trip(tmp_path):
    d = np.array([[0.0, 1.0, 12.3456], [80.0, 255.99, 300.0]], dtype=np.float32)
    q = to_kitti_png(d)
    assert q.dtype == np.uint16
    assert q[0, 0] == 0 and q[0, 1] == 256 and q[1, 0] == 80 * 256
    assert q[1, 2] == 0                                      # beyond 255.996 m: dropped
    import cv2

    cv2.imwrite(str(tmp_path / "d.png"), q)
    back = read_kitti_png(tmp_path / "d.png")
    ok = d < 255.996
    np.testing.assert_allclose(back[ok], d[ok], atol=0.5 / 256)


def test_real_frame_files_agree(tmp_path, raw_frames):
    f = raw_frames[0]
    paths = write_depth(f, f.T_ref, tmp_path)
    assert [p.name for p in paths] == [f"{f.name}.png", f"{f.name}.npy", f"{f.name}_overlay.png"]
    d = np.load(paths[1])
    png = read_kitti_png(paths[0])
    assert d.shape == (f.camera.height, f.camera.width)
    hit = d > 0
    assert 10_000 < hit.sum() < 20_000                     # about 16k returns land in view
    np.testing.assert_allclose(png[hit], d[hit], atol=0.5 / 256 + 1e-6)
    assert (png[~hit] == 0).all()
    assert 2.0 < d[hit].min() and d[hit].max() < 90.0
    assert not list(tmp_path.glob(".*tmp*"))


def test_command(tmp_path, raw_date, capsys):
    code = main(["depth", str(raw_date), "--out", str(tmp_path / "d"), "--frames", "0:2"])
    assert code == 0, capsys.readouterr().err
    assert len(list((tmp_path / "d").glob("*.npy"))) == 2
    code = main(["depth", str(raw_date), "--out", str(tmp_path / "d"), "--max-depth", "0"])
    assert code == 2 and "--max-depth" in capsys.readouterr().err
