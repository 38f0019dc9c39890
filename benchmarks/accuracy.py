"""Accuracy from random decalibrations of the sample KITTI drive, through the public CLI.

Each trial draws a seeded correction, uniform per axis in +-ROT deg and +-TRANS m, and starts
from the extrinsic that this correction brings back to KITTI's reference (so the correction to
find lies in the box, inside the search bounds for the paper's +-20 deg / +-1.5 m). It writes
a *blind copy* of the dataset whose calibration file holds the perturbed extrinsic (symbolic
links to the frames, rewritten calib_velo_to_cam.txt), so the tool cannot see the reference,
and runs

    paretocal calibrate COPY --init INIT.yaml --out RUN --quiet [--frames ...] [--config ...]

and compares ``RUN/result.json`` with the reference.

    .venv/bin/python benchmarks/accuracy.py --trials 20 --rot 10 --trans 0.25
    .venv/bin/python benchmarks/accuracy.py --trials 20 --rot 20 --trans 1.5 --json out.json

``--api`` calls the library instead of the CLI (same calibration, no copy, no process start).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from paretocal.geometry import correction_matrix, invert, pose_error
from paretocal.io import detect_source, write_extrinsic
from paretocal.io.exports import kitti_velo_to_cam_text

DATA = Path(os.environ.get("PARETOCAL_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))
DATE = DATA / "kitti_raw" / "2011_09_26"
AXES = ("yaw_deg", "pitch_deg", "roll_deg", "x_cm", "y_cm", "z_cm")


def blind_copy(date: Path, T_cam_lidar: np.ndarray, dst: Path, camera: int = 2) -> Path:
    """A KITTI raw date folder whose ``calib_velo_to_cam.txt`` holds ``T_cam_lidar``.

    The frames are symbolic links; ``calib_cam_to_cam.txt`` is copied. Since the tool's extrinsic
    for camera N is ``[I | b] R_rect_00 Tr``, the file gets ``Tr = ([I | b] R_rect_00)^-1 T``
    (written by the same exporter as every run's ``calib_velo_to_cam.txt``).
    Returns the drive folder of the copy.
    """
    src = detect_source(date, camera)
    out = dst / date.name
    out.mkdir(parents=True)
    (out / "calib_cam_to_cam.txt").write_text((date / "calib_cam_to_cam.txt").read_text())
    (out / "calib_velo_to_cam.txt").write_text(
        kitti_velo_to_cam_text(T_cam_lidar, src.frames[0].kitti_rect, "blind accuracy trial"))
    drive = out / src.root.name
    drive.symlink_to(src.root.resolve(), target_is_directory=True)
    check = detect_source(drive, camera).frames[0].T_ref
    assert np.allclose(check, T_cam_lidar, atol=1e-9), "blind copy does not hold the extrinsic"
    return drive


def blind_copy_object(root: Path, T_cam_lidar: np.ndarray, dst: Path, camera: int = 2) -> Path:
    """A KITTI object ``training`` folder whose calib files hold ``T_cam_lidar``.

    Images and scans are symbolic links; each ``calib/<stem>.txt`` is rewritten with
    ``Tr_velo_to_cam = ([I | b] R0_rect)^-1 T`` and its other lines unchanged.
    """
    out = dst / "training"
    (out / "calib").mkdir(parents=True)
    for d in (f"image_{camera}", "velodyne"):
        (out / d).symlink_to((root / d).resolve(), target_is_directory=True)
    for cfile, files in zip(sorted((root / "calib").glob("*.txt")),
                            detect_source(root, camera).frames):
        Tr = np.linalg.inv(files.kitti_rect) @ T_cam_lidar
        lines = [f"Tr_velo_to_cam: {' '.join(f'{v:.12e}' for v in Tr[:3].ravel())}"
                 if line.startswith("Tr_velo_to_cam:") else line
                 for line in cfile.read_text().splitlines()]
        (out / "calib" / cfile.name).write_text("\n".join(lines) + "\n")
    check = detect_source(out, camera).frames[0].T_ref
    assert np.allclose(check, T_cam_lidar, atol=1e-9), "blind copy does not hold the extrinsic"
    return out


def run_trial(k: int, args, T_ref: np.ndarray, work: Path) -> dict:
    rng = np.random.default_rng(1000 + k)
    p = np.r_[rng.uniform(-args.trans, args.trans, 3), rng.uniform(-args.rot, args.rot, 3)]
    T_init = T_ref @ invert(correction_matrix(p))
    t0 = time.perf_counter()
    if args.api:
        from paretocal import calibrate, load_frames
        from paretocal.config import Settings, load_settings

        settings = load_settings(args.config) if args.config else Settings()
        frames = load_frames(args.source, args.frames)
        r = calibrate(frames, T_init, settings)
        T = r.T_cam_lidar
        n = r.n_points
    else:
        trial = work / f"trial_{k:03d}"
        drive = (blind_copy_object(args.source, T_init, trial / "data")
                 if args.dataset == "object" else blind_copy(DATE, T_init, trial / "data"))
        init = trial / "init.yaml"
        write_extrinsic(init, T_init)
        run = trial / "run"
        cmd = [sys.executable, "-m", "paretocal.cli", "calibrate", str(drive), "--init",
               str(init), "--out", str(run), "--quiet", "--no-figures"]
        if args.frames:
            cmd += ["--frames", args.frames]
        if args.config:
            cmd += ["--config", args.config]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"trial {k}: exit {proc.returncode}: {proc.stderr.strip()}")
        doc = json.loads((run / "result.json").read_text())
        T = np.array(doc["T_cam_lidar"])
        n = doc["n_points"]
    e0 = pose_error(T_init, T_ref)
    e = pose_error(T, T_ref)
    row = {"trial": k, "start_deg": float(e0["rotation_deg"]),
           "start_cm": float(e0["translation_cm"]), "rot_deg": float(e["rotation_deg"]),
           "trans_cm": float(e["translation_cm"]), "n": int(n),
           "wall_s": time.perf_counter() - t0}
    row.update({a: float(e[a]) for a in AXES})
    return row


def summarise(rows: list[dict], args) -> str:
    R = np.array([r["rot_deg"] for r in rows])
    Tc = np.array([r["trans_cm"] for r in rows])
    W = np.array([r["wall_s"] for r in rows])

    def stats(v):
        return (f"mean {np.mean(v):.3f}, median {np.median(v):.3f}, "
                f"p95 {np.percentile(v, 95):.3f}, max {np.max(v):.3f}")

    lines = [f"summary: {len(rows)} trials, start +-{args.rot} deg / +-{args.trans} m per axis, "
             f"{args.dataset} frames {args.frames or 'all'}, "
             f"via {'API' if args.api else 'CLI (blind copy)'}",
             f"  rotation (deg):    {stats(R)}",
             f"  translation (cm):  {stats(Tc)}"]
    for a in AXES:
        lines.append(f"  |{a}|: {stats(np.abs([r[a] for r in rows]))}")
    for rot, cm in ((1.0, 10.0), (0.5, 5.0), (0.3, 3.0)):
        ok = int(np.sum((R < rot) & (Tc < cm)))
        lines.append(f"  within {rot} deg and {cm:g} cm: {ok}/{len(rows)} "
                     f"({100.0 * ok / len(rows):.0f} %)")
    lines.append(f"  wall time per calibration (s): median {np.median(W):.0f}, max {W.max():.0f}")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--rot", type=float, default=10.0, help="per-axis bound, deg")
    ap.add_argument("--trans", type=float, default=0.25, help="per-axis bound, m")
    ap.add_argument("--dataset", choices=("raw", "object"), default="raw",
                    help="the 20-frame raw drive, or the single KITTI object frame (another "
                         "scene, not used to tune anything)")
    ap.add_argument("--frames", default=None, help="frame selection, e.g. 0:10")
    ap.add_argument("--config", default=None, help="settings file (YAML/JSON by section)")
    ap.add_argument("--api", action="store_true", help="call the library, not the CLI")
    ap.add_argument("--json", default=None, help="also write the trials to this JSON file")
    ap.add_argument("--keep", default=None, help="keep the blind copies and runs here")
    args = ap.parse_args()

    args.source = DATE if args.dataset == "raw" else DATA / "kitti_object" / "training"
    T_ref = detect_source(args.source).frames[0].T_ref
    rows = []
    with tempfile.TemporaryDirectory(prefix="paretocal-acc-") as tmp:
        work = Path(args.keep) if args.keep else Path(tmp)
        for k in range(args.first_seed, args.first_seed + args.trials):
            row = run_trial(k, args, T_ref, work)
            rows.append(row)
            print(f"trial {k:3d}: start {row['start_deg']:5.2f} deg {row['start_cm']:6.1f} cm -> "
                  f"{row['rot_deg']:.3f} deg {row['trans_cm']:.2f} cm (n = {row['n']}) "
                  f"{row['wall_s']:.0f} s", flush=True)
            if args.json:
                Path(args.json).write_text(json.dumps(rows, indent=1))
    print(summarise(rows, args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
