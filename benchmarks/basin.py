"""The objective's basin at the reference: the fast loop for objective work (no search).

For every development set and camera, with the reference extrinsic as the pose the points are
chosen at, the LiDAR steps a calibration does (LiDAR pose, rings, de-skew) done first:

* **local optimum**: the objective polished from the reference (Newton, then a pattern search,
  every point, no sampling-error charge): how far it moves (deg, cm, and the mean pixel
  displacement of the feature points);
* **basin centre**: the mean of the local optima polished from 8 seeded starts within
  0.5 deg / 5 cm of the reference: the objective is rough at the scale of a pixel, and the
  optimum from one start depends on where it starts;
* **neighbours better**: the share of the 3^6 - 1 grid neighbours of the reference (0.5 deg /
  5 cm steps, as ``paretocal check``) that score lower than the reference (Levinson & Thrun);

for the objective as configured (``all``) and for each feature group alone (``depth``: depth
edges only; ``intensity``: intensity edges only), over all the frames and, with
``--single``, each frame alone (the median and worst over frames).

A correct objective has its local optimum at the reference (a few tenths of a degree, a few cm)
and few neighbours better. ::

    PARETOCAL_DATA=../shared/data .venv/bin/python benchmarks/basin.py
    .venv/bin/python benchmarks/basin.py --sets pandaset_front,kitti_raw --groups all --single
    .venv/bin/python benchmarks/basin.py --config my_objective.yaml --json runs/basin.json

``--config`` takes a settings file (as ``paretocal calibrate --config``), so an objective
variant is measured without touching the defaults.

``--joint SET,SET,...`` also measures the cameras of one rig at once: one correction in the
LiDAR frame shared by every camera (``T_cam_lidar @ D(d)`` for each keeps the camera-to-camera
extrinsics), the objective the sum of the cameras' objectives, each over its own set's frames
and points; local optimum and basin centre as above (the sets must share the LiDAR's clouds
and frame, e.g. PandaSet's three cameras)::

    .venv/bin/python benchmarks/basin.py --sets pandaset_front,pandaset_left,pandaset_front_left \
        --groups all --joint pandaset_front,pandaset_left,pandaset_front_left
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from paretocal.check import NEIGHBOUR_STEP
from paretocal.config import Settings, load_settings
from paretocal.geometry import correction_matrix, pose_error
from paretocal.inputs import prepare_lidar
from paretocal.io import load_frames
from paretocal.quality import (correction_between, displacement_px, local_optimum,
                               neighbour_fraction)
from paretocal.search.polish import newton_polish, polish
from paretocal.stage import Stage

DATA = Path(os.environ.get("PARETOCAL_DATA", Path(__file__).resolve().parents[1].parent
                           / "shared" / "data"))

#: name -> (folder under DATA, frames, camera index). PandaSet's left and front-left share the
#: front camera's points, whose time matches theirs only while the car stands (frames 00-24:
#: indices 0-12), see the data's README.
SETS = {
    "kitti_raw": ("kitti_raw/2011_09_26", None, 2),
    "kitti_object": ("kitti_object/training", None, 2),
    "pandaset_front": ("pandaset/front", None, 2),
    "pandaset_left": ("pandaset/left", "0:13", 2),
    "pandaset_front_left": ("pandaset/front_left", "0:13", 2),
    "aimotive_front": ("aimotive/front_pinhole", None, 2),
    "aimotive_fisheye": ("aimotive/left_fisheye", None, 2),
}

#: Feature groups measured alone: objective settings that keep only that group.
GROUPS = {
    "all": {},
    "depth": {"w_edge": 1.0, "contrast": 0.0},
    "intensity": {"w_edge": 0.0, "contrast": 0.0},
}


#: Starts of the basin's centre: seeded, uniform within these (m, deg) of the reference on
#: every axis. The objective is rough at the scale of a pixel, so the optimum polished from one
#: start depends on where it starts; the mean of several is the basin's centre.
STARTS = 8
START_BOX = np.r_[[0.05] * 3, [0.5] * 3]


def basin(frames, T_ref: np.ndarray, settings: Settings, rings=None) -> dict:
    """The objective's basin at ``T_ref`` on ``frames``: the local optimum polished from
    ``T_ref`` (``deg``, ``cm``, ``px``), the centre of the optima polished from :data:`STARTS`
    starts about it (``centre_deg``, ``centre_cm``) and their median distance from it
    (``spread_deg``, ``spread_cm``: large where the objective is flat), and the share of grid
    neighbours that score better (``better``)."""
    stage = Stage(frames, T_ref, T_ref, settings, rings=rings)
    obj = stage.objective
    x0 = np.zeros(7)
    x0[6] = stage.n_max
    frac, _ = neighbour_fraction(obj, x0, NEIGHBOUR_STEP)
    S = np.tile(x0, (STARTS + 1, 1))
    S[1:, :6] += np.random.default_rng(0).uniform(-1.0, 1.0, (STARTS, 6)) * START_BOX
    Z = local_optimum(obj, S)                       # every start polished in one batch
    d = np.array([correction_between(T_ref, T) for T in obj.transforms(Z)])
    counts = [f.counts() for f in stage.feats]
    return {**_optima(T_ref, d), "px": float(displacement_px(obj, x0, Z[0])),
            "better": float(frac),
            "points_per_frame": {g: round(float(np.mean([c[g] for c in counts])), 1)
                                 for g in counts[0]}}


def _optima(T_ref: np.ndarray, d: np.ndarray) -> dict:
    """The local optima's corrections ``d`` (k, 6) from ``T_ref``, the first polished from
    ``T_ref`` itself: its error, the centre of all k, and their median distance from it."""
    T_opt = [T_ref @ correction_matrix(v) for v in d]
    e = pose_error(T_opt[0], T_ref)
    centre = T_ref @ correction_matrix(d.mean(axis=0))
    c = pose_error(centre, T_ref)
    # How far the optima lie from their centre: where the objective is flat they scatter.
    spread = [pose_error(T, centre) for T in T_opt]
    return {"deg": float(e["rotation_deg"]), "cm": float(e["translation_cm"]),
            "centre_deg": float(c["rotation_deg"]), "centre_cm": float(c["translation_cm"]),
            "spread_deg": float(np.median([e["rotation_deg"] for e in spread])),
            "spread_cm": float(np.median([e["translation_cm"] for e in spread])),
            "correction": [round(float(v), 5) for v in d[0]]}


def load_set(name: str, settings: Settings):
    """A development set's LiDAR steps (its frames after them, rings, LiDAR pose) and its
    reference."""
    folder, spec, cam = SETS[name]
    frames = load_frames(DATA / folder, spec, cam)
    T_ref = frames[0].T_ref
    return prepare_lidar(frames, settings, [(frames[0].camera, T_ref)]), T_ref


def joint_basin(parts: list, settings: Settings) -> dict:
    """The basin of several cameras sharing one LiDAR correction, each at its own pose.

    ``parts``: one ``(frames, T, rings)`` per camera (from :func:`load_set`), ``T`` the
    camera's pose the correction is measured from (the reference). The objective is the sum of
    the cameras' objectives (each at all its points), polished from ``T`` and from the
    :data:`STARTS` starts of :func:`basin` (Newton, then a pattern search, as
    :func:`~paretocal.quality.local_optimum`). Keys as :func:`basin`'s, without ``px`` and
    ``points_per_frame``, with ``value`` (the summed objective at the local optimum); errors
    are those of the first camera (a correction on the right turns and moves every camera
    alike).
    """
    stages = [(Stage(frames, T, T, settings, rings=rings), T) for frames, T, rings in parts]

    def f1(Z):
        total = np.zeros(len(Z))
        for st, _ in stages:
            X = np.array(Z, dtype=np.float64)
            X[:, 6] = st.n_max
            total += st.objective.chamfer(X, ucb_k=0.0)["f1"]
        return total

    class Summed:  # the one method neighbour_fraction calls
        def chamfer(self, X, ucb_k=0.0):
            return {"f1": f1(X)}

    x0 = np.zeros(7)
    frac, _ = neighbour_fraction(Summed(), x0, NEIGHBOUR_STEP)
    S = np.tile(x0, (STARTS + 1, 1))
    S[1:, :6] += np.random.default_rng(0).uniform(-1.0, 1.0, (STARTS, 6)) * START_BOX
    Z, _, _ = newton_polish(f1, S, iters=15)
    Z, _, _ = polish(f1, Z, step=np.array([0.005] * 3 + [0.05] * 3))
    # A correction on the right: rotation and translation errors are the same for every camera.
    return {**_optima(stages[0][1], Z[:, :6]), "better": float(frac),
            "value": float(f1(Z[:1])[0])}


def measure(name: str, settings: Settings, groups: list[str], single: bool) -> dict:
    t0 = time.perf_counter()
    steps, T_ref = load_set(name, settings)
    frames = steps.frames
    out = {"frames": len(frames), "lidar_pose": steps.lidar_info.get("source"),
           "rings": sorted({int(r.n_rings) for r in steps.rings}),
           "purity": round(float(min(r.purity for r in steps.rings)), 3), "groups": {}}
    for g in groups:
        s = settings.replace(objective=GROUPS[g])
        row = basin(steps.frames, T_ref, s, steps.rings)
        if single and len(frames) > 1:
            per = [basin([f], T_ref, s, [r]) for f, r in zip(steps.frames, steps.rings)]
            row["single"] = {k: {"median": float(np.median([p[k] for p in per])),
                                 "max": float(np.max([p[k] for p in per]))}
                             for k in ("deg", "cm", "px", "better")}
        out["groups"][g] = row
    out["seconds"] = round(time.perf_counter() - t0, 1)
    return out


def table(results: dict) -> str:
    lines = ["| set | frames | group | optimum deg | cm | px | centre deg / cm | "
             "spread deg / cm | neighbours better | single frame: optimum deg / cm (median, "
             "worst) | better (median) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in results.items():
        for g, row in r["groups"].items():
            s = row.get("single")
            one = (f"{s['deg']['median']:.2f} / {s['cm']['median']:.1f}, "
                   f"{s['deg']['max']:.2f} / {s['cm']['max']:.1f}" if s else "")
            better1 = f"{100 * s['better']['median']:.0f} %" if s else ""
            lines.append(f"| {name} | {r['frames']} | {g} | {row['deg']:.2f} | {row['cm']:.1f} | "
                         f"{row['px']:.1f} | {row['centre_deg']:.2f} / {row['centre_cm']:.1f} | "
                         f"{row['spread_deg']:.2f} / {row['spread_cm']:.1f} | "
                         f"{100 * row['better']:.0f} % | {one} | {better1} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sets", default=",".join(SETS), help="comma-separated: " + ", ".join(SETS))
    ap.add_argument("--groups", default="all,depth,intensity")
    ap.add_argument("--single", action="store_true", help="also each frame alone")
    ap.add_argument("--config", type=Path, help="settings file (YAML/JSON) by section")
    ap.add_argument("--json", type=Path, help="write the results here")
    ap.add_argument("--joint", help="comma-separated sets of one rig, measured at once")
    a = ap.parse_args(argv)
    settings = load_settings(a.config)
    results = {}
    for name in a.sets.split(","):
        results[name] = measure(name, settings, a.groups.split(","), a.single)
        r = results[name]
        print(f"{name}: {r['frames']} frames, LiDAR pose {r['lidar_pose']}, rings {r['rings']} "
              f"(purity {r['purity']}), {r['seconds']} s", file=sys.stderr)
        for g, row in r["groups"].items():
            print(f"  {g:<10} optimum {row['deg']:.2f} deg / {row['cm']:.1f} cm / "
                  f"{row['px']:.1f} px, centre {row['centre_deg']:.2f} deg / "
                  f"{row['centre_cm']:.1f} cm, {100 * row['better']:.0f} % better, correction "
                  f"{row['correction']}, points {row['points_per_frame']}", file=sys.stderr)
    print(table(results))
    if a.joint:
        names = a.joint.split(",")
        t0 = time.perf_counter()
        parts = [(st.frames, T, st.rings) for st, T in (load_set(n, settings) for n in names)]
        j = joint_basin(parts, settings)
        results["joint"] = {"sets": names, **j}
        print(f"\njoint ({', '.join(names)}): optimum {j['deg']:.2f} deg / {j['cm']:.1f} cm, "
              f"centre {j['centre_deg']:.2f} / {j['centre_cm']:.1f}, spread "
              f"{j['spread_deg']:.2f} / {j['spread_cm']:.1f}, {100 * j['better']:.0f} % "
              f"neighbours better, correction {j['correction']} "
              f"({time.perf_counter() - t0:.0f} s)")
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
