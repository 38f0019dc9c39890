"""Peak memory and time on a very large point cloud, against one normal KITTI scan, in one run.

    .venv/bin/python benchmarks/memory.py [--cloud concat|repeat] [--scans 18] [--pop 16] [--gens 3]
                                          [--json runs/memory.json]

Builds two generic-layout folders (docs/conventions.md section 2c) in a temporary directory, each with one
frame: the first KITTI scan alone (about 114 000 points), and a cloud of about 2 million points
(``concat``: the first 18 scans concatenated, about 2.04 M points; ``repeat``: the first scan
repeated 18 times with 1 cm Gaussian jitter). For each, in a fresh process:

1. the feature extraction (``prepare_features``) alone, its time and its tracemalloc peak (the
   largest total of the arrays it held at once: numpy reports its buffers to tracemalloc);
2. a short calibration through the command line (``paretocal calibrate --pop 16 --gens 3
   --no-figures``), its wall time, and the process's peak RSS (``getrusage``), also above the
   RSS of the process right after importing paretocal.

It prints a table with the ratios large / normal. The sample data are read in place
(``$PARETOCAL_DATA`` or ../shared/data beside the project); nothing is written to the project.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DATA = Path(os.environ.get("PARETOCAL_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))
DRIVE = DATA / "kitti_raw" / "2011_09_26"


def _rss_mb() -> float:
    """Peak resident set size of this process so far, MB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def build_folder(root: Path, cloud: str, scans: int, seed: int = 0) -> dict:
    """A generic folder with one frame: the first scan (``scans == 1``) or a large cloud."""
    import numpy as np
    import yaml

    from paretocal.io import load_frames

    frames = load_frames(DRIVE, f"0:{max(scans, 1) if cloud == 'concat' else 1}")
    f0 = frames[0]
    if scans <= 1:
        pts = f0.points
    elif cloud == "concat":
        pts = np.vstack([f.points for f in frames[:scans]])
    else:
        rng = np.random.default_rng(seed)
        pts = np.vstack([f0.points] * scans)
        pts[:, :3] += rng.normal(0.0, 0.01, (len(pts), 3)).astype(np.float32)
    (root / "images").mkdir(parents=True)
    (root / "points").mkdir()
    import cv2

    cv2.imwrite(str(root / "images" / "000000.png"), f0.image)
    pts.astype(np.float32).tofile(root / "points" / "000000.bin")
    (root / "calib.yaml").write_text(yaml.safe_dump({
        "camera": {"K": f0.camera.K.tolist(), "width": f0.camera.width,
                   "height": f0.camera.height},
        "T_cam_lidar": f0.T_ref.tolist()}))
    return {"points": int(len(pts)), "bytes": int(pts.nbytes)}


def child(folder: Path, out: Path, pop: int, gens: int) -> dict:
    """Measure one folder in this (fresh) process; returns the figures."""
    import tracemalloc

    import paretocal.pipeline  # noqa: F401  (import everything before the baseline)
    from paretocal.cli import main
    from paretocal.config import Settings
    from paretocal.io import load_frames
    from paretocal.pipeline import prepare_features

    base = _rss_mb()
    frames = load_frames(folder)
    tracemalloc.start()
    t0 = time.perf_counter()
    feats = prepare_features(frames, frames[0].T_ref, Settings())
    feat_s = time.perf_counter() - t0
    _, feat_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    n_feat = int(len(feats[0].xyz))
    del frames, feats
    t0 = time.perf_counter()
    code = main(["calibrate", str(folder), "--out", str(out), "--pop", str(pop), "--gens",
                 str(gens), "--no-figures", "--checkpoint-every", "0", "--quiet"])
    wall = time.perf_counter() - t0
    if code != 0:
        raise SystemExit(f"calibrate exited {code}")
    doc = json.loads((out / "result.json").read_text())
    return {"baseline_rss_mb": base, "features_s": feat_s,
            "features_tracemalloc_peak_mb": feat_peak / 2**20, "feature_points": n_feat,
            "calibrate_s": wall, "peak_rss_mb": _rss_mb(), "n_range": doc["n_range"],
            "evaluations": doc["evaluations"]}


def measure(folder: Path, out: Path, pop: int, gens: int) -> dict:
    """Run :func:`child` in a fresh interpreter so that each peak RSS is its own."""
    r = subprocess.run([sys.executable, __file__, "--child", str(folder), "--child-out", str(out),
                        "--pop", str(pop), "--gens", str(gens)], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"measuring {folder} failed:\n{r.stderr}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cloud", choices=("concat", "repeat"), default="concat")
    ap.add_argument("--scans", type=int, default=18, help="scans making the large cloud")
    ap.add_argument("--pop", type=int, default=16)
    ap.add_argument("--gens", type=int, default=3)
    ap.add_argument("--json", type=Path, help="also write the figures here")
    ap.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--child-out", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child is not None:
        print(json.dumps(child(args.child, args.child_out, args.pop, args.gens)))
        return
    rows = {}
    with tempfile.TemporaryDirectory(prefix="paretocal-memory-") as tmp:
        tmp = Path(tmp)
        for name, scans in (("one scan", 1), ("large", args.scans)):
            folder = tmp / name.replace(" ", "_")
            info = build_folder(folder, args.cloud, scans)
            rows[name] = {**info, **measure(folder, tmp / f"run_{folder.name}", args.pop,
                                            args.gens)}
    one, big = rows["one scan"], rows["large"]
    print(f"paretocal memory benchmark: --cloud {args.cloud}, --pop {args.pop} --gens {args.gens}")
    print(f"{'':34s}{'one scan':>12s}{'large':>12s}{'ratio':>9s}")

    def line(label, key, fmt="{:.0f}"):
        a, b = one[key], big[key]
        print(f"{label:34s}{fmt.format(a):>12s}{fmt.format(b):>12s}{b / a:>8.1f}x")

    for r in (one, big):
        r["cloud_mb"] = r["bytes"] / 2**20
    line("points", "points")
    line("cloud size (MB)", "cloud_mb", "{:.1f}")
    line("feature points kept", "feature_points")
    line("features: time (s)", "features_s", "{:.2f}")
    line("features: tracemalloc peak (MB)", "features_tracemalloc_peak_mb", "{:.0f}")
    line("calibrate: wall time (s)", "calibrate_s", "{:.1f}")
    line("calibrate: peak RSS (MB)", "peak_rss_mb", "{:.0f}")
    for r in (one, big):
        r["rss_above_baseline_mb"] = r["peak_rss_mb"] - r["baseline_rss_mb"]
    line("  above the RSS after imports (MB)", "rss_above_baseline_mb", "{:.0f}")
    print(f"large cloud: {big['features_tracemalloc_peak_mb'] / big['cloud_mb']:.1f} MB of "
          "feature-extraction arrays per MB of cloud at the peak")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"cloud": args.cloud, "pop": args.pop, "gens": args.gens,
                                         "cases": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
