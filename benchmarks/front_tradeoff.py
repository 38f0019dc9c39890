"""Does the front trade accuracy for cost? Default objective against the naive one (k = 0).

Runs the same calibration twice from the same perturbed start on the sample drive: with the
default sampling-error charge and with ``ucb_k = 0`` (the plain mean over the first n points),
and plots, for each front, the Chamfer objective and the rotation and translation errors
against n. Writes ``front_tradeoff.png`` and prints each front's n range.

    .venv/bin/python benchmarks/front_tradeoff.py --out runs/front_tradeoff.png
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from paretocal import Settings, calibrate, load_frames  # noqa: E402
from paretocal.geometry import correction_matrix  # noqa: E402

DATA = Path(os.environ.get("PARETOCAL_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="runs/front_tradeoff.png")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    frames = load_frames(DATA / "kitti_raw" / "2011_09_26")
    rng = np.random.default_rng(1000 + args.seed)
    p = np.r_[rng.uniform(-0.2, 0.2, 3), rng.uniform(-5, 5, 3)]
    T_init = frames[0].T_ref @ correction_matrix(p)
    runs = {}
    for label, k in (("default (k = sqrt(2 ln M))", None), ("naive mean (k = 0)", 0.0)):
        s = Settings().replace(objective={"ucb_k": k}) if k is not None else Settings()
        r = calibrate(frames, T_init, s)
        runs[label] = r
        X = r.front.X
        print(f"{label}: front of {len(X)}, n = {int(X[:, 6].min())}..{int(X[:, 6].max())}, "
              f"chosen n = {r.n_points}: {r.reference_error['rotation_deg']:.3f} deg "
              f"{r.reference_error['translation_cm']:.2f} cm")
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for (label, r), colour in zip(runs.items(), ("tab:blue", "tab:red")):
        n, c = r.front.X[:, 6], r.front.columns
        axes[0].plot(n, r.front.F[:, 0], "o-", ms=3, color=colour, label=label)
        axes[1].plot(n, c["ref_rotation_deg"], "o-", ms=3, color=colour, label=label)
        axes[2].plot(n, c["ref_translation_cm"], "o-", ms=3, color=colour, label=label)
        for ax in axes:
            ax.axvline(r.n_points, color=colour, ls=":", lw=1)
    axes[0].set_ylabel("f1 on the front (px)")
    axes[1].set_ylabel("rotation error vs KITTI reference (deg)")
    axes[2].set_ylabel("translation error vs KITTI reference (cm)")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xlabel("n, feature points per frame (log)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("Pareto fronts on the 20 sample KITTI frames (dotted: chosen n). "
                 "Data: KITTI, CC BY-NC-SA 3.0", fontsize=10)
    fig.tight_layout()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
