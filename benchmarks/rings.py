"""Ring recovery on rig variants of the KITTI drive: the share of points given their true ring.

    .venv/bin/python benchmarks/rings.py [--frames 0:20] [--json [FILE]]

Every sweep of the KITTI raw sample (HDL-64E, stored ring by ring) is turned at run time into
the rig variants of :mod:`paretocal.testing` (32 and 16 beams, firing order, shuffled order, a
vehicle frame with the sensor 1.5 m from the origin and tilted). For each the rings are
recovered as ``paretocal calibrate`` does without a ring field (``auto``): for the vehicle frame
the LiDAR's pose is first estimated from the sweep
(:func:`paretocal.lidar.sensor.estimate_sensor_pose`), as when ``calib.yaml`` has no
``lidar_pose``. Printed per variant: the share of points on their true ring (min and median over
the frames), the rings found, the method used, and the time per sweep. ``--json`` writes the
figures as JSON (to FILE, or alone to standard output without one, the table then on stderr).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from paretocal import testing as T  # noqa: E402
from paretocal.lidar.rings import recover_rings  # noqa: E402
from paretocal.lidar.sensor import estimate_sensor_pose  # noqa: E402
from paretocal.io.layouts import load_frames  # noqa: E402

VARIANTS = {
    "scan order (64)": lambda v, k: v,
    "32 beams": lambda v, k: T.decimate(v, 2),
    "16 beams": lambda v, k: T.decimate(v, 4),
    "firing order (64)": lambda v, k: T.firing_order(v),
    "firing order, 16 beams": lambda v, k: T.firing_order(T.decimate(v, 4)),
    "vehicle frame, pose estimated": lambda v, k: T.to_vehicle_frame(T.firing_order(v)),
    "shuffled (64)": lambda v, k: T.shuffled(v, k),
    "shuffled, 16 beams": lambda v, k: T.shuffled(T.decimate(v, 4), k),
}


def _recover(v, seed: int):
    pts = v.points
    if not np.allclose(v.sensor_pose, np.eye(4)):
        est = estimate_sensor_pose(pts, rng=seed)
        if est is None or not est.ok:
            return None
        pts = est.to_sensor(pts)
    return recover_rings(pts, "auto", rng=seed)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", default="0:20")
    ap.add_argument("--json", nargs="?", const="-", default=None)
    args = ap.parse_args(argv)
    import os
    data = Path(os.environ.get("PARETOCAL_DATA", ROOT.parent / "shared" / "data"))
    frames = load_frames(data / "kitti_raw" / "2011_09_26", args.frames)
    rows = {}
    # With --json and no file the JSON alone goes to standard output, the table to stderr.
    out = sys.stderr if args.json == "-" else sys.stdout
    print(f"{'variant':32s} {'min':>7s} {'median':>7s} {'rings':>9s}  method   s/sweep", file=out)
    for name, make in VARIANTS.items():
        acc, n, methods, dt = [], set(), set(), []
        for k, f in enumerate(frames):
            v = make(T.kitti_truth(f.points), k)
            t0 = time.perf_counter()
            r = _recover(v, k)
            dt.append(time.perf_counter() - t0)
            if r is None:
                acc.append(0.0)
                methods.add("no pose")
                continue
            acc.append(T.ring_accuracy(r.ring, v.ring))
            n.add(int(r.n_rings))
            methods.add(r.method)
        rows[name] = {"min": min(acc), "median": float(np.median(acc)), "n_rings": sorted(n),
                      "methods": sorted(methods), "s_per_sweep": float(np.median(dt)),
                      "frames": len(frames)}
        print(f"{name:32s} {100 * min(acc):6.2f}% {100 * np.median(acc):6.2f}% "
              f"{','.join(map(str, sorted(n))):>9s}  {','.join(sorted(methods)):8s} "
              f"{np.median(dt):.2f}", file=out, flush=True)
    if args.json:
        text = json.dumps(rows, indent=1)
        if args.json == "-":
            print(text)
        else:
            Path(args.json).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
