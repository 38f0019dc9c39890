"""The wide start alone (paretocal.wide): where it lands and what each step costs.

For seeded starts drawn like ``benchmarks/accuracy.py`` (per axis uniform in +-ROT deg and
+-TRANS m about the reference), after the LiDAR steps a calibration does (LiDAR pose, rings,
de-skew), runs :func:`paretocal.wide.wide_start` with that error stated and prints, per start,
the start's and the result's distance from the reference, the rounds, what was kept (edges or
photo-consistency), ambiguity, and the wall time of each step (odometry of both sensors, the
photo map, the search, the polish). This is the fast loop for work on the wide start: no
calibration follows. ::

    PARETOCAL_DATA=../shared/data .venv/bin/python benchmarks/wide.py --trials 5
    .venv/bin/python benchmarks/wide.py --source DATA/pandaset/front --trials 3 --json out.json

The seeds are those of ``benchmarks/accuracy.py`` (1000 + trial), so a trial here is the wide
start of the same trial there.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from paretocal.config import Settings
from paretocal.geometry import decalibrate, pose_error
from paretocal.inputs import prepare_lidar
from paretocal.io import load_frames
from paretocal.wide import wide_start

DATA = Path(os.environ.get("PARETOCAL_DATA", Path(__file__).resolve().parents[1].parent
                           / "shared" / "data"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--source", default=None,
                    help="dataset folder ('DATA/' is the data folder; default the KITTI drive)")
    ap.add_argument("--frames", default=None, help="frame selection, e.g. 0:10")
    ap.add_argument("--trials", type=int, default=5)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--rot", type=float, default=20.0, help="per-axis bound, deg")
    ap.add_argument("--trans", type=float, default=1.5, help="per-axis bound, m")
    ap.add_argument("--json", default=None, help="also write the trials here")
    args = ap.parse_args(argv)
    src = (DATA / "kitti_raw" / "2011_09_26" if args.source is None
           else Path(args.source.replace("DATA/", f"{DATA}/", 1)))
    frames = load_frames(src, args.frames, 2)
    T_ref = frames[0].T_ref
    if T_ref is None:
        print(f"{src}: no reference extrinsic to compare with", file=sys.stderr)
        return 2
    settings = Settings().replace(search={"init_error_deg": args.rot,
                                          "init_error_m": args.trans, "wide": "on"})
    t0 = time.perf_counter()
    steps = prepare_lidar(frames, settings, [(frames[0].camera, T_ref)])
    print(f"{src} ({len(frames)} frames): LiDAR steps {time.perf_counter() - t0:.1f} s")
    rows = []
    for k in range(args.first_seed, args.first_seed + args.trials):
        T0 = decalibrate(T_ref, args.rot, args.trans, 1000 + k)[0]
        t1 = time.perf_counter()
        w = wide_start(steps.frames, T0, settings, steps.rings)
        wall = time.perf_counter() - t1
        e0 = pose_error(T0, T_ref)
        e = pose_error(w.T, T_ref) if w.applied else None
        row = {"trial": k, "start_deg": float(e0["rotation_deg"]),
               "start_cm": float(e0["translation_cm"]), "applied": w.applied,
               "deg": None if e is None else float(e["rotation_deg"]),
               "cm": None if e is None else float(e["translation_cm"]),
               "rounds": len(w.rounds), "kept_by": [r["kept"]["by"] for r in w.rounds],
               "ambiguous": w.ambiguous, "disagree": w.disagree, "wall_s": wall,
               "seconds": w.seconds, "evaluations": w.evaluations,
               "reasons": w.to_dict()["reasons"]}
        rows.append(row)
        got = ("not applied: " + "; ".join(w.reasons)) if e is None else (
            f"{row['deg']:.2f} deg {row['cm']:.1f} cm, {row['rounds']} round(s) "
            f"kept by {'/'.join(row['kept_by'])}{', ambiguous' if w.ambiguous else ''}")
        parts = ", ".join(f"{name} {v:.1f}" for name, v in w.seconds.items())
        print(f"trial {k:3d}: start {row['start_deg']:5.1f} deg {row['start_cm']:6.1f} cm -> "
              f"{got}; {wall:.1f} s ({parts}; {w.evaluations} evaluations)", flush=True)
    ok = [r for r in rows if r["deg"] is not None and r["deg"] < 1.0 and r["cm"] < 10.0]
    walls = [r["wall_s"] for r in rows]
    print(f"within 1 deg / 10 cm: {len(ok)}/{len(rows)}; wall median {np.median(walls):.1f} s, "
          f"max {np.max(walls):.1f} s")
    for name in ("odometry", "photo", "search", "polish"):
        v = [r["seconds"].get(name, 0.0) for r in rows]
        print(f"  {name:9s} median {np.median(v):5.1f} s  max {np.max(v):5.1f} s")
    if args.json:
        Path(args.json).write_text(json.dumps({"argv": sys.argv, "source": str(src),
                                               "trials": rows}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
