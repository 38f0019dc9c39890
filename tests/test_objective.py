import dataclasses

import numpy as np
import pytest

from paretocal.camera import Camera
from paretocal.config import Settings
from paretocal.geometry import apply_correction
from paretocal.objective import (CalibrationObjective, build_scene, combine, get_evaluator,
                                 measure_cost_model, paper_chamfer, sums_kdtree, sums_numba,
                                 sums_numpy)
from paretocal.pipeline import prepare_features


@pytest.fixture(scope="module")
def scene_and_feats(raw_frames):
    s = Settings()
    frames = raw_frames[:3]
    feats = prepare_features(frames, frames[0].T_ref, s)
    return build_scene(feats), feats, frames[0].T_ref


def _population(T, n_max, rng, C=24):
    X = np.zeros((C, 7))
    X[:, :3] = rng.uniform(-0.2, 0.2, (C, 3))
    X[:, 3:6] = rng.uniform(-3, 3, (C, 3))
    X[:, 6] = rng.integers(5, n_max, C)
    X[0] = 0
    X[0, 6] = n_max
    return X


class TestEvaluators:
    def test_numba_equals_numpy(self, scene_and_feats, rng):
        scene, feats, T = scene_and_feats
        X = _population(T, int(scene.points_per_frame.max()), rng)
        A = apply_correction(T, X)
        n = X[:, 6].astype(np.int64)
        a, b = sums_numba(scene, A, n), sums_numpy(scene, A, n)
        for u, v in zip(a, b):
            np.testing.assert_allclose(u, v, rtol=1e-9, atol=1e-6)

    def test_the_grouped_layout_holds_the_first_n_points_of_each_group(self, scene_and_feats,
                                                                        rng):
        """The kernel reads points grouped (Scene.gx ...): for every n, the first
        ``group_count[f, n, g]`` grouped points of group g are the group-g points among the
        first n of the frame, in the same order (so the sums are the same, bit for bit)."""
        scene = scene_and_feats[0]
        for f in range(scene.n_frames):
            a, b = scene.point_start[f], scene.point_start[f + 1]
            for n in [0, 1, *rng.integers(2, b - a, 5), b - a]:
                for g in range(scene.group_start.shape[1]):
                    first = a + np.flatnonzero(scene.group[a:a + n] == g)
                    s = scene.group_start[f, g]
                    got = slice(s, s + scene.group_count[f, n, g])
                    for grouped, flat in ((scene.gx, scene.x), (scene.gy, scene.y),
                                          (scene.gz, scene.z), (scene.gweight, scene.weight)):
                        np.testing.assert_array_equal(grouped[got], flat[first])

    def test_the_order_of_the_candidates_changes_no_sum(self, scene_and_feats, rng):
        """The kernel deals candidates to threads by n (balanced_order); every candidate's
        sums stay bitwise what they are alone, whatever the order or the thread count."""
        from paretocal.objective.kernel import balanced_order

        scene, feats, T = scene_and_feats
        X = _population(T, int(scene.points_per_frame.max()), rng, C=40)
        X = X[np.argsort(X[:, 6])]                    # sorted by n, as a polish sends them
        A, n = apply_correction(T, X), X[:, 6].astype(np.int64)
        whole = sums_numba(scene, A, n)
        shuffled = rng.permutation(len(X))
        again = sums_numba(scene, A[shuffled], n[shuffled])
        one = [sums_numba(scene, A[i:i + 1], n[i:i + 1]) for i in range(len(X))]
        for k in range(3):
            np.testing.assert_array_equal(again[k], whole[k][shuffled])
            np.testing.assert_array_equal(np.concatenate([o[k] for o in one]), whole[k])
        perm = balanced_order(n, 2)
        assert sorted(perm) == list(range(len(n)))
        assert balanced_order(n, 1) is None and balanced_order(np.full(40, 7), 2) is None
        halves = [n[perm[:20]].sum(), n[perm[20:]].sum()]
        assert abs(halves[0] - halves[1]) <= n.max()   # in the caller's order: far apart
        assert abs(n[:20].sum() - n[20:].sum()) > n.max()

    def test_close_to_exact_kdtree_oracle(self, scene_and_feats, rng):
        scene, feats, T = scene_and_feats
        X = _population(T, int(scene.points_per_frame.max()), rng, C=8)
        A = apply_correction(T, X)
        n = X[:, 6].astype(np.int64)
        K1, _, kin = sums_kdtree(scene, [f.image.edge_uv for f in feats], A, n)
        for evaluator in (sums_numba, sums_numpy):
            S1, _, nin = evaluator(scene, A, n)
            np.testing.assert_array_equal(nin, kin)
            # Bilinear interpolation of the exact EDT vs the exact distance at the same point:
            # the mean per-point difference is a small fraction of a pixel.
            per_point = np.abs(S1 - K1).sum() / np.maximum(scene.points_used(n), 1).sum()
            assert per_point < 0.1

    def test_out_of_view_points_cost_the_outside_charge(self, scene_and_feats):
        scene, feats, T = scene_and_feats
        T_away = T.copy()
        T_away[:3, 3] += [0.0, 0.0, -500.0]           # everything behind the camera
        A = T_away[None]
        n = np.array([int(scene.points_per_frame.max())])
        S1, S2, nin = sums_numba(scene, A, n)
        assert nin.sum() == 0
        expect = scene.outside * scene.points_per_frame  # unweighted points
        np.testing.assert_allclose(S1[0].sum(axis=1), expect, rtol=1e-5)

    def test_objective_is_invariant_to_frame_order_within_a_prefix(self, scene_and_feats, rng):
        scene, feats, T = scene_and_feats
        # The same points in reverse frame order give the same mean over frames.
        rev = build_scene(feats[::-1])
        s = Settings()
        cm = measure_cost_model(scene, sums_numba, T, 10, 100, candidates=4, repeats=1)
        X = _population(T, 100, rng, C=6)
        f_a = CalibrationObjective(scene, T, s.objective, cm, ucb_k=2.0).chamfer(X)["f1"]
        f_b = CalibrationObjective(rev, T, s.objective, cm, ucb_k=2.0).chamfer(X)["f1"]
        np.testing.assert_allclose(f_a, f_b, rtol=1e-10)

    def test_a_mounted_camera_is_evaluated_at_its_mount(self, scene_and_feats, rng):
        """Frames whose camera has a mount M (a rig calibrated at once) give, in every
        evaluator, the sums of the same frames without it at ``M @ T``, bit for bit where M is
        the identity's absence; the other frames are untouched."""
        from paretocal.geometry import decalibrate

        scene, feats, T = scene_and_feats
        M = decalibrate(np.eye(4), 1.0, 0.05, 4)[0]
        cams = [dataclasses.replace(c, mount=M) if f == 1 else c
                for f, c in enumerate(scene.cameras)]
        mounted = build_scene([dataclasses.replace(ft, camera=c) for ft, c in zip(feats, cams)])
        assert mounted.mounted.tolist() == [False, True, False]
        X = _population(T, int(scene.points_per_frame.max()), rng, C=8)
        A = apply_correction(T, X)
        n = X[:, 6].astype(np.int64)
        for sums in (sums_numba, sums_numpy):
            got, plain, moved = (sums(mounted, A, n), sums(scene, A, n),
                                 sums(scene, M @ A, n))
            for g, p, m in zip(got, plain, moved):
                np.testing.assert_array_equal(g[:, [0, 2]], p[:, [0, 2]])
                np.testing.assert_allclose(g[:, 1], m[:, 1], rtol=1e-9, atol=1e-6)
            assert not np.allclose(got[0][:, 1], plain[0][:, 1])

    def test_auto_prefers_numba(self):
        assert get_evaluator("auto") is sums_numba
        assert get_evaluator("numpy") is sums_numpy


def _with_cameras(scene, cam):
    """The scene with every frame seen through ``cam`` (same points and distance transforms)."""
    return dataclasses.replace(scene, cameras=[cam] * scene.n_frames,
                               cam_params=np.stack([cam.kernel_params()] * scene.n_frames))


def _lens_cameras(K):
    """A strongly distorted pinhole (the aiMotive front camera's D), a rational pinhole with
    thin-prism terms and skew, a fisheye and a Mei camera (the aiMotive fisheye's D and xi),
    all at KITTI's K and image size so the sample frames' features serve."""
    Ks = K.copy()
    Ks[0, 1] = 2.0
    return {
        "radtan": Camera(K, 1242, 375, "pinhole", [-0.3007, 0.0842, 0.00203, 0.00061, 0.0]),
        "rational": Camera(Ks, 1242, 375, "pinhole", [0.1, 0.01, 0.001, -0.002, 0.0, 0.2,
                                                      0.01, 0.001, 0.001, -0.0005, 0.0007,
                                                      0.0002]),
        "fisheye": Camera(K, 1242, 375, "fisheye", [0.08, -0.03, 0.01, -0.002]),
        "mei": Camera(K, 1242, 375, "mei", [0.0336, -0.0842, 0.0, 0.0, 0.0], xi=1.0222),
    }


@pytest.mark.parametrize("lens", ["radtan", "rational", "fisheye", "mei"])
class TestEvaluatorsThroughLensModels:
    def test_numba_numpy_kdtree_agree(self, scene_and_feats, rng, lens):
        scene, feats, T = scene_and_feats
        sc = _with_cameras(scene, _lens_cameras(feats[0].camera.K)[lens])
        X = _population(T, int(sc.points_per_frame.max()), rng, C=8)
        Ts = apply_correction(T, X)
        n = X[:, 6].astype(np.int64)
        a, b = sums_numba(sc, Ts, n), sums_numpy(sc, Ts, n)
        for u, v in zip(a, b):
            np.testing.assert_allclose(u, v, rtol=1e-9, atol=1e-6)
        K1, _, kin = sums_kdtree(sc, [f.image.edge_uv for f in feats], Ts, n)
        np.testing.assert_array_equal(a[2], kin)
        assert kin.sum() > 0.3 * sc.points_used(n).sum()        # most points are seen
        assert np.abs(a[0] - K1).sum() / sc.points_used(n).sum() < 0.1
        # The lens matters: an ideal pinhole with the same K sees the points elsewhere.
        assert not np.array_equal(sums_numba(scene, Ts, n)[2], a[2])

    def test_paper_chamfer_projects_through_the_lens(self, scene_and_feats, lens):
        scene, feats, T = scene_and_feats
        cam = _lens_cameras(feats[0].camera.K)[lens]
        sc = _with_cameras(scene, cam)
        n = np.array([50])
        got = paper_chamfer(sc, [f.image.edge_uv for f in feats], T[None], n)[0]
        expect = []
        for f in range(sc.n_frames):
            p = sc.frame_xyz(f)[:50].astype(np.float64)
            uv, valid = cam.project_camera_points(p @ T[:3, :3].T + T[:3, 3])
            d = np.linalg.norm(feats[f].image.edge_uv[:, None] - uv[valid][None], axis=2)
            expect.append((d.min(axis=1) ** 2).sum() / 50)
        assert got == pytest.approx(np.mean(expect), rel=1e-9)


class TestCombine:
    def test_hand_computed(self):
        # One candidate, one frame, groups: depth edges {1, 3}, none, smooth {4}.
        S1 = np.array([[[4.0, 0.0, 4.0]]])
        S2 = np.array([[[10.0, 0.0, 16.0]]])
        W1 = np.array([[[2.0, 0.0, 1.0]]])
        W2 = W1.copy()
        w = np.array([1.0, 0.0, -0.5])
        out = combine(S1, S2, W1, W2, np.array([7.0]), w, ucb_k=0.0)
        assert out["f1"][0] == pytest.approx(2.0 - 0.5 * 4.0)
        k = combine(S1, S2, W1, W2, np.array([7.0]), w, ucb_k=3.0)
        # Sample variance of {1, 3} is 2; SE of the mean = sqrt(2 / 2) = 1 (smooth: 1 point).
        assert k["se"][0] == pytest.approx(1.0)
        assert k["f1"][0] == pytest.approx(out["f1"][0] + 3.0)

    def test_compiled_pass_is_numpys_arithmetic_bit_for_bit(self):
        # The array-operation form of combine (what the compiled per-group pass replaced),
        # against the compiled one on sums with empty groups, single points, zero variance,
        # negative rounding residues and weights of every sign.
        def reference(S1, S2, W1, W2, outside, weights, ucb_k):
            has = W1 > 0
            safe = np.where(has, W1, 1.0)
            mean = np.where(has, S1 / safe, outside[None, :, None])
            n_eff = np.where(has, W1 * W1 / np.where(W2 > 0, W2, 1.0), 0.0)
            var = np.where(n_eff > 1, (S2 / safe - mean**2) * n_eff
                           / np.maximum(n_eff - 1.0, 1e-12), 0.0)
            var = np.maximum(var, 0.0)
            F = S1.shape[1]
            term = (mean * weights).sum(axis=2)
            se2 = (np.where(n_eff > 0, var / np.maximum(n_eff, 1e-12), 0.0)
                   * weights**2)[..., weights != 0].sum(axis=(1, 2)) / F**2
            se = np.sqrt(se2)
            return {"f1": term.mean(axis=1) + ucb_k * se, "mean": mean.mean(axis=1),
                    "se": se, "per_frame": term}

        rng = np.random.default_rng(5)
        for C, F in [(1, 1), (3, 7), (50, 20), (7, 33)]:
            W1 = rng.choice([0.0, 1.0, 0.7, 3.0, 250.0], size=(C, F, 3)) * rng.uniform(
                0.5, 1.5, (C, F, 3))
            W2 = np.where(W1 > 0, W1 * rng.uniform(0.3, 1.0, W1.shape), 0.0)
            d = rng.uniform(0, 10, (C, F, 3))
            S1 = W1 * d
            S2 = np.where(rng.random(W1.shape) < 0.2, S1 * d, W1 * (d * d + rng.uniform(
                0, 4, W1.shape)))           # some exact d^2 (zero variance up to rounding)
            outside = rng.uniform(3, 8, F).astype(np.float32)
            for weights in (np.array([0.7, 0.3, -0.2]), np.array([1.0, 0.0, -0.5])):
                got = combine(S1, S2, W1, W2, outside, weights, 4.6)
                want = reference(S1, S2, W1, W2, outside, weights, 4.6)
                for key in want:
                    np.testing.assert_array_equal(got[key], want[key], err_msg=key)

    def test_sampling_error_shrinks_with_n(self, scene_and_feats):
        scene, feats, T = scene_and_feats
        s = Settings()
        cm = measure_cost_model(scene, sums_numba, T, 10, 300, candidates=4, repeats=1)
        obj = CalibrationObjective(scene, T, s.objective, cm, ucb_k=4.0)
        X = np.zeros((3, 7))
        X[:, 6] = [20, 100, 300]
        se = obj.chamfer(X)["se"]
        assert se[0] > se[1] > se[2] > 0
        # A per-call multiplier: 0 gives the plain mean, and the objective keeps its own.
        plain = obj.chamfer(X, ucb_k=0.0)
        charged = obj.chamfer(X)
        np.testing.assert_allclose(charged["f1"], plain["f1"] + 4.0 * plain["se"], rtol=1e-9)
        assert obj.ucb_k == 4.0


class TestPaperChamfer:
    def test_matches_brute_force(self, rng):
        from types import SimpleNamespace

        from paretocal.camera import Camera

        pts = rng.uniform(-1, 1, (30, 3)) + [0, 0, 5]
        K = np.array([[50.0, 0, 50], [0, 50, 50], [0, 0, 1]])
        scene = SimpleNamespace(x=pts[:, 0].astype(np.float32), y=pts[:, 1].astype(np.float32),
                                z=pts[:, 2].astype(np.float32), point_start=np.array([0, 30]),
                                z_min=0.1, cameras=[Camera(K, 100, 100)])
        edges = rng.uniform(0, 100, (40, 2))
        n = np.array([12])
        got = paper_chamfer(scene, [edges], np.eye(4)[None], n)[0]
        p = pts[:12].astype(np.float32).astype(np.float64)
        uv = (p @ K.T)[:, :2] / p[:, 2:3]
        d2 = ((edges[:, None, :] - uv[None]) ** 2).sum(-1).min(axis=1)
        assert got == pytest.approx(d2.sum() / 12, rel=1e-9)


class TestCostModel:
    def test_monotone_and_normalised(self, scene_and_feats):
        scene, feats, T = scene_and_feats
        cm = measure_cost_model(scene, sums_numba, T, 10, 500, candidates=16, repeats=3)
        pts = scene.points_used(np.array([10, 100, 500]))
        t, m = cm.normalised(pts)
        np.testing.assert_allclose([t[0], m[0], t[-1], m[-1]], [0, 0, 1, 1], atol=1e-12)
        assert np.all(np.diff(cm.time_ms(pts)) > 0) and np.all(np.diff(cm.nbytes(pts)) > 0)
        assert cm.bytes_fixed >= scene.dtq.nbytes

    def test_normalised_cost_does_not_depend_on_the_timing(self, scene_and_feats):
        # Two different measured lines give the same normalised cost: the search stays
        # deterministic while the absolute figures reflect this machine.
        from paretocal.objective.cost import CostModel

        a = CostModel(0.01, 1e-5, 1e6, 13, 100, 5000, {})
        b = CostModel(0.5, 3e-4, 1e6, 13, 100, 5000, {})
        p = np.array([100, 700, 5000])
        np.testing.assert_allclose(sum(a.normalised(p)), sum(b.normalised(p)), atol=1e-12)
