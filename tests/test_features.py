import numpy as np
import pytest
from scipy.spatial import cKDTree

from paretocal.camera import project
from paretocal.config import Settings
from paretocal.features import (DEPTH_EDGE, INTENSITY_EDGE, SMOOTH, image_features,
                                lidar_features, prepare_frame, stratified_order)
from paretocal.lidar.rings import (elevation_deg, recover_rings, rings_from_elevation,
                                   rings_from_scan_order)

from .helpers import box_scene


class TestRings:
    def test_kitti_sample_has_64_rings(self, raw_frames):
        for f in raw_frames:
            r = recover_rings(f.points)
            assert r.method == "scan" and r.n_rings == 64 and r.purity > 0.99
            ring = r.ring
            # Each ring is one laser: its median elevation differs from its neighbours'.
            el = elevation_deg(f.points)
            med = np.array([np.median(el[ring == k]) for k in range(64)])
            assert np.unique(np.round(med, 2)).size == 64

    def test_elevation_clustering_is_ordered_on_kitti(self, raw_frames):
        # KITTI's returns of one laser spread over 0.3-0.6 deg of elevation (more than the ring
        # spacing), so clusters are approximate there; they must still be ordered like rings.
        pts = raw_frames[0].points
        far = np.linalg.norm(pts[:, :3], axis=1) > 15
        scan = rings_from_scan_order(pts)[far]
        elev = rings_from_elevation(pts[far])
        assert 30 <= elev.max() + 1 <= 64
        el = elevation_deg(pts[far])
        ids = [k for k in np.unique(scan) if (scan == k).sum() > 200]
        by_height = sorted(ids, key=lambda k: -np.median(el[scan == k]))
        med_cluster = [np.median(elev[scan == k]) for k in by_height]
        assert np.all(np.diff(med_cluster) >= 0)

    def test_elevation_clustering_exact_on_synthetic_shuffled_scan(self, rng):
        K, img, pts, T = box_scene(rng)
        truth = rings_from_scan_order(pts)
        perm = rng.permutation(len(pts))
        far = np.linalg.norm(pts[perm, :3], axis=1) > 0       # all points
        elev = rings_from_elevation(pts[perm][far])
        assert elev.max() + 1 == truth.max() + 1 == 32
        # The same partition: each scan ring is exactly one elevation cluster.
        t = truth[perm]
        mapping = {k: np.unique(elev[t == k]) for k in range(32)}
        assert all(len(v) == 1 for v in mapping.values())
        assert len({int(v[0]) for v in mapping.values()}) == 32

    def test_shuffled_cloud_falls_back_to_the_line_model(self, raw_frames, rng):
        pts = raw_frames[0].points[rng.permutation(len(raw_frames[0].points))]
        r = recover_rings(pts)
        assert r.method == "lines" and r.n_rings == 64 and r.purity > 0.99


class TestLidarEdges:
    def test_box_silhouette(self, rng):
        K, img, pts, T = box_scene(rng)
        lf = lidar_features(pts, depth_jump_m=1.0, smooth_ratio=1.0, rng=0)
        edges = lf.xyz[lf.group == DEPTH_EDGE]
        assert len(edges) > 50
        # Only the near side of a jump is an edge: every edge point lies on the box (x = 8 m).
        np.testing.assert_allclose(edges[:, 0], 8.0, atol=0.05)
        # Along-ring edges sit at the box's sides, cross-ring edges at its top.
        side = np.abs(np.abs(edges[:, 1]) - 1.0) < 0.1
        top = np.abs(edges[:, 2] - 0.5) < 0.2
        bottom = np.abs(edges[:, 2] + 1.0) < 0.2
        assert side.sum() > 10 and top.sum() > 10 and bottom.sum() > 10
        assert (side | top | bottom).all()
        # Placed midway between the last ray on the box and the first ray past it: within half
        # a beam spacing (0.2 deg at 8 m = 2.8 cm) of the true silhouette at |y| = 1.
        np.testing.assert_allclose(np.abs(edges[side & ~top & ~bottom, 1]), 1.0, atol=0.015)

    def test_edge_support_drops_foliage_and_keeps_silhouettes(self, rng):
        K, img, pts, T = box_scene(rng)
        pts = pts.copy()
        # Foliage: returns left of the box scatter in range at random (10-20 m on their rays).
        bush = (pts[:, 0] > 0) & (pts[:, 1] > 3) & (pts[:, 1] < 7) & (pts[:, 2] > -2)
        r = np.linalg.norm(pts[bush, :3], axis=1)
        pts[bush, :3] *= (rng.uniform(10, 20, bush.sum()) / r)[:, None]
        plain = lidar_features(pts, smooth_ratio=0.0, rng=0)
        kept = lidar_features(pts, smooth_ratio=0.0, edge_support=True, rng=0)
        in_bush = lambda f: (f.xyz[:, 1] > 1.5) & (f.group == DEPTH_EDGE)  # noqa: E731
        on_box = lambda f: (np.abs(f.xyz[:, 0] - 8) < 0.05) & (f.group == DEPTH_EDGE)  # noqa: E731
        assert in_bush(plain).sum() > 100
        assert in_bush(kept).sum() < 0.1 * in_bush(plain).sum()
        # The box's silhouette survives almost entirely.
        assert on_box(kept).sum() > 0.9 * on_box(plain).sum() > 50

    def test_intensity_edges_only_on_one_surface(self, rng):
        pts = np.array([[10.0, y, 0.0, 0.1 if y < 4 else 0.9] for y in np.linspace(2, 6, 400)],
                       dtype=np.float32)
        lf = lidar_features(pts, ring_method="scan", cross_ring=False, min_range_m=0.5,
                            smooth_ratio=0.0, rng=0)
        ie = lf.xyz[lf.group == INTENSITY_EDGE]
        assert len(ie) == 1 and abs(ie[0, 1] - 4.0) < 0.02
        assert not (lf.group == DEPTH_EDGE).any()

    def test_smooth_points_are_not_edges(self, rng):
        K, img, pts, T = box_scene(rng)
        lf = lidar_features(pts, smooth_ratio=2.0, rng=0)
        sm = lf.xyz[lf.group == SMOOTH]
        assert len(sm) > 0
        assert (np.abs(np.abs(sm[:, 1]) - 1.0) > 0.02).all()


class TestImageFeatures:
    def test_dt_is_exact_distance_at_pixel_centres(self, raw_frames):
        feats = image_features(raw_frames[0].image, truncation_px=1e6)
        tree = cKDTree(feats.edge_uv)
        rng = np.random.default_rng(0)
        uv = np.column_stack([rng.integers(0, 1242, 2000), rng.integers(0, 375, 2000)])
        d, _ = tree.query(uv)
        np.testing.assert_allclose(feats.dt[uv[:, 1], uv[:, 0]], d, atol=1e-3)

    def test_truncation_and_mean(self, raw_frames):
        feats = image_features(raw_frames[0].image, truncation_px=10)
        assert feats.dt.max() == pytest.approx(10.0)
        assert feats.mean_dt == pytest.approx(float(feats.dt.mean()), rel=1e-6)

    def test_small_fragments_removed(self, raw_frames):
        full = image_features(raw_frames[0].image).edges
        pruned = image_features(raw_frames[0].image, min_edge_px=30).edges
        assert 0 < (pruned > 0).sum() < (full > 0).sum()
        assert not (pruned & ~full).any()

    def test_blank_image_has_no_edges(self):
        feats = image_features(np.zeros((50, 60, 3), np.uint8))
        assert len(feats.edge_uv) == 0 and (feats.dt == feats.truncation_px).all()


class TestOrdering:
    def test_permutation_and_proportional_prefixes(self, rng):
        group = rng.integers(0, 2, 3000).astype(np.int8)
        cell = rng.integers(0, 32, 3000)
        order = stratified_order(group, cell, rng)
        assert np.array_equal(np.sort(order), np.arange(3000))
        share = group.mean()
        for n in (50, 200, 1000):
            assert abs(group[order[:n]].mean() - share) < 2.0 / np.sqrt(n) + 0.02

    def test_prepared_frame_is_in_view_and_seeded(self, raw_frames):
        s = Settings()
        f = raw_frames[0]
        a = prepare_frame(f, f.T_ref, s.features, s.objective, np.random.default_rng(3))
        b = prepare_frame(f, f.T_ref, s.features, s.objective, np.random.default_rng(3))
        np.testing.assert_array_equal(a.xyz, b.xyz)
        uv, z, _ = project(a.xyz, f.camera, f.T_ref)
        m = s.features.view_margin_px
        assert (z > 0).all() and (uv[:, 0] >= -m).all() and (uv[:, 0] <= 1241 + m).all()
        counts = a.counts()
        assert counts["depth_edge"] > 500 and counts["intensity_edge"] > 100  # w_edge = 0.8


def test_equalize_brings_a_night_image_to_a_day_images_edges(data, raw_frames):
    from paretocal.features.image import edge_map
    from paretocal.io.layouts import load_frames

    folder = data / "aimotive" / "front_pinhole"
    if not folder.is_dir():
        pytest.skip("aiMotive sample not present")
    night = load_frames(folder, "0")[0].image
    day = raw_frames[0].image
    n_night, n_day = ((edge_map(im) > 0).mean() for im in (night, day))
    e_night, e_day = ((edge_map(im, equalize=True) > 0).mean() for im in (night, day))
    # Fixed thresholds find a tenth of the day image's edge density at night (measured
    # 0.09); with local contrast equalised about a third (0.35), and the day image changes
    # far less than the night one (x1.6 against x5.9).
    assert n_night < 0.15 * n_day
    assert e_night / e_day > 0.25
    assert e_night / n_night > 5.0 and e_day / n_day < 2.0


def _feature_counts_dict(feats):
    """The features as result.json wrote them from a plain dict, key for key."""
    from paretocal.features.lidar import GROUP_NAMES
    from paretocal.stage import depth_edges_doubtful
    from paretocal.verdict import MIN_POINTS_PER_FRAME

    per = [f.counts() for f in feats]
    total = {g: int(sum(p[g] for p in per)) for g in GROUP_NAMES}
    summaries = [f.rings for f in feats if f.rings]
    ring_info = None if not summaries else {
        "methods": sorted({s["method"] for s in summaries}),
        "min_purity": min(s["purity"] for s in summaries),
        "spacing_deg_median": summaries[0]["spacing_deg_median"]}
    return {"per_frame_mean": {g: round(total[g] / len(feats), 1) for g in GROUP_NAMES},
            "total": total, "rings": sorted({f.n_rings for f in feats}),
            "ring_recovery": ring_info,
            "frames_contributing": int(sum(len(f.xyz) >= MIN_POINTS_PER_FRAME for f in feats)),
            "per_frame": [{"frame": f.name, **c,
                           "rings": None if not f.rings else
                           {k: f.rings[k] for k in ("method", "n_rings", "purity")}}
                          for f, c in zip(feats, per)],
            "noise": [{"frame": f.name, "reason": why} for f in feats
                      if (why := depth_edges_doubtful(f.rings))]}


def test_feature_counts_name_each_frame_and_the_noisy_ones(raw_frames):
    """result.json and check say how many features of each group every frame gave, with its
    rings, and which frames' depth edges are likely noise (rings that are not the lasers')."""
    from dataclasses import replace

    from paretocal.stage import Stage, feature_counts

    frames = raw_frames[:2]
    stage = Stage(frames, frames[0].T_ref, frames[0].T_ref, Settings())
    good = feature_counts(stage.feats)
    assert good.to_dict() == _feature_counts_dict(stage.feats)
    assert [p.frame for p in good.per_frame] == [f.name for f in frames]
    for p, f in zip(good.per_frame, stage.feats):
        assert p.depth_edge == int((f.group == DEPTH_EDGE).sum()) > 0
        assert p.rings is not None and p.rings.n_rings == 64 and p.rings.purity > 0.9
    assert good.noise == ()
    mixed = [replace(stage.feats[0], rings=dict(stage.feats[0].rings, n_rings=3)),
             replace(stage.feats[1], rings=dict(stage.feats[1].rings, purity=0.4))]
    noise = feature_counts(mixed).noise
    assert [n.frame for n in noise] == [f.name for f in frames]
    assert "3 laser rings" in noise[0].reason and "40 %" in noise[1].reason


def test_feature_counts_are_written_as_before():
    """result.json's ``features``: the keys in their order, the nested records as dicts, the
    tuples as lists; read back, the same JSON."""
    import json

    from paretocal.inputs import RingBrief
    from paretocal.stage import FeatureCounts, FrameCounts, NoiseNote, RingRecovery

    rings = RingBrief(method="scan", n_rings=64, purity=0.9931)
    counts = FeatureCounts(
        per_frame_mean={"depth_edge": 406.0, "intensity_edge": 6.5, "smooth": 700.0},
        total={"depth_edge": 812, "intensity_edge": 13, "smooth": 1400}, rings=(3, 64),
        ring_recovery=RingRecovery(methods=("lines", "scan"), min_purity=0.4,
                                   spacing_deg_median=0.4214),
        frames_contributing=2,
        per_frame=(FrameCounts("a", 800, 12, 700, rings), FrameCounts("b", 12, 1, 700)),
        noise=(NoiseNote("b", "3 laser rings found"),))
    doc = counts.to_dict()
    assert list(doc) == ["per_frame_mean", "total", "rings", "ring_recovery",
                         "frames_contributing", "per_frame", "noise"]
    assert doc["rings"] == [3, 64] and doc["frames_contributing"] == 2
    assert doc["ring_recovery"] == {"methods": ["lines", "scan"], "min_purity": 0.4,
                                    "spacing_deg_median": 0.4214}
    assert doc["per_frame"] == [
        {"frame": "a", "depth_edge": 800, "intensity_edge": 12, "smooth": 700,
         "rings": {"method": "scan", "n_rings": 64, "purity": 0.9931}},
        {"frame": "b", "depth_edge": 12, "intensity_edge": 1, "smooth": 700, "rings": None}]
    assert doc["noise"] == [{"frame": "b", "reason": "3 laser rings found"}]
    assert [p.edges for p in counts.per_frame] == [812, 13]
    text = json.dumps(doc, indent=2)
    back = FeatureCounts.from_dict(json.loads(text))
    assert back == counts and json.dumps(back.to_dict(), indent=2) == text
    # No rings recovered: written as null.
    assert FeatureCounts.from_dict(dict(doc, ring_recovery=None)).to_dict()["ring_recovery"] \
        is None


def test_sampling_px_is_the_lidars_step_seen_in_the_image():
    """The box scene's LiDAR steps 0.2 deg in azimuth and 20/31 deg between rings; seen by a
    500 px focal length that is 1.75 px and 5.6 px at the image centre and more towards the
    borders (a pinhole magnifies by up to 1 / cos^2 of the angle off its axis, 1.4 in this
    image's corners), in any storage order and from a vehicle frame alike."""
    from paretocal.features.prepare import sampling_px
    from paretocal.camera import Camera
    from paretocal.geometry import invert

    K, img, pts, T = box_scene(np.random.default_rng(0))
    cam = Camera(K, img.shape[1], img.shape[0])
    el = np.round(np.degrees(np.arctan2(pts[:, 2], np.hypot(pts[:, 0], pts[:, 1]))), 1)
    levels = np.unique(el)
    ring = len(levels) - 1 - np.searchsorted(levels, el)          # top first
    s = sampling_px(pts, ring, cam, T)
    want = 500.0 * np.radians([0.2, 20.0 / 31.0])
    assert np.all(s >= want) and np.all(s < 1.15 * want)
    perm = np.random.default_rng(1).permutation(len(pts))
    np.testing.assert_allclose(sampling_px(pts[perm], ring[perm], cam, T), s, rtol=1e-9)
    # The same sensor mounted in a vehicle frame: its pose maps the rays into that frame.
    pose = np.eye(4)
    pose[:3, 3] = [1.2, 0.3, 1.5]
    T_vehicle = T @ invert(pose)
    np.testing.assert_allclose(sampling_px(pts, ring, cam, T_vehicle, sensor_pose=pose), s,
                               rtol=0.02)
    # Nothing in view, or no rings: nothing measured.
    assert sampling_px(pts, np.full(len(pts), -1), cam, T) is None
