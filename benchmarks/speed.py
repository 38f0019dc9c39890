"""Speed and memory of paretocal on the bundled KITTI frames, side by side in one run.

    .venv/bin/python benchmarks/speed.py [--quick] [--png runs/speed_scaling.png]

Prints:
1. evaluations and projected points per second of the paper-style evaluator (the paper's
   Chamfer with a KD-tree built per evaluation, timed with psutil over 3 repetitions, as the
   paper describes), the numpy batched evaluator and the fused numba kernel, at the same n, and
   their ratios; then the fused kernel through each camera model (ideal and distorted
   pinhole, Mei, fisheye), and against the machine's limits (the same projection without
   reading the distance transform, and with one read instead of four);
2. wall time and peak RSS of a paper-scale NSGA-II search (population 1000 x 200 generations)
   on 1 and 5 frames, split into objective time and optimiser overhead, each in a fresh process,
   and of the full calibration (search, seeds and polish) at that scale;
3. how the fused evaluation time grows with n, population size and frame count (a table and a
   log-log PNG);
4. the feature extraction time per frame (edges, distance transform, rings, LiDAR edges).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

DATA = Path(os.environ.get("PARETOCAL_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))
DRIVE = DATA / "kitti_raw" / "2011_09_26"


def _scene(frames, settings):
    from paretocal.objective import build_scene
    from paretocal.pipeline import prepare_features

    feats = prepare_features(frames, frames[0].T_ref, settings)
    return build_scene(feats, settings.features.z_min, settings.objective.outside), feats


def _population(T, C, n, rng):
    from paretocal.geometry import apply_correction

    X = np.zeros((C, 7))
    X[:, :3] = rng.uniform(-0.05, 0.05, (C, 3))
    X[:, 3:6] = rng.uniform(-0.5, 0.5, (C, 3))
    X[:, 6] = n
    return apply_correction(T, X), X


def _best_of(fn, repeats):
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def evaluators(frames, settings, n=1000, quick=False):
    """Section 1: paper-style vs numpy vs fused, one frame, n points per evaluation."""
    from paretocal.objective import paper_chamfer, sums_numba, sums_numpy
    from paretocal.objective.cost import measure_per_candidate

    scene, feats = _scene(frames[:1], settings)
    n = min(n, int(scene.points_per_frame.max()))
    rng = np.random.default_rng(0)
    T, _ = _population(frames[0].T_ref, 1000, n, rng)
    A = T  # candidate extrinsics (C, 4, 4)
    nn = np.full(len(A), n)
    edge_uv = [f.image.edge_uv for f in feats]

    k = 10 if quick else 40
    t0 = time.perf_counter()
    measure_per_candidate(lambda i: paper_chamfer(scene, edge_uv, A[i:i + 1], nn[i:i + 1]), k,
                          repeats=3)
    paper_eps = k / (time.perf_counter() - t0)
    numpy_eps = len(A) / _best_of(lambda: sums_numpy(scene, A, nn), 1 if quick else 3)
    numba_eps = len(A) / _best_of(lambda: sums_numba(scene, A, nn), 3 if quick else 10)
    rows = [("paper-style (KD-tree per evaluation, psutil, 3 reps)", paper_eps),
            ("numpy, batched over the population", numpy_eps),
            ("fused numba kernel", numba_eps)]
    print(f"\n1. Evaluators, 1 frame, n = {n} points per evaluation "
          f"({len(edge_uv[0])} image edge pixels)")
    print(f"   {'evaluator':<52} {'evals/s':>12} {'points/s':>12} {'vs paper':>9}")
    for name, eps in rows:
        print(f"   {name:<52} {eps:12,.0f} {eps * n:12.3g} {eps / paper_eps:9.0f}x")
    print(f"   fused / numpy = {numba_eps / numpy_eps:.1f}x")
    return {"n": n, "paper_eps": paper_eps, "numpy_eps": numpy_eps, "numba_eps": numba_eps}


def camera_models(frames, settings, n=1000, quick=False):
    """Section 1b: the fused kernel through each lens model, on the same points and DTs.

    The KITTI features are evaluated as if seen through an ideal pinhole (KITTI's own camera),
    a radial-tangential pinhole (the aiMotive front camera's D), a Mei camera (the aiMotive
    fisheye's D and xi) and an equidistant fisheye, all with KITTI's K, so only the projection
    differs (and with it which points land in the image).
    """
    import dataclasses

    from paretocal.camera import Camera
    from paretocal.objective import sums_numba

    scene, _ = _scene(frames[:5], settings)
    n = min(n, int(scene.points_per_frame.min()))
    K, (w, h) = frames[0].camera.K, frames[0].size
    cams = {"ideal pinhole": frames[0].camera,
            "radial-tangential": Camera(K, w, h, "pinhole", [-0.3007, 0.0842, 0.00203, 0.00061]),
            "Mei": Camera(K, w, h, "mei", [0.0336, -0.0842, 0.0, 0.0], xi=1.0222),
            "fisheye": Camera(K, w, h, "fisheye", [0.08, -0.03, 0.01, -0.002])}
    T, _ = _population(frames[0].T_ref, 500, n, np.random.default_rng(2))
    nn = np.full(len(T), n)
    scenes = {k: dataclasses.replace(scene, cameras=[c] * scene.n_frames,
                                     cam_params=np.stack([c.kernel_params()] * scene.n_frames))
              for k, c in cams.items()}
    best = {k: np.inf for k in cams}
    for _ in range(3 if quick else 10):          # interleaved, so load changes hit all alike
        for k, sc in scenes.items():
            best[k] = min(best[k], _best_of(lambda sc=sc: sums_numba(sc, T, nn), 1))
    print(f"\n1b. Fused kernel by camera model, {scene.n_frames} frames, n = {n}, "
          f"population {len(T)}")
    print(f"   {'model':<20} {'evals/s':>10} {'points/s':>10} {'vs pinhole':>11}")
    out = {}
    for k, t in best.items():
        eps = len(T) / t
        out[k] = eps
        print(f"   {k:<20} {eps:10,.0f} {eps * n * scene.n_frames:10.3g} "
              f"{eps / out['ideal pinhole']:10.2f}x")
    return out


def _limit_kernels():
    """Two stripped copies of the fused kernel's ideal-pinhole path on one frame, for the
    limits of section 1c: ``project`` projects and sums the fractions (no distance-transform
    read), ``nearest`` reads one pixel per point instead of the bilinear four."""
    import numba
    from numba import njit, prange

    from paretocal.objective.kernel import BLOCK, pinhole_block

    def make(lookup):
        @njit(parallel=True, error_model="numpy")
        def run(A, x, y, z, dtq, w, h, z_min, n, KS, FS, OS):
            out = np.zeros(A.shape[0])
            for c in prange(A.shape[0]):
                t = numba.get_thread_id()
                KB, FXB, FYB, OKB = KS[t], FS[t, 0], FS[t, 1], OS[t]
                s = 0.0
                for b in range(0, n, BLOCK):
                    bb = min(b + BLOCK, n)
                    pinhole_block(A[c, 0], A[c, 1], A[c, 2], A[c, 3], A[c, 4], A[c, 5],
                                   A[c, 6], A[c, 7], A[c, 8], A[c, 9], A[c, 10], A[c, 11],
                                   x[b:bb], y[b:bb], z[b:bb], w, h, z_min, KB, FXB, FYB, OKB)
                    for j in range(bb - b):
                        if lookup:
                            d = np.float64(dtq[KB[j]]) if OKB[j] else 1.0
                        else:
                            d = FXB[j] + FYB[j] if OKB[j] else 1.0
                        s += d
                        s += d * d
                out[c] = s
            return out
        return run
    return make(False), make(True)


def kernel_limits(frames, settings, n=1000, quick=False):
    """Section 1c: the fused kernel against what this machine allows it, one frame, n points.

    ``projection only``: the kernel's projection and in-order sums without reading the
    distance transform (the arithmetic limit); ``nearest pixel``: one read per point; the
    kernel reads four (bilinear). On one thread and on all of numba's threads.
    """
    import numba

    from paretocal.objective import sums_numba
    from paretocal.objective.kernel import BLOCK

    scene, _ = _scene(frames[:1], settings)
    n = min(n, int(scene.points_per_frame[0]))
    T, _ = _population(frames[0].T_ref, 1000, n, np.random.default_rng(0))
    nn = np.full(len(T), n)
    K = scene.K[0]
    P = np.einsum("ij,cjk->cik", K, T[:, :3, :])              # (C, 3, 4): K @ T[:3]
    A = np.ascontiguousarray(np.concatenate([P[:, 0], P[:, 1], T[:, 2, :]], axis=1))
    threads_all = numba.get_num_threads()
    Tn = numba.config.NUMBA_NUM_THREADS
    scratch = (np.empty((Tn, BLOCK), np.int64), np.empty((Tn, 2, BLOCK)),
               np.empty((Tn, BLOCK), np.bool_))
    project, nearest = _limit_kernels()
    args = (scene.x[:n], scene.y[:n], scene.z[:n], scene.dtq, int(scene.width[0]),
            int(scene.height[0]), float(scene.z_min), n) + scratch
    cases = {"fused kernel (bilinear, 4 reads)": lambda: sums_numba(scene, T, nn),
             "nearest pixel (1 read)": lambda: nearest(A, *args),
             "projection only (arithmetic limit)": lambda: project(A, *args)}
    rates = {}
    for threads in sorted({1, threads_all}):
        numba.set_num_threads(threads)
        for k, fn in cases.items():
            rates[(k, threads)] = len(T) * n / _best_of(fn, 3 if quick else 10)
    numba.set_num_threads(threads_all)
    print(f"\n1c. Fused kernel against this machine's limits, 1 frame, n = {n}, "
          f"population {len(T)} (points/s)")
    print(f"   {'':<36} {'1 thread':>10} {f'{threads_all} threads':>11}")
    for k in cases:
        print(f"   {k:<36} {rates[(k, 1)]:10.3g} {rates[(k, threads_all)]:11.3g}")
    return {f"{k} ({t} threads)": v for (k, t), v in rates.items()}


def optimiser_overhead(quick=False):
    """Section 2a: NSGA-II's own time per generation at population 1000, objective excluded."""
    from pymoo.algorithms.moo.nsga2 import NSGA2
    from pymoo.operators.crossover.sbx import SBX
    from pymoo.operators.mutation.pm import PM

    from paretocal.config import SearchSettings
    from paretocal.search import run_nsga2
    from paretocal.search.problem import RoundN

    sys.path.insert(0, str(Path(__file__).parent))
    from pymoo_nsga import make_algorithm, run_pymoo_nsga2

    class Toy:
        def evaluate(self, X):
            d = np.linalg.norm(X[:, :6] - 0.1, axis=1)
            return np.column_stack([d + 5.0 / np.sqrt(X[:, 6]), X[:, 6]])

    gens = 10 if quick else 30
    s = SearchSettings(pop=1000, gens=gens, seed=0)
    variants = [
        ("pymoo NSGA2 as the paper ran it (duplicate elimination)",
         lambda: run_pymoo_nsga2(Toy(), s, 20, 2000, NSGA2(
             pop_size=s.pop, crossover=SBX(prob=0.9, eta=15), mutation=PM(eta=20),
             repair=RoundN(), eliminate_duplicates=True))),
        ("pymoo NSGA2, duplicates off",
         lambda: run_pymoo_nsga2(Toy(), s, 20, 2000, NSGA2(
             pop_size=s.pop, crossover=SBX(prob=0.9, eta=15),
             mutation=PM(eta=20, at_least_once=True), repair=RoundN(),
             eliminate_duplicates=False))),
        ("pymoo NSGA2 tuned (benchmarks/pymoo_nsga.py)",
         lambda: run_pymoo_nsga2(Toy(), s, 20, 2000, make_algorithm(s))),
        ("array engine (the package's)", lambda: run_nsga2(Toy(), s, 20, 2000)),
    ]
    print("\n2a. NSGA-II's own time per generation, population 1000 (objective excluded)")
    rows = []
    for label, run in variants:
        r = run()
        ms = 1e3 * (r.wall_s - r.objective_s) / gens
        rows.append((label, ms))
        print(f"   {label:<58} {ms:7.1f} ms")
    return dict(rows)


def _child(case: str, frames_spec: str) -> dict:
    """One measured run in this process (called in a fresh subprocess)."""
    from paretocal import Settings, calibrate, load_frames
    from paretocal.geometry import correction_matrix
    from paretocal.objective import CalibrationObjective, measure_cost_model, sums_numba
    from paretocal.pipeline import n_range
    from paretocal.search import run_nsga2

    frames = load_frames(DRIVE, frames_spec)
    settings = Settings().replace(search={"pop": 1000, "gens": 200, "seed": 0})
    T_init = frames[0].T_ref @ correction_matrix([0.1, -0.1, 0.1, 2.0, -2.0, 1.0])
    if case == "default":
        # The default calibration from make demo's start (perturb --rot 5 --trans 0.2 --seed 1000).
        from paretocal.geometry import decalibrate

        settings = Settings()
        T_init = decalibrate(frames[0].T_ref, 5.0, 0.2, 1000)[0]
    t0 = time.perf_counter()
    if case == "search":
        scene, _ = _scene(frames, settings)
        lo, hi = n_range(settings.search, scene.points_per_frame)
        cm = measure_cost_model(scene, sums_numba, T_init, lo, hi)
        obj = CalibrationObjective(scene, T_init, settings.objective, cm, ucb_k=settings.ucb_k)
        r = run_nsga2(obj, settings.search, lo, hi)
        out = {"wall_s": r.wall_s, "objective_s": r.objective_s,
               "overhead_s": r.wall_s - r.objective_s, "evaluations": r.evaluations,
               "points": int(scene.points_per_frame.sum())}
    else:
        r = calibrate(frames, T_init, settings)
        out = {"wall_s": r.wall_s, "timings": {k: round(v, 2) for k, v in r.timings.items()},
               "evaluations": r.evaluations,
               "error": [r.reference_error["rotation_deg"], r.reference_error["translation_cm"]]}
    out["total_s"] = time.perf_counter() - t0
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return out


def default_run() -> dict:
    """Section 0: the default calibration of the 20 bundled frames (make demo's start), by
    stage, in a fresh process (the numba kernels come from the on-disk cache)."""
    p = subprocess.run([sys.executable, __file__, "--child", "default", "--frames", "0:20"],
                       capture_output=True, text=True, check=True)
    r = json.loads(p.stdout.strip().splitlines()[-1])
    t = r["timings"]
    print("\n0. The default calibration, 20 frames (make demo's start), by stage")
    print(f"   {'stage':<18} {'s':>7} {'share':>7}")
    for k, v in sorted(t.items(), key=lambda kv: -kv[1]):
        if k not in ("total", "search_objective"):
            print(f"   {k:<18} {v:7.2f} {100 * v / t['total']:6.1f} %")
    print(f"   {'total':<18} {t['total']:7.2f}   (of which the search's objective "
          f"{t.get('search_objective', 0):.2f} s; {r['evaluations']:,} evaluations; "
          f"error {r['error'][0]:.3f} deg / {r['error'][1]:.2f} cm; peak RSS "
          f"{r['peak_rss_mb']:.0f} MB)")
    return r


def paper_scale(quick=False):
    """Section 2: paper-scale runs, each in a fresh process for an honest peak RSS."""
    cases = [("search", "0"), ("search", "0:5")] + ([] if quick else [("calibrate", "0"),
                                                                     ("calibrate", "0:5")])
    print("\n2. Paper-scale runs (population 1000 x 200 generations), fresh process each")
    print(f"   {'run':<28} {'wall s':>8} {'objective s':>12} {'overhead s':>11} {'peak RSS MB':>12}")
    results = {}
    for case, spec in cases:
        p = subprocess.run([sys.executable, __file__, "--child", case, "--frames", spec],
                           capture_output=True, text=True, check=True)
        r = json.loads(p.stdout.strip().splitlines()[-1])
        results[f"{case} {spec}"] = r
        nf = len(range(*slice(*map(int, spec.split(":"))).indices(20))) if ":" in spec else 1
        label = f"{'NSGA-II search' if case == 'search' else 'full calibrate'}, {nf} frame(s)"
        if case == "search":
            print(f"   {label:<28} {r['wall_s']:8.1f} {r['objective_s']:12.1f} "
                  f"{r['overhead_s']:11.1f} {r['peak_rss_mb']:12.0f}")
        else:
            t = r["timings"]
            print(f"   {label:<28} {r['wall_s']:8.1f} {t.get('search_objective', 0):12.1f} "
                  f"{r['wall_s'] - t.get('search_objective', 0):11.1f} {r['peak_rss_mb']:12.0f}"
                  f"   (stages: {', '.join(f'{k} {v}' for k, v in t.items() if k != 'total')})")
    return results


def scaling(frames, settings, png=None, quick=False):
    """Section 3: fused evaluation time against n, population and frames."""
    from paretocal.objective import sums_numba

    rng = np.random.default_rng(1)
    rep = 2 if quick else 5
    out = {"n": [], "pop": [], "frames": []}
    scene1, _ = _scene(frames[:1], settings)
    nmax = int(scene1.points_per_frame.max())
    for n in [n for n in (125, 250, 500, 1000, 2000) if n <= nmax]:
        T, _ = _population(frames[0].T_ref, 1000, n, rng)
        A = T  # candidate extrinsics (C, 4, 4)
        out["n"].append((n, _best_of(lambda A=A, n=n: sums_numba(scene1, A, np.full(1000, n)), rep)))
    for C in (125, 250, 500, 1000, 2000, 4000):
        T, _ = _population(frames[0].T_ref, C, 1000, rng)
        A = T  # candidate extrinsics (C, 4, 4)
        out["pop"].append((C, _best_of(lambda A=A, C=C: sums_numba(scene1, A, np.full(C, 1000)),
                                        rep)))
    for nf in (1, 2, 5, 10, 20):
        sc, _ = _scene(frames[:nf], settings)
        T, _ = _population(frames[0].T_ref, 1000, 1000, rng)
        A = T  # candidate extrinsics (C, 4, 4)
        out["frames"].append((nf, _best_of(lambda sc=sc, A=A: sums_numba(sc, A, np.full(1000, 1000)),
                                           rep)))
    print("\n3. Fused evaluation of a whole population (1 frame, pop 1000, n 1000 unless varied)")
    for key, label in (("n", "points per frame n"), ("pop", "population"),
                       ("frames", "frames")):
        xs = np.array([x for x, _ in out[key]], float)
        ts = np.array([t for _, t in out[key]])
        slope = np.polyfit(np.log(xs), np.log(ts), 1)[0]
        cells = "  ".join(f"{int(x)}: {t * 1e3:.1f} ms" for x, t in out[key])
        print(f"   {label:<20} {cells}   (log-log slope {slope:.2f})")
    if png:
        import matplotlib
        import matplotlib.ticker

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
        for ax, (key, label) in zip(axes, (("n", "points per frame n"), ("pop", "population"),
                                           ("frames", "frames"))):
            xs = np.array([x for x, _ in out[key]], float)
            ts = np.array([t for _, t in out[key]]) * 1e3
            ax.loglog(xs, ts, "o-", label="measured")
            ax.loglog(xs, ts[0] * xs / xs[0], ":", color="0.5", label="linear")
            ax.set_xticks(xs, [f"{int(x)}" for x in xs])
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
            ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
            ax.set_xlabel(label)
            ax.set_ylabel("fused evaluation time (ms)")
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize=8)
        fig.suptitle("paretocal fused kernel scaling on KITTI frames (2 cores)", fontsize=10)
        fig.tight_layout()
        Path(png).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(png, dpi=110)
        print(f"   wrote {png}")
    return out


def features(frames, settings):
    """Section 4: feature extraction per frame."""
    from paretocal.features import image_features, lidar_features, prepare_frame
    from paretocal.lidar.rings import recover_rings

    f = frames[0]
    s = settings
    parts = {
        "edges + distance transform": lambda: image_features(f.image),
        "rings": lambda: recover_rings(f.points),
        "LiDAR edges (incl. rings)": lambda: lidar_features(f.points),
        "whole frame (prepare_frame)": lambda: prepare_frame(
            f, f.T_ref, s.features, s.objective, np.random.default_rng(0)),
    }
    print(f"\n4. Feature extraction, one frame ({len(f.points)} points, "
          f"{f.image.shape[1]}x{f.image.shape[0]} image)")
    out = {}
    for name, fn in parts.items():
        out[name] = _best_of(fn, 5)
        print(f"   {name:<30} {out[name] * 1e3:7.1f} ms")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repetitions, no full runs")
    ap.add_argument("--png", default=None, help="write the scaling plot here")
    ap.add_argument("--json", default=None, help="write all figures here")
    ap.add_argument("--stages", action="store_true",
                    help="only section 0: the default 20-frame run by stage")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--frames", default="0", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(_child(args.child, args.frames)))
        return 0

    from paretocal import Settings, load_frames

    settings = Settings()
    frames = load_frames(DRIVE)
    import numba

    print(f"paretocal speed benchmark: {os.cpu_count()} CPUs, numba threads "
          f"{numba.get_num_threads()}, data {DRIVE}")
    if args.stages:
        res = {"default_run": default_run()}
        if args.json:
            Path(args.json).write_text(json.dumps(res, indent=1, default=float))
        return 0
    res = {"default_run": default_run(),
           "evaluators": evaluators(frames, settings, quick=args.quick),
           "camera_models": camera_models(frames, settings, quick=args.quick),
           "kernel_limits": kernel_limits(frames, settings, quick=args.quick),
           "overhead_ms": optimiser_overhead(quick=args.quick),
           "paper_scale": paper_scale(quick=args.quick),
           "scaling": scaling(frames, settings, args.png, quick=args.quick),
           "features": features(frames, settings)}
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
