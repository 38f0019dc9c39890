"""The fleet figure of ``paretocal batch``: each vehicle's extrinsic drift over its drives."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from matplotlib import colormaps

from .figures import save_figure, subplots


def fleet_figure(rows: list[dict], path: Path) -> None:
    """Rotation and translation drift (calibrated vs initial extrinsic) per entry, one line per
    vehicle in manifest order; entries whose initial extrinsic was checked miscalibrated are
    ringed, failed entries marked on the axis."""
    fig, axes = subplots(1, 2, figsize=(12.5, 4.4))
    vehicles = sorted({str(r["vehicle"] or r["id"]) for r in rows})
    for k, v in enumerate(vehicles):
        rs = [r for r in rows if str(r["vehicle"] or r["id"]) == v]
        xs = np.arange(len(rs))
        colour = colormaps["tab10"](k % 10)
        for ax, key in zip(axes, ("drift_rotation_deg", "drift_translation_cm")):
            ok = [i for i, r in enumerate(rs) if r["status"] == "ok"]
            y = [rs[i][key] for i in ok]
            ax.plot(xs[ok], y, "o-", color=colour, ms=5, lw=1.2, label=v)
            bad = [i for i in ok if rs[i].get("check_verdict") == "miscalibrated"]
            ax.scatter(xs[bad], [rs[i][key] for i in bad], s=160, facecolor="none",
                       edgecolor="tab:red", lw=1.5, zorder=4)
            fail = [i for i, r in enumerate(rs) if r["status"] != "ok"]
            ax.scatter(xs[fail], np.zeros(len(fail)), marker="x", s=70, color=colour, zorder=4)
    from matplotlib.ticker import MaxNLocator

    for ax, label in zip(axes, ("rotation drift (deg)", "translation drift (cm)")):
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("entry of the vehicle (manifest order)")
        ax.set_ylabel(f"{label}: calibrated vs initial extrinsic")
        ax.grid(alpha=0.3)
    axes[0].scatter([], [], s=160, facecolor="none", edgecolor="tab:red", lw=1.5,
                    label="initial extrinsic checked miscalibrated")
    axes[0].scatter([], [], marker="x", s=70, color="0.3", label="failed entry")
    axes[0].legend(fontsize=8, loc="best")
    axes[0].set_title("Fleet: how far each calibration moved the vehicle's extrinsic", loc="left")
    fig.tight_layout()
    save_figure(fig, path)
