"""Intensity against grey level at the reference: where a second objective, sharing no feature
with the edge objective, puts its optimum on every development set.

The normalised information distance (NID) between the LiDAR's intensity and the image's grey
level at each projected return, ``NID = (H(A, B) - I(A; B)) / H(A, B)`` from a ``BINS x BINS``
joint histogram over all returns in view of all frames (the image blurred by 1 px, intensities
binned between their 1st and 99th percentiles), is polished from the reference with Powell's
method over the six axes of the correction. Compare it with the edge objective's optimum
(``benchmarks/basin.py``, the same sets and LiDAR steps): where both
agree with each other and not with the reference, the reference is suspect; where NID holds the
reference and the edges do not, the edge objective is biased. Numpy, one candidate at a time:
a measurement, not the calibration's code. ::

    PARETOCAL_DATA=../shared/data .venv/bin/python benchmarks/nid.py
    .venv/bin/python benchmarks/nid.py --sets pandaset_front,kitti_raw

Measured (2026-11, about a minute per set on two cores): from the reference Powell moves only
0.01-0.15 deg (KITTI drive 0.13, object 0.01, PandaSet front 0.03, left 0.04, front-left 0.08,
aiMotive front 0.15) and 2.5-146 cm; from ``--start 0,0,0,0.5,-0.5,0.5`` (and its negative) it
stops 0.5-1.1 deg away on the KITTI drive and object frame, at NID values worse than the
reference's: NID is rough at this scale and a local method does not find its optimum.
"""

from __future__ import annotations

import argparse
import sys

import cv2
import numpy as np
from scipy.optimize import minimize

from basin import DATA, SETS  # noqa: I001 - the benchmarks folder is on sys.path when run
from paretocal.camera import project
from paretocal.config import Settings
from paretocal.geometry import correction_matrix, pose_error
from paretocal.inputs import prepare_lidar
from paretocal.io import load_frames

#: Joint-histogram bins per axis.
BINS = 32
#: Powell's steps are taken in these units (m, m, m, deg, deg, deg).
SCALE = np.r_[[0.02] * 3, [0.2] * 3]


class IntensityNID:
    """NID between LiDAR intensity and image grey level for corrections of ``T_ref``.

    Parameters
    ----------
    frames : list of Frame
        After the LiDAR steps (``prepare_lidar``); ``points[:, 3]`` is the intensity.
    T_ref : ndarray, shape (4, 4)
        The pose the corrections apply to (``T = T_ref @ D(d)``).
    margin_px : float
        Returns projecting this far outside the image at ``T_ref`` are kept (they may come in).
    """

    def __init__(self, frames, T_ref: np.ndarray, margin_px: float = 50.0):
        self.T_ref = T_ref
        self.data = []
        for f in frames:
            xyz = f.points[:, :3].astype(np.float64)
            inten = f.points[:, 3].astype(np.float64)
            uv, _, ok = project(xyz, f.camera, T_ref, 0.5)
            c = f.camera
            ok &= ((uv[:, 0] > -margin_px) & (uv[:, 0] < c.width + margin_px)
                   & (uv[:, 1] > -margin_px) & (uv[:, 1] < c.height + margin_px))
            img = f.image if f.image.ndim == 2 else cv2.cvtColor(f.image, cv2.COLOR_BGR2GRAY)
            grey = cv2.GaussianBlur(img, (0, 0), 1.0).astype(np.float64)
            self.data.append((xyz[ok], inten[ok], grey, c))
        all_i = np.concatenate([d[1] for d in self.data])
        self.lo, self.hi = np.percentile(all_i, [1, 99])
        # Grey levels binned over the image type's range (8 bits: 0-255).
        self.grey_max = 256.0 if all(d[2].max() < 256 for d in self.data) else \
            float(max(d[2].max() for d in self.data)) + 1.0

    def __call__(self, d: np.ndarray) -> float:
        """NID (0 best, 1 worst) at the correction ``d`` (6,), metres and degrees."""
        T = self.T_ref @ correction_matrix(np.asarray(d, dtype=np.float64))
        H = np.zeros(BINS * BINS)
        for xyz, inten, grey, c in self.data:
            uv, _, ok = project(xyz, c, T, 0.5)
            u, v = uv[:, 0], uv[:, 1]
            ok &= (u >= 0) & (u < c.width - 1) & (v >= 0) & (v < c.height - 1)
            g = grey[v[ok].astype(np.int64), u[ok].astype(np.int64)]
            a = np.clip(((inten[ok] - self.lo) / (self.hi - self.lo) * BINS).astype(np.int64),
                        0, BINS - 1)
            b = np.clip((g / self.grey_max * BINS).astype(np.int64), 0, BINS - 1)
            H += np.bincount(a * BINS + b, minlength=BINS * BINS)
        p = H.reshape(BINS, BINS) / max(H.sum(), 1.0)

        def entropy(q):
            q = q[q > 0]
            return float(-(q * np.log(q)).sum())
        joint = entropy(p)
        mutual = entropy(p.sum(axis=1)) + entropy(p.sum(axis=0)) - joint
        return (joint - mutual) / joint if joint > 0 else 1.0

    def optimum(self, start=None, max_evaluations: int = 600) -> tuple[np.ndarray, float]:
        """The correction (6,) that Powell's method reaches from ``start`` (6,; zero by
        default), and its NID."""
        y0 = np.zeros(6) if start is None else np.asarray(start, dtype=np.float64) / SCALE
        res = minimize(lambda y: self(y * SCALE), y0, method="Powell",
                       options={"xtol": 1e-2, "ftol": 1e-6, "maxfev": max_evaluations})
        return res.x * SCALE, float(res.fun)


def measure(name: str, start=None) -> dict:
    folder, spec, cam = SETS[name]
    frames = load_frames(DATA / folder, spec, cam)
    T_ref = frames[0].T_ref
    steps = prepare_lidar(frames, Settings(), [(frames[0].camera, T_ref)])
    nid = IntensityNID(steps.frames, T_ref)
    d, value = nid.optimum(start)
    e = pose_error(T_ref @ correction_matrix(d), T_ref)
    return {"nid_reference": nid(np.zeros(6)), "nid_optimum": value,
            "deg": float(e["rotation_deg"]), "cm": float(e["translation_cm"]),
            "correction": [round(float(v), 5) for v in d]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", default=",".join(SETS), help=f"comma-separated: {', '.join(SETS)}")
    ap.add_argument("--start", default=None,
                    help="x,y,z,yaw,pitch,roll (m, deg): start Powell here instead of at the "
                         "reference (does NID bring a start back?)")
    args = ap.parse_args(argv)
    start = None if args.start is None else [float(v) for v in args.start.split(",")]
    print("| set | NID at the reference | NID optimum | optimum deg | cm | correction "
          "(x, y, z cm in the LiDAR frame; yaw, pitch, roll deg) |")
    print("|---|---|---|---|---|---|")
    for name in args.sets.split(","):
        r = measure(name, start)
        c = r["correction"]
        print(f"| {name} | {r['nid_reference']:.5f} | {r['nid_optimum']:.5f} | {r['deg']:.2f} "
              f"| {r['cm']:.1f} | {100 * c[0]:+.1f}, {100 * c[1]:+.1f}, {100 * c[2]:+.1f}; "
              f"{c[3]:+.2f}, {c[4]:+.2f}, {c[5]:+.2f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
