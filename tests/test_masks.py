"""Image masks: a point on a masked pixel counts exactly like a point outside the image, in every
evaluator; edges at a mask's border are dropped; calib.yaml's ``camera.mask`` and the lens
model's own unreachable pixels (the Mei fold-back region) reach the frame."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml

from paretocal.camera import Camera, in_image
from paretocal.depth import depth_map
from paretocal.features.image import ImageFeatures, distance_transform, image_features
from paretocal.features.prepare import FrameFeatures
from paretocal.io import load_frames
from paretocal.objective import build_scene, sums_kdtree, sums_numba, sums_numpy
from paretocal.objective.scene import DT_MASKED

from .helpers import write_generic

W, H, WC = 200, 120, 120       # image size and the width of the usable (left) part


def _edges(rng):
    """Random rectangles' outlines, all in the left part and clear of its border."""
    img = np.zeros((H, W), np.uint8)
    for _ in range(12):
        u0, v0 = rng.integers(2, WC - 30), rng.integers(2, H - 30)
        cv2.rectangle(img, (int(u0), int(v0)), (int(u0 + rng.integers(5, 25)),
                                                 int(v0 + rng.integers(5, 25))), 255, 1)
    img[:, WC - 8:] = 0
    return img


def _frame(cam, edges, mask, xyz):
    dt = distance_transform(edges, 10.0)
    v, u = np.nonzero(edges)
    img = ImageFeatures(edges=edges, dt=dt, truncation_px=10.0,
                        mean_dt=float(dt.mean(dtype=np.float64)),
                        edge_uv=np.column_stack([u, v]).astype(np.float64), mask=mask)
    m = len(xyz)
    return FrameFeatures("f", cam, img, xyz, (np.arange(m) % 3).astype(np.int8), np.ones(m), 1)


@pytest.mark.parametrize("cam", [
    lambda w: Camera(np.array([[90.0, 0, 99.5], [0, 90.0, 59.5], [0, 0, 1]]), w, H),
    lambda w: Camera(np.array([[90.0, 0, 99.5], [0, 90.0, 59.5], [0, 0, 1]]), w, H, "pinhole",
                     [-0.2, 0.05, 0.001, 0.002, 0.0]),
    lambda w: Camera(np.array([[60.0, 0, 99.5], [0, 60.0, 59.5], [0, 0, 1]]), w, H, "mei",
                     [0.03, -0.08, 0.0, 0.0, 0.0], xi=1.02),
], ids=["ideal", "radtan", "mei"])
def test_a_masked_part_is_exactly_outside_the_image(rng, cam):
    """The right part of the image masked gives the sums of the image cropped to the left part
    (same K), for all three evaluators and every candidate."""
    edges = _edges(rng)
    mask = np.zeros((H, W), bool)
    mask[:, :WC] = True
    xyz = np.column_stack([rng.uniform(-2.5, 2.5, 3000), rng.uniform(-1.2, 1.2, 3000),
                           rng.uniform(0.5, 4.0, 3000)])
    full = build_scene([_frame(cam(W), edges, mask, xyz)])
    crop = build_scene([_frame(cam(WC), np.ascontiguousarray(edges[:, :WC]), None, xyz)])
    assert full.has_mask.tolist() == [True] and crop.has_mask.tolist() == [False]
    assert full.outside[0] == crop.outside[0]                # the mean DT over usable pixels
    np.testing.assert_array_equal(full.frame_dt(0)[:, :WC], crop.frame_dt(0))
    T = np.repeat(np.eye(4)[None], 6, axis=0)
    T[1:, :3, 3] = rng.uniform(-0.2, 0.2, (5, 3))
    n = np.array([3000, 3000, 2000, 1000, 500, 3000])
    uv, valid = cam(W).project_camera_points(xyz)
    in_masked_part = valid & in_image(uv, W, H) & (uv[:, 0] > WC - 1)
    assert in_masked_part.sum() > 200                       # the mask has work to do
    for name, a, b in (("numba", sums_numba(full, T, n), sums_numba(crop, T, n)),
                       ("numpy", sums_numpy(full, T, n), sums_numpy(crop, T, n)),
                       ("kdtree", sums_kdtree(full, [full_edges(full)], T, n),
                        sums_kdtree(crop, [full_edges(full)], T, n))):
        for x, y in zip(a, b):
            np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-9, err_msg=name)
    np.testing.assert_array_equal(sums_numba(full, T, n)[2], sums_kdtree(
        full, [full_edges(full)], T, n)[2])


def full_edges(scene):
    """Edge pixels of the scene's single frame (from its DT: the zeros)."""
    v, u = np.nonzero(scene.frame_dt(0) == 0)
    return np.column_stack([u, v]).astype(np.float64)


def test_a_point_touching_a_masked_pixel_costs_the_outside_charge(rng):
    """A masked square in the middle: exactly the points whose bilinear lookup reads one of its
    pixels leave the in-view count, and each costs the outside charge."""
    edges = _edges(rng)
    mask = np.ones((H, W), bool)
    mask[40:80, 60:100] = False
    cam = Camera(np.array([[90.0, 0, 99.5], [0, 90.0, 59.5], [0, 0, 1]]), W, H)
    xyz = np.column_stack([rng.uniform(-1.5, 1.5, 4000), rng.uniform(-1, 1, 4000),
                           np.full(4000, 1.5)])
    masked = build_scene([_frame(cam, edges, mask, xyz)])
    plain = build_scene([_frame(cam, edges, None, xyz)])
    uv, valid = cam.project_camera_points(xyz)
    seen = valid & in_image(uv, W, H)
    x0 = np.minimum(np.floor(uv[seen, 0]).astype(int), W - 2)
    y0 = np.minimum(np.floor(uv[seen, 1]).astype(int), H - 2)
    touch = np.zeros(len(xyz), bool)
    touch[seen] = ~(mask[y0, x0] & mask[y0, x0 + 1] & mask[y0 + 1, x0] & mask[y0 + 1, x0 + 1])
    assert touch.sum() > 300
    n = np.array([len(xyz)])
    T = np.eye(4)[None]
    for sums in (sums_numba, sums_numpy):
        S1, _, nin = sums(masked, T, n)
        S1p, _, ninp = sums(plain, T, n)
        assert nin[0, 0] == seen.sum() - touch.sum() and ninp[0, 0] == seen.sum()
        # Per group: the untouched points cost what they cost without the mask (same DT),
        # the touched ones the outside charge instead of their DT value.
        dt = plain.frame_dt(0)
        d = np.full(len(xyz), float(plain.outside[0]))
        us, vs = uv[seen, 0], uv[seen, 1]
        fx, fy = us - x0, vs - y0
        top = dt[y0, x0] + fx * (dt[y0, x0 + 1] - dt[y0, x0])
        bot = dt[y0 + 1, x0] + fx * (dt[y0 + 1, x0 + 1] - dt[y0 + 1, x0])
        d[seen] = top + fy * (bot - top)
        d_masked = np.where(touch | ~seen, float(masked.outside[0]), d)
        g = np.arange(len(xyz)) % 3
        np.testing.assert_allclose(S1[0, 0], np.bincount(g, d_masked, 3), rtol=1e-7)
        np.testing.assert_allclose(S1p[0, 0], np.bincount(g, d, 3), rtol=1e-7)
    q = masked.dtq.reshape(H, W)
    assert (q[~mask] == DT_MASKED).all() and (q[mask] < DT_MASKED).all()


def test_image_features_drop_edges_at_the_mask_border():
    """A bright hood below a dark scene: its border is a strong edge, dropped with everything
    within the blur's reach of the mask; the mean DT is over usable pixels."""
    img = np.full((120, 160, 3), 30, np.uint8)
    img[85:, :] = 200                                     # the hood (masked)
    cv2.rectangle(img, (20, 20), (60, 50), (220, 220, 220), -1)   # a real object
    mask = np.ones((120, 160), bool)
    mask[82:, :] = False                                  # hood masked with a 3 px margin
    plain = image_features(img)
    masked = image_features(img, mask=mask)
    assert plain.edges[80:90].any()                       # the hood's border is an edge...
    assert not masked.edges[75:].any()                    # ... dropped, with its surroundings
    np.testing.assert_array_equal(masked.edges[:60], plain.edges[:60])   # the object stays
    assert masked.mean_dt == pytest.approx(float(masked.dt[mask].mean()))
    assert masked.mask is mask and len(masked.edge_uv) == int((masked.edges > 0).sum())


def test_calib_yaml_mask_reaches_frames_features_and_depth(tmp_path, raw_frames):
    f0 = raw_frames[0]
    root = write_generic(tmp_path / "rig", raw_frames[:1])
    usable = np.ones((375, 1242), np.uint8) * 255
    usable[300:, :] = 0                                   # a bonnet along the bottom
    cv2.imwrite(str(root / "mask.png"), usable)
    calib = yaml.safe_load((root / "calib.yaml").read_text())
    calib["camera"]["mask"] = "mask.png"
    (root / "calib.yaml").write_text(yaml.safe_dump(calib))
    (frame,) = load_frames(root)
    np.testing.assert_array_equal(frame.mask, usable > 0)
    np.testing.assert_array_equal(frame.image, f0.image)
    d_all = depth_map(f0.points, f0.camera, f0.T_ref)
    d = depth_map(frame.points, frame.camera, frame.T_ref, mask=frame.mask)
    assert (d_all[300:] > 0).sum() > 500 and not (d[300:] > 0).any()
    np.testing.assert_array_equal(d[:300], d_all[:300])


def _aimotive(data, tmp_path, camera):
    """One aiMotive camera folder as a source: its calib.yaml, images and the shared clouds
    (linked, not copied)."""
    src, root = data / "aimotive", tmp_path / camera
    root.mkdir()
    (root / "calib.yaml").write_bytes((src / camera / "calib.yaml").read_bytes())
    (root / "images").symlink_to(src / camera / "images")
    (root / "points").symlink_to(src / "points")
    return root


def test_mei_camera_masks_its_fold_back_region(data, tmp_path):
    """The aiMotive fisheye (Mei model): loaded as stored, with the pixels beyond the lens's
    monotonic radius masked; most LiDAR returns in view land on usable pixels."""
    (frame,) = load_frames(_aimotive(data, tmp_path, "left_fisheye"), frames="0")
    cam = frame.camera
    assert (cam.model, cam.xi) == ("mei", pytest.approx(1.0222136193840399))
    assert frame.image.shape == (704, 1280, 3)
    assert frame.mask is not None and not frame.mask.all()
    np.testing.assert_array_equal(frame.mask, cam.valid_pixels)
    assert frame.mask[345, 642] and not frame.mask[0, 0]
    from paretocal.camera import project

    uv, _, vis = project(frame.points, cam, frame.T_ref)
    assert vis.sum() > 10_000
    ok = frame.mask[np.rint(uv[vis, 1]).astype(int).clip(0, 703),
                    np.rint(uv[vis, 0]).astype(int).clip(0, 1279)]
    assert ok.mean() > 0.99
    front = load_frames(_aimotive(data, tmp_path, "front_pinhole"), frames="0")[0]
    assert front.camera.model == "pinhole" and len(front.camera.D) == 5
    assert front.mask is None                     # its distortion is monotonic everywhere
