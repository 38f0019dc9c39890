"""Depth edges on synthetic spinning-LiDAR sweeps whose true contours are known exactly.

A ray caster sweeps lasers at given elevations over a scene of planes and boxes; every test
states which returns must (or must not) become edges.
"""

import numpy as np

from paretocal.features.lidar import DEPTH_EDGE, lidar_features
from paretocal.lidar.rings import Rings, _as_rings

#: Uneven elevations like a modern 64-beam head: dense near the horizon, 1 deg apart below.
UNEVEN = np.r_[np.arange(2.0, -6.0, -0.2), np.arange(-6.0, -25.5, -1.0)]


def sweep(elevations_deg, boxes=(), height=1.8, step_deg=0.2, max_range=80.0, rng=None,
          time_span=None, seam_shift=0.0):
    """Returns of a sensor ``height`` m above a flat ground, with axis-aligned ``boxes``
    ``(xmin, xmax, ymin, ymax, zmin, zmax)`` in the sensor frame. Points are (N, 4) with zero
    intensity, their ring (top first) and, with ``time_span``, a time per azimuth; the last
    tenth of the sweep sees the scene shifted by ``seam_shift`` m in x (a moving sensor)."""
    az = np.radians(np.arange(0.0, 360.0, step_deg))
    pts, rings, times = [], [], []
    for k, e in enumerate(np.radians(elevations_deg)):
        d = np.stack([np.cos(e) * np.cos(az), np.cos(e) * np.sin(az),
                      np.full_like(az, np.sin(e))], axis=1)
        t = np.full(len(az), np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            tg = np.where(d[:, 2] < 0, -height / d[:, 2], np.inf)
        t = np.minimum(t, tg)
        shift = np.where(az > np.radians(324.0), seam_shift, 0.0)
        for (x0, x1, y0, y1, z0, z1) in boxes:
            with np.errstate(divide="ignore", invalid="ignore"):
                lo = np.stack([(x0 + shift) / d[:, 0], y0 / d[:, 1], z0 / d[:, 2]], 1)
                hi = np.stack([(x1 + shift) / d[:, 0], y1 / d[:, 1], z1 / d[:, 2]], 1)
            tmin = np.nanmax(np.minimum(lo, hi), axis=1)
            tmax = np.nanmin(np.maximum(lo, hi), axis=1)
            hit = (tmax >= tmin) & (tmin > 0)
            t = np.where(hit, np.minimum(t, tmin), t)
        ok = t < max_range
        p = d[ok] * t[ok, None]
        if rng is not None:
            p += rng.normal(0, 0.005, p.shape)
        pts.append(p)
        rings.append(np.full(ok.sum(), k))
        times.append(az[ok] / (2 * np.pi) * (time_span or 0.0))
    pts = np.vstack(pts)
    return (np.column_stack([pts, np.zeros(len(pts))]), np.concatenate(rings),
            np.concatenate(times) if time_span else None)


def rings_of(points, ring):
    return _as_rings(points, ring, "field")


def test_flat_ground_under_uneven_rings_has_no_edges():
    pts, ring, _ = sweep(UNEVEN)
    r = rings_of(pts, ring)
    f = lidar_features(pts, ring=r, smooth_ratio=0.0, edge_contour=False)
    assert (f.group == DEPTH_EDGE).sum() == 0
    # The median spacing alone (0.2 deg) would call the ground between the 1-deg rings edges:
    # the test can fail.
    g = lidar_features(pts, ring=r.ring, ring_spacing_deg=float(np.median(r.spacing_deg())),
                       smooth_ratio=0.0, edge_contour=False)
    assert (g.group == DEPTH_EDGE).sum() > 100


def test_box_top_against_the_ground_far_behind_is_an_edge():
    box = (15.0, 17.0, -2.0, 2.0, -1.8, 0.2)
    pts, ring, _ = sweep(UNEVEN, boxes=[box])
    f = lidar_features(pts, ring=rings_of(pts, ring), smooth_ratio=0.0)
    e = f.xyz[f.group == DEPTH_EDGE]
    assert len(e) > 20
    on_box = (e[:, 0] > 14.5) & (e[:, 0] < 17.5) & (np.abs(e[:, 1]) < 2.5)
    assert on_box.mean() > 0.9


def test_seam_of_a_moving_sweep_is_not_an_edge():
    wall = (20.0, 21.0, -30.0, 30.0, -1.8, 3.0)
    pts, ring, t = sweep(UNEVEN, boxes=[wall], time_span=0.1, seam_shift=2.0)
    r = rings_of(pts, ring)
    without = lidar_features(pts, ring=r, smooth_ratio=0.0, edge_contour=False)
    with_t = lidar_features(pts, ring=r, smooth_ratio=0.0, edge_contour=False, time=t)

    def at_seam(f):
        e = f.xyz[f.group == DEPTH_EDGE]
        return int(np.sum((e[:, 0] > 15) & (np.abs(e[:, 1]) < 1.0)))

    assert at_seam(without) > 10          # the wall's two sides 2 m apart meet straight ahead
    assert at_seam(with_t) == 0


def test_contour_keeps_a_thin_pole_and_drops_scattered_returns(rng):
    pole = (10.0, 10.15, -0.075, 0.075, -1.8, 3.0)
    wall = (30.0, 31.0, -40.0, 40.0, -1.8, 6.0)
    pts, ring, _ = sweep(UNEVEN, boxes=[pole, wall], step_deg=0.1)
    # Foliage: isolated returns pulled towards the sensor at random on one side.
    leafy = (pts[:, 1] > 8) & (pts[:, 0] > 25)
    idx = np.flatnonzero(leafy)
    pull = rng.random(len(idx)) < 0.4
    pts[idx[pull], :3] *= rng.uniform(0.5, 0.8, (pull.sum(), 1))
    r = rings_of(pts, ring)
    plain = lidar_features(pts, ring=r, smooth_ratio=0.0, edge_contour=False)
    contour = lidar_features(pts, ring=r, smooth_ratio=0.0, edge_contour=True)

    def count(f, sel):
        e = f.xyz[f.group == DEPTH_EDGE]
        return int(sel(e).sum())

    pole_sel = lambda e: (np.abs(e[:, 0] - 10.07) < 0.3) & (np.abs(e[:, 1]) < 0.3)  # noqa: E731
    leaf_sel = lambda e: e[:, 1] > 4  # noqa: E731
    assert count(contour, pole_sel) >= 0.8 * count(plain, pole_sel) > 20
    assert count(contour, leaf_sel) < 0.3 * count(plain, leaf_sel)


def test_sky_edges_mark_the_top_of_a_box_against_empty_sky():
    # Its top is seen at -1 deg; the lasers above it reach no ground within 60 m: sky.
    # A tall building behind the sensor gives every laser returns somewhere in the sweep.
    box = (12.0, 14.0, -3.0, 3.0, -1.8, -0.2)
    behind = (-21.0, -20.0, -40.0, 40.0, -1.8, 30.0)
    pts, ring, _ = sweep(UNEVEN, boxes=[box, behind], max_range=60.0)
    r = rings_of(pts, ring)
    off = lidar_features(pts, ring=r, smooth_ratio=0.0, sky_edges=False)
    on = lidar_features(pts, ring=r, smooth_ratio=0.0, sky_edges=True)
    top = lambda e: (e[:, 2] > -0.6) & (e[:, 0] > 11.5) & (e[:, 0] < 14.5)  # noqa: E731
    n_off = top(off.xyz[off.group == DEPTH_EDGE]).sum()
    n_on = top(on.xyz[on.group == DEPTH_EDGE]).sum()
    assert n_on > n_off + 20
    e = on.xyz[on.group == DEPTH_EDGE]
    z = e[top(e) & (np.abs(e[:, 1]) < 2.5), 2]          # the top, not the box's sides
    assert np.all(np.abs(z + 0.2) < 0.1)            # between the top ring and the sky ray


def test_rings_object_gives_the_per_pair_gaps():
    pts, ring, _ = sweep(UNEVEN)
    r = rings_of(pts, ring)
    hit = UNEVEN[np.unique(ring)]                   # lasers above the horizon see nothing
    assert isinstance(r, Rings) and r.n_rings == len(hit) == 43
    assert np.allclose(r.elevation_deg, hit, atol=0.05)


def test_relative_canny_thresholds_follow_the_exposure(raw_frames, rng):
    from paretocal.features.image import edge_map

    img = raw_frames[0].image
    full = edge_map(img, relative=True) > 0
    assert (edge_map(img, relative=False) > 0).sum() == full.sum()   # a full-range image
    dark = (img.astype(np.float64) * 0.4).round().astype(np.uint8)
    fixed = (edge_map(dark, relative=False) > 0).sum()
    rel = edge_map(dark, relative=True) > 0
    assert fixed < 0.5 * full.sum()
    assert 0.7 * full.sum() < rel.sum() < 1.3 * full.sum()
    # Pure noise of a dark exposure makes no edges: the thresholds stay above the noise.
    noise = np.clip(rng.normal(40, 3, img.shape[:2]), 0, 255).astype(np.uint8)
    assert (edge_map(noise, relative=True) > 0).sum() < 0.001 * noise.size


def test_noise_relative_canny_thresholds_keep_a_dim_images_edges(raw_frames, rng):
    from paretocal.features.image import edge_map, gradient_noise

    img = raw_frames[0].image
    full = (edge_map(img, noise_sigmas=13.0) > 0).sum()
    # A dim, low-contrast exposure of the same scene with its own sensor noise: thresholds in
    # noise deviations keep its edges; fixed ones lose most of them.
    dim = np.clip(img.astype(np.float64) * 0.3 + rng.normal(0, 0.5, img.shape), 0, 255)
    dim = dim.round().astype(np.uint8)
    assert (edge_map(dim) > 0).sum() < 0.3 * full
    assert (edge_map(dim, noise_sigmas=13.0) > 0).sum() > 0.5 * full
    # The threshold follows the noise: on noise alone almost nothing is an edge.
    noise = np.clip(rng.normal(40, 6, img.shape[:2]), 0, 255).astype(np.uint8)
    assert gradient_noise(noise) > 0
    assert (edge_map(noise, noise_sigmas=13.0) > 0).sum() < 0.001 * noise.size
