"""Ego-motion from the aiMotive sweep sequence: speed per frame pair, conditioning, de-skew gain.

    .venv/bin/python benchmarks/motion.py [--frames 0:20] [--points 15000] [--per-frame]
                                          [--seed 0] [--json [FILE]]

Reads the aiMotive clouds (``$PARETOCAL_DATA/aimotive/points/*.pcd``, default ../shared/data
beside the project; 100 ms Hesai Pandar64 revolutions with per-point times, not
motion-compensated) and runs :func:`paretocal.lidar.motion.estimate_motion` on them. It prints, per
consecutive pair: the velocity and yaw rate from the registration, the standard error of the
forward speed from the registration's own information matrix, the share of the translation
constraint along x, y and z, the smallest eigenvalue of the translation information with its
direction, and the median nearest-neighbour distance between the two clouds, raw and de-skewed.
Then the mean speed, its spread across pairs and standard error, the yaw rate, the wall time
(reading and estimating), and the residual improvement.

The data README's speed (30.2 m/s, measured by registering clouds 0.4 s apart) is printed next
to the estimate as an independent check; the estimate does not use it. ``--json`` writes the
figures as JSON (to FILE, or to standard output without one). Figures made from these data
credit the aiMotive dataset (Matuszka et al., arXiv:2211.09445, CC BY-NC-SA 4.0).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from paretocal.io.clouds import read_cloud
from paretocal.lidar.motion import estimate_motion

DATA = Path(os.environ.get("PARETOCAL_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))
POINTS = DATA / "aimotive" / "points"
#: The speed aimotive/README.md reports for this drive: a check printed beside the estimate.
README_SPEED = 30.2


def load(paths: list[Path]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Points (N, 3) float64 and per-point times (N,) s of each sweep file."""
    out = []
    for p in paths:
        cloud = read_cloud(p)
        if cloud.time is None:
            raise SystemExit(f"{p}: no per-point time field; the sweep cannot be de-skewed")
        out.append((cloud.points[:, :3].astype(np.float64), cloud.time))
    return out


def _slice(text: str) -> slice:
    parts = [int(v) if v else None for v in text.split(":")]
    return slice(*parts)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", default="0:20", help="python slice of the sorted sweeps (0:20)")
    ap.add_argument("--points", type=int, default=15000, help="registration points per sweep")
    ap.add_argument("--per-frame", action="store_true", help="de-skew each frame with its own twist")
    ap.add_argument("--seed", type=int, default=0, help="seed of the voxel and residual sampling")
    ap.add_argument("--json", nargs="?", const="-", default=None, metavar="FILE",
                    help="write the figures as JSON to FILE (standard output without FILE)")
    args = ap.parse_args(argv)

    paths = sorted(POINTS.glob("*.pcd"))[_slice(args.frames)]
    if len(paths) < 2:
        raise SystemExit(f"need at least two sweeps in {POINTS} (frames {args.frames})")
    t0 = time.perf_counter()
    clouds = load(paths)
    t_read = time.perf_counter() - t0
    t0 = time.perf_counter()
    est = estimate_motion(clouds, points=args.points, per_frame=args.per_frame, seed=args.seed)
    t_est = time.perf_counter() - t0

    out = sys.stderr if args.json == "-" else sys.stdout
    v, w = est.pair_twists[:, :3], est.pair_twists[:, 3:]
    speed = np.linalg.norm(v, axis=1)
    print(f"aiMotive {POINTS}: {len(paths)} sweeps, {sum(len(x) for x, _ in clouds)} points, "
          f"frames {paths[0].stem} .. {paths[-1].stem}", file=out)
    print(f"{'pair':>13} {'|v| m/s':>8} {'vx':>7} {'vy':>6} {'vz':>6} {'yaw r/s':>8} "
          f"{'se vx':>6} {'share x':>7} {'y':>5} {'z':>5} {'min eig':>8} {'weakest':>19} "
          f"{'raw m':>6} {'deskew':>6}", file=out)
    for k in range(len(paths) - 1):
        ax = est.weakest_axis[k]
        print(f"{paths[k].stem}-{paths[k + 1].stem[-2:]:>2} {speed[k]:8.3f} {v[k, 0]:7.3f} "
              f"{v[k, 1]:6.2f} {v[k, 2]:6.2f} {w[k, 2]:8.4f} {est.pair_se[k, 0]:6.3f} "
              f"{est.share[k, 0]:7.3f} {est.share[k, 1]:5.3f} {est.share[k, 2]:5.3f} "
              f"{est.min_eigenvalue[k]:8.2e} ({ax[0]:5.2f},{ax[1]:5.2f},{ax[2]:5.2f}) "
              f"{est.residual_raw[k]:6.3f} {est.residual[k]:6.3f}", file=out)
    gain = 1.0 - np.median(est.residual) / np.median(est.residual_raw)
    rel = 100 * (est.speed / README_SPEED - 1)
    print(f"speed {est.speed:.3f} m/s (README {README_SPEED}: {rel:+.2f} %), "
          f"spread {est.speed_spread:.3f} m/s across {len(speed)} pairs, standard error "
          f"{est.speed_sem:.3f} m/s; registration's own se of vx {np.median(est.pair_se[:, 0]):.3f} m/s",
          file=out)
    print(f"v = ({est.twist.v[0]:.3f}, {est.twist.v[1]:.3f}, {est.twist.v[2]:.3f}) m/s, "
          f"yaw rate {est.twist.w[2]:+.4f} rad/s ({np.degrees(est.twist.w[2]):+.3f} deg/s), "
          f"spread {np.std(w[:, 2], ddof=1):.4f} rad/s", file=out)
    print(f"conditioning: median share x/y/z {np.median(est.share, axis=0).round(3).tolist()}, "
          f"observable {est.observable.tolist()} (min share {est.min_share}), compensable "
          f"{est.compensable}; weakest axis x-component >= {np.abs(est.weakest_axis[:, 0]).min():.3f}",
          file=out)
    print(f"residual (median NN distance): raw {np.median(est.residual_raw):.3f} m, de-skewed "
          f"{np.median(est.residual):.3f} m ({100 * gain:.1f} % lower), better in "
          f"{int((est.residual < est.residual_raw).sum())}/{len(speed)} pairs", file=out)
    print(f"wall time: read {t_read:.2f} s, estimate {t_est:.2f} s ({est.iterations} passes, "
          f"converged {est.converged}, voxel {np.median(est.voxel):.2f} m)", file=out)

    if args.json is not None:
        doc = {"frames": [p.stem for p in paths], "points_per_sweep": args.points,
               "per_frame": args.per_frame, "seed": args.seed, "read_s": t_read,
               "estimate_s": t_est, "readme_speed_mps": README_SPEED,
               "residual_gain": float(gain), **est.summary()}
        text = json.dumps(doc, indent=1)
        if args.json == "-":
            print(text)
        else:
            Path(args.json).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
