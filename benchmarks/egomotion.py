"""Ego-motion of both sensors: LiDAR odometry (own ICP and KISS-ICP) against camera visual odometry.

    .venv/bin/python benchmarks/egomotion.py [--sets kitti,aimotive,pandaset] [--strides 1,5]
                                             [--methods own,kiss-icp] [--pairs] [--json [FILE]]

For every development set (``$PARETOCAL_DATA``, default ../shared/data beside the project) it
reads the frames, de-skews the sweeps that carry per-point time (the pipeline's
:func:`paretocal.inputs.compensate_motion`), runs :func:`paretocal.egomotion.lidar_odometry`
with each method and :func:`paretocal.egomotion.camera_odometry` on image pairs ``(k, k + s)``
for each stride ``s``, and prints:

* per method: the time per pair, the translation per pair (median, min, max), the standing
  pairs, and how far the two methods' pair poses lie apart (translation, rotation);
* per stride: the angle between the camera's direction of travel and the LiDAR's mapped through
  the reference extrinsic (``frames[0].T_ref``), median and maximum over the pairs that give
  both, the rotation-angle difference of the two relative rotations, the camera's bootstrap
  direction uncertainty, the pairs without a direction and why (``--pairs``: every pair);
* per stride and method, the rotation from motion (:func:`paretocal.egomotion.rotation_from_motion`)
  from 8 seeded initial rotations 20 deg off the reference about random axes (the lever arm
  taken with the reference's translation, uncertain by 1.5 m per axis): its error on the angles
  the motion observes (the error about a free axis taken off), whether an axis stays free, and
  the reversed camera directions it dropped;
* a check beside an independent figure where the data give one: aiMotive's speed (30.2 m/s in
  its README, 4.03 m per 0.1333 s pair), PandaSet's standing frames 00-24 (indices 0-12; its
  README), whose pairs must come out standing.

Figures made from a set credit its source: KITTI (Geiger et al., IJRR 2013, CC BY-NC-SA 3.0),
aiMotive (Matuszka et al., arXiv:2211.09445, CC BY-NC-SA 4.0), PandaSet (Xiao et al., ITSC 2021,
by Scale AI and Hesai).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from pathlib import Path

import numpy as np

from paretocal.config import Settings
from paretocal.egomotion import (camera_odometry, compare_motion, lidar_odometry,
                                 rotation_angle_deg, rotation_from_motion)
from paretocal.inputs import compensate_motion
from paretocal.io.layouts import load_frames

DATA = Path(os.environ.get("PARETOCAL_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))

#: name -> (folder under DATA, frames, description)
SETS = {
    "kitti": ("kitti_raw/2011_09_26", None, "KITTI raw drive, 20 frames at 10 Hz"),
    "aimotive": ("aimotive/front_pinhole", None, "aiMotive night motorway, front pinhole"),
    "aimotive_fisheye": ("aimotive/left_fisheye", None, "aiMotive night motorway, left Mei fisheye"),
    "pandaset": ("pandaset/front", None, "PandaSet 002, front camera"),
    "pandaset_left": ("pandaset/front_left", None, "PandaSet 002, front-left camera"),
}
#: aimotive/README.md: 30.2 m/s, pairs 0.1333 s apart.
AIMOTIVE_STEP_M = 30.2 * 0.1333
#: pandaset/README.md: the car stands until frame 24 (index 12) and moves from frame 26.
PANDASET_STANDING = 12


def _stats(a) -> dict:
    a = np.asarray(a, dtype=float)
    a = a[np.isfinite(a)]
    if not len(a):
        return {"n": 0}
    return {"n": int(len(a)), "median": round(float(np.median(a)), 4),
            "min": round(float(np.min(a)), 4), "max": round(float(np.max(a)), 4)}


def _rotation_figures(lo, cams, T_ref, starts: int = 8, deg: float = 20.0) -> dict:
    """Rotation from motion from ``starts`` initial rotations ``deg`` off the reference."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    R_ref = T_ref[:3, :3]
    errs, free = [], 0
    mr = None
    for _ in range(starts):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        R0 = Rotation.from_rotvec(np.radians(deg) * axis).as_matrix() @ R_ref
        mr = rotation_from_motion(lo, cams, R0, T_ref[:3, 3], t_sigma_m=1.5)
        e = Rotation.from_matrix(mr.R @ R_ref.T).as_rotvec()
        if mr.free_axis is not None:
            free += 1
            e = e - (e @ mr.free_axis) * mr.free_axis
        errs.append(float(np.degrees(np.linalg.norm(e))))
    return {"observed_error_deg": _stats(errs), "free": free,
            "directions": mr.directions, "turns": mr.turns, "reversed": mr.reversed}


def measure(name: str, strides: list[int], methods: list[str], show_pairs: bool) -> dict:
    folder, spec, desc = SETS[name]
    frames = load_frames(DATA / folder, spec)
    print(f"\n== {name}: {desc}, {len(frames)} frames")
    frames, minfo = compensate_motion(frames, Settings())
    speed = float("nan") if minfo.speed_mps is None else minfo.speed_mps
    print(f"   de-skew: {'yes' if minfo.compensated else 'no'} "
          f"({minfo.reason or 'speed %.2f m/s' % speed})")
    clouds = [f.points[:, :3] for f in frames]
    T_ref = frames[0].T_ref
    out: dict = {"frames": len(frames), "methods": {}, "strides": {}}
    odo = {}
    for m in methods:
        t0 = time.perf_counter()
        lo = lidar_odometry(clouds, method=m)
        wall = time.perf_counter() - t0
        odo[m] = lo
        rec = {"method_used": lo.method, "note": lo.note,
               "seconds_per_pair": round(float(np.mean(lo.seconds)), 4),
               "wall_s_with_covariance": round(wall, 2),
               "translation_m": _stats(lo.translation_m),
               "translation_sigma_cm": _stats(100 * lo.translation_sigma_m),
               "direction_sigma_deg": _stats(lo.direction_sigma_deg),
               "standing_pairs": [k for k in range(len(lo.standing)) if lo.standing[k]]}
        out["methods"][m] = rec
        print(f"   LiDAR {m:8s} ({lo.method}): {rec['seconds_per_pair']:.3f} s/pair "
              f"({wall:.1f} s with covariances), |t| per pair {rec['translation_m']}, "
              f"sigma along t {rec['translation_sigma_cm']} cm, direction sigma "
              f"{rec['direction_sigma_deg']} deg, standing pairs {rec['standing_pairs']}"
              + (f"; note: {lo.note}" if lo.note else ""))
        if name == "aimotive" or name == "aimotive_fisheye":
            step = lo.translation_m
            print(f"     check: {np.median(step):.3f} m per pair against {AIMOTIVE_STEP_M:.3f} m "
                  "(README speed)")
        if name.startswith("pandaset"):
            st = lo.standing[:PANDASET_STANDING]
            print(f"     check: {int(st.sum())} of {len(st)} pairs within frames 00-24 standing "
                  f"(README: the car stands); moving from index {PANDASET_STANDING}: "
                  f"{int((~lo.standing[PANDASET_STANDING:]).sum())} of "
                  f"{len(lo.standing) - PANDASET_STANDING} pairs")
            for k in range(min(PANDASET_STANDING, len(st))):
                if show_pairs or not st[k]:
                    print(f"       pair {k}: |t| {100 * lo.translation_m[k]:.1f} cm, "
                          f"Mahalanobis {lo.mahalanobis[k]:.1f} {lo.reasons[k] or 'moving'}")
    if len(odo) == 2:
        a, b = (odo[m] for m in methods)
        dt = [float(np.linalg.norm(x[:3, 3] - y[:3, 3])) for x, y in zip(a.pair_poses, b.pair_poses)]
        dr = [rotation_angle_deg(x[:3, :3].T @ y[:3, :3]) for x, y in zip(a.pair_poses, b.pair_poses)]
        out["methods_apart"] = {"translation_cm": _stats(100 * np.array(dt)), "rotation_deg": _stats(dr)}
        apart = out["methods_apart"]
        print(f"   {methods[0]} vs {methods[1]}: pair translations apart {apart['translation_cm']} "
              f"cm, rotations apart {apart['rotation_deg']} deg")
    K = len(frames)
    images = [f.image for f in frames]
    for s in strides:
        if s >= K:
            continue
        pairs = [(k, k + s) for k in range(K - s)]
        t0 = time.perf_counter()
        cams = camera_odometry(images, frames[0].camera, pairs=pairs, mask=frames[0].mask)
        wall = time.perf_counter() - t0
        rec = {"camera_seconds_per_pair": round(float(np.mean([c.seconds for c in cams])), 4),
               "camera_wall_s": round(wall, 2),
               "inliers": _stats([c.inliers for c in cams]),
               "parallax_px": _stats([c.parallax_px for c in cams]),
               "camera_direction_sigma_deg": _stats([c.direction_sigma_deg for c in cams if c.ok]),
               "no_direction": {f"{c.i}-{c.j}": c.reason for c in cams if not c.ok}}
        print(f"   camera stride {s}: {len(pairs)} pairs, {rec['camera_seconds_per_pair']:.2f} s/pair "
              f"(features included: {wall / len(pairs):.2f} s), inliers {rec['inliers']}, parallax "
              f"{rec['parallax_px']} px, bootstrap direction sigma {rec['camera_direction_sigma_deg']} deg, "
              f"{len(rec['no_direction'])} pairs without a direction")
        for m, lo in odo.items():
            ag = compare_motion(lo, cams, T_ref)
            d, r = _stats(ag.direction_deg), _stats(ag.rotation_deg)
            rec[m] = {"direction_deg": d, "rotation_deg": r,
                      "lidar_rotation_deg": _stats(ag.lidar_rotation_deg),
                      "camera_rotation_deg": _stats(ag.camera_rotation_deg)}
            print(f"     {m:8s}: direction camera vs LiDAR {d} deg; rotation difference {r} deg "
                  f"(LiDAR turns {rec[m]['lidar_rotation_deg'].get('median', float('nan'))} deg median)")
            rm = _rotation_figures(lo, cams, T_ref)
            rec[m]["rotation_from_motion"] = rm
            print(f"       rotation from motion, 8 starts 20 deg off: observed angles off by "
                  f"{rm['observed_error_deg']} deg; free axis in {rm['free']} of 8; "
                  f"{rm['directions']} directions and {rm['turns']} turns used, "
                  f"{rm['reversed']} reversed camera directions dropped")
            if name.startswith("pandaset"):
                st = [k for k, c in enumerate(cams) if c.j <= PANDASET_STANDING]
                none = [k for k in st if not np.isfinite(ag.direction_deg[k])]
                rec[m]["standing_pairs_without_direction"] = f"{len(none)} of {len(st)}"
                print(f"       check: {len(none)} of {len(st)} pairs within frames 00-24 give no "
                      "direction (camera and LiDAR together)")
            if show_pairs:
                for k, c in enumerate(cams):
                    print(f"       {c.i:2d}-{c.j:2d}: dir {ag.direction_deg[k]:6.2f} rot "
                          f"{ag.rotation_deg[k]:.3f} (cam {ag.camera_rotation_deg[k]:.3f}, lidar "
                          f"{ag.lidar_rotation_deg[k]:.3f}) inl {c.inliers} par {c.parallax_px:.1f} "
                          f"px noise {c.noise_px:.2f} px sigma {c.direction_sigma_deg:.2f} deg "
                          f"{ag.reasons[k]}")
        if not show_pairs:
            for key, why in list(rec["no_direction"].items())[:5]:
                print(f"       no direction {key}: {why}")
        out["strides"][s] = rec
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", default="kitti,aimotive,pandaset")
    ap.add_argument("--strides", default="1,5", help="image pair strides, comma-separated")
    ap.add_argument("--methods", default="own,kiss-icp")
    ap.add_argument("--pairs", action="store_true", help="print every pair")
    ap.add_argument("--json", nargs="?", const="-", help="write the figures as JSON")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    strides = [int(s) for s in a.strides.split(",")]
    methods = a.methods.split(",")
    res = {}
    for name in a.sets.split(","):
        if name not in SETS:
            ap.error(f"unknown set {name!r}; one of {', '.join(SETS)}")
        if not (DATA / SETS[name][0]).exists():
            print(f"\n== {name}: {DATA / SETS[name][0]} not found, skipped")
            continue
        res[name] = measure(name, strides, methods, a.pairs)
    if a.json:
        text = json.dumps(res, indent=1, default=str)
        if a.json == "-":
            print(text)
        else:
            Path(a.json).write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
