"""Accuracy from random decalibrations on the sample KITTI drive (library API).

Each trial perturbs the dataset's extrinsic by a seeded random correction, uniform per axis in
+-ROT deg and +-TRANS m, runs the default calibration from it and compares the chosen
extrinsic (and the front's most expensive solution) with KITTI's reference.

    .venv/bin/python benchmarks/accuracy.py --trials 10 --rot 5 --trans 0.2 [--frames 0:20]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from paretocal import Settings, calibrate, load_frames
from paretocal.geometry import correction_matrix

DATA = Path(os.environ.get("PARETOCAL_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--rot", type=float, default=5.0, help="per-axis bound, deg")
    ap.add_argument("--trans", type=float, default=0.2, help="per-axis bound, m")
    ap.add_argument("--frames", default=None, help="frame selection, e.g. 0:10")
    ap.add_argument("--config", default=None, help="settings file (YAML/JSON by section)")
    ap.add_argument("--json", default=None, help="also write the trials to this JSON file")
    args = ap.parse_args()

    from paretocal.config import load_settings

    settings = load_settings(args.config) if args.config else Settings()
    frames = load_frames(DATA / "kitti_raw" / "2011_09_26", args.frames)
    T_ref = frames[0].T_ref
    rows = []
    for k in range(args.first_seed, args.first_seed + args.trials):
        rng = np.random.default_rng(1000 + k)
        p = np.r_[rng.uniform(-args.trans, args.trans, 3), rng.uniform(-args.rot, args.rot, 3)]
        t0 = time.perf_counter()
        r = calibrate(frames, T_ref @ correction_matrix(p), settings)
        e, e0, c = r.reference_error, r.initial_error, r.front.columns
        dear = int(np.argmax(r.front.X[:, 6]))
        row = {"trial": k, "start_deg": e0["rotation_deg"], "start_cm": e0["translation_cm"],
               "rot_deg": e["rotation_deg"], "trans_cm": e["translation_cm"],
               "n": r.n_points, "n_max_rot_deg": float(c["ref_rotation_deg"][dear]),
               "n_max_trans_cm": float(c["ref_translation_cm"][dear]),
               "front": len(r.front.X), "n_span": [int(r.front.X[:, 6].min()),
                                                   int(r.front.X[:, 6].max())],
               "wall_s": time.perf_counter() - t0}
        rows.append(row)
        print(f"trial {k:3d}: start {row['start_deg']:5.2f} deg {row['start_cm']:5.1f} cm -> "
              f"{row['rot_deg']:.3f} deg {row['trans_cm']:.2f} cm (n = {row['n']}; largest n: "
              f"{row['n_max_rot_deg']:.3f} deg {row['n_max_trans_cm']:.2f} cm) "
              f"{row['wall_s']:.0f} s", flush=True)
    R = np.array([[r["rot_deg"], r["trans_cm"]] for r in rows])
    ok = np.sum((R[:, 0] < 0.3) & (R[:, 1] < 3.0))
    ok1 = np.sum((R[:, 0] < 1.0) & (R[:, 1] < 10.0))
    print(f"summary: {len(rows)} trials, frames {args.frames or 'all'}, start +-{args.rot} deg "
          f"+-{args.trans} m per axis\n"
          f"  rotation deg: median {np.median(R[:, 0]):.3f}, mean {R[:, 0].mean():.3f}, "
          f"max {R[:, 0].max():.3f}\n"
          f"  translation cm: median {np.median(R[:, 1]):.2f}, mean {R[:, 1].mean():.2f}, "
          f"max {R[:, 1].max():.2f}\n"
          f"  within 0.3 deg and 3 cm: {ok}/{len(rows)}; within 1 deg and 10 cm: {ok1}/{len(rows)}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
