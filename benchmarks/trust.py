"""How far the verdict can be trusted: wrong results flagged, good ones passed, intervals kept.

Runs decalibrated calibrations (library API, seeded starts drawn as in ``accuracy.py``: the
correction to find is uniform per axis in +-ROT deg / +-TRANS m) over the development data
and stress cases made at run time, and compares each result with the reference:

=============  =================================================================================
case           what it is
=============  =================================================================================
clean5         KITTI raw drive, 20 frames, +-5 deg / 0.2 m
clean10        the same, +-10 deg / 0.25 m
wide           the same, +-20 deg / 1.5 m, stated as such (``--init-error 20,1.5``)
two_frames     frames 0 and 10, +-3 deg / 0.1 m
one_frame      frame 5 alone, +-3 deg / 0.1 m
mismatched     every image paired with another frame's cloud (rolled by 5 frames, or a seeded
               permutation on odd trials), +-5 deg / 0.2 m
few_points     each cloud randomly thinned to 3 % of its points, +-5 deg / 0.2 m
focal          the camera's focal length 5 % too long, +-5 deg / 0.2 m
budget         a small search (population 40, 10 generations), +-10 deg / 0.25 m
beams16        the drive decimated to 16 beams, +-5 deg / 0.2 m
contour16      16 beams with ``features.edge_contour`` on (all frames agree on a wrong pose)
object         the KITTI object frame (one frame, hedges and trees), +-10 deg / 0.25 m
aimotive       aiMotive front camera, 5 night frames (0, 4, ..., 16), +-5 deg / 0.2 m
standing       PandaSet front-left camera, the 13 frames taken standing (0:13), +-5 deg / 0.2 m:
               every frame shows one view, whose bias they share
=============  =================================================================================

A result is *wrong* when it is more than 1 deg or 10 cm from the reference. Reported: wrong
results flagged ``unreliable`` (recall), good results flagged (false alarms), the share of good
results whose per-axis 95 % intervals contain the true error (the correction from the result to
the reference, in the search's axes: translation in the LiDAR frame, ZYX angles), axes reported
as undetermined, and the verdict's cost (its checks' time over the rest of the calibration).

    PARETOCAL_DATA=../shared/data .venv/bin/python benchmarks/trust.py --json runs/trust.json

``--cases a,b`` runs some cases, ``--trials-scale 0.5`` halves every case's trial count (at
least one each), ``--resume`` skips the trials already in ``--json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import DATA, DATE, OBJECT, build_variant, trial_start  # noqa: E402

from paretocal import calibrate, load_frames  # noqa: E402
from paretocal.config import Settings  # noqa: E402
from paretocal.errors import ParetocalError  # noqa: E402
from paretocal.geometry import pose_error  # noqa: E402
from paretocal.quality import AXES, TO_REPORT, correction_between  # noqa: E402

AIMOTIVE = DATA / "aimotive" / "front_pinhole"
PANDASET_FRONT_LEFT = DATA / "pandaset" / "front_left"


@dataclasses.dataclass
class Case:
    name: str
    trials: int
    rot: float
    trans: float
    frames: callable                 #: (work dir, trial) -> (frames, T_ref)
    settings: dict = dataclasses.field(default_factory=dict)
    init_error: tuple | None = None  #: (deg, m) stated to the tool; None: the default


def _source(path, spec=None):
    """Frames of ``path`` (loaded once) with their own reference extrinsic."""
    cache = {}

    def get(work, k):
        if "frames" not in cache:
            cache["frames"] = load_frames(path, spec)
        fr = cache["frames"]
        return list(fr), fr[0].T_ref
    return get


def _kitti(spec=None):
    return _source(DATE, spec)


def _modified(change, spec=None):
    base = _kitti(spec)

    def get(work, k):
        fr, T = base(work, k)
        return change(fr, k), T
    return get


def _mismatch(frames, k):
    n = len(frames)
    order = (np.roll(np.arange(n), 5) if k % 2 == 0
             else np.random.default_rng(k).permutation(n))
    if np.any(order == np.arange(n)):                # no frame keeps its own image
        order = np.roll(order, 1)
    return [dataclasses.replace(f, image=frames[j].image) for f, j in zip(frames, order)]


def _thin(frames, k):
    out = []
    for i, f in enumerate(frames):
        rng = np.random.default_rng(100 * k + i)
        keep = np.sort(rng.choice(len(f.points), len(f.points) * 3 // 100, replace=False))
        out.append(dataclasses.replace(
            f, points=f.points[keep], ring=None if f.ring is None else f.ring[keep],
            time=None if f.time is None else f.time[keep]))
    return out


def _long_focal(frames, k):
    cam = frames[0].camera
    K = cam.K.copy()
    K[0, 0] *= 1.05
    K[1, 1] *= 1.05
    cam2 = dataclasses.replace(cam, K=K)
    return [dataclasses.replace(f, camera=cam2) for f in frames]


_VARIANTS: dict = {}


def _variant(name):
    def get(work, k):
        # One folder per variant, shared by the cases that use it.
        if name not in _VARIANTS:
            folder, T_ref, _ = build_variant(DATE, name, Path(work) / f"variant_{name}")
            _VARIANTS[name] = (load_frames(folder), T_ref)
        fr, T = _VARIANTS[name]
        return list(fr), T
    return get


def cases() -> list[Case]:
    return [
        Case("clean5", 10, 5, 0.2, _kitti()),
        Case("clean10", 6, 10, 0.25, _kitti()),
        Case("wide", 6, 20, 1.5, _kitti(), init_error=(20, 1.5)),
        Case("two_frames", 4, 3, 0.1, _kitti("0,10")),
        Case("one_frame", 2, 3, 0.1, _kitti("5")),
        Case("mismatched", 4, 5, 0.2, _modified(_mismatch)),
        Case("few_points", 4, 5, 0.2, _modified(_thin)),
        Case("focal", 4, 5, 0.2, _modified(_long_focal)),
        Case("budget", 6, 10, 0.25, _kitti(), {"search": {"pop": 40, "gens": 10}}),
        Case("beams16", 4, 5, 0.2, _variant("16beam")),
        Case("contour16", 4, 5, 0.2, _variant("16beam"), {"features": {"edge_contour": True}}),
        Case("object", 3, 10, 0.25, _source(OBJECT)),
        Case("aimotive", 3, 5, 0.2, _source(AIMOTIVE, "0:20:4")),
        Case("standing", 2, 5, 0.2, _source(PANDASET_FRONT_LEFT, "0:13")),
    ]


def run_trial(case: Case, k: int, work: Path) -> dict:
    frames, T_ref = case.frames(work, k)
    box = argparse.Namespace(rot=case.rot, trans=case.trans)
    T_init = trial_start(k, box, T_ref)
    settings = Settings().replace(**case.settings) if case.settings else Settings()
    if case.init_error:
        settings = settings.replace(search={"init_error_deg": case.init_error[0],
                                            "init_error_m": case.init_error[1]})
    t0 = time.perf_counter()
    row = {"case": case.name, "trial": k}
    e0 = pose_error(T_init, T_ref)
    row.update(start_deg=float(e0["rotation_deg"]), start_cm=float(e0["translation_cm"]))
    try:
        r = calibrate(frames, T_init, settings)
    except ParetocalError as exc:
        row.update(error=str(exc), wall_s=time.perf_counter() - t0)
        return row
    e = pose_error(r.T_cam_lidar, T_ref)
    rel = r.reliability.to_dict()                  # as result.json writes it (cm and deg)
    d = correction_between(r.T_cam_lidar, T_ref) * TO_REPORT
    iv = rel.get("intervals") or {}
    half = iv.get("half_width") or {}
    row.update(
        rot_deg=float(e["rotation_deg"]), trans_cm=float(e["translation_cm"]),
        wrong=bool(e["rotation_deg"] > 1.0 or e["translation_cm"] > 10.0),
        verdict=rel["verdict"], reasons=rel["reasons"],
        true_correction={a: float(v) for a, v in zip(AXES, d)},
        half_width=half,
        covered={a: (None if half.get(a) is None else bool(abs(d[i]) <= half[a]))
                 for i, a in enumerate(AXES)},
        jackknife_se=None if r.quality is None else r.quality.to_dict()["jackknife_se"],
        resolution_per_px=iv.get("resolution_per_px"),
        evidence=rel.get("evidence"),
        basin=None if r.decision.basin is None else r.decision.basin.to_dict(),
        verdict_s=float(r.timings.get("verdict", 0.0)), total_s=float(r.timings["total"]),
        wall_s=time.perf_counter() - t0)
    return row


def summarise(rows: list[dict]) -> dict:
    done = [r for r in rows if "verdict" in r]
    wrong = [r for r in done if r["wrong"]]
    good = [r for r in done if not r["wrong"]]
    cov = {}
    for a in AXES:
        c = [r["covered"][a] for r in good if r["covered"].get(a) is not None]
        cov[a] = {"covered": int(sum(c)), "determined": len(c),
                  "undetermined": sum(r["covered"].get(a) is None for r in good),
                  "rate": (sum(c) / len(c)) if c else None}
    share = [r["verdict_s"] / max(r["total_s"] - r["verdict_s"], 1e-9) for r in done]
    by_case = {}
    for r in done:
        c = by_case.setdefault(r["case"], {"trials": 0, "wrong": 0, "wrong_flagged": 0,
                                          "good_flagged": 0})
        c["trials"] += 1
        c["wrong"] += r["wrong"]
        c["wrong_flagged"] += r["wrong"] and r["verdict"] != "ok"
        c["good_flagged"] += (not r["wrong"]) and r["verdict"] != "ok"
    return {
        "trials": len(done), "errors": len(rows) - len(done),
        "wrong": len(wrong), "wrong_flagged": sum(r["verdict"] != "ok" for r in wrong),
        "recall": (sum(r["verdict"] != "ok" for r in wrong) / len(wrong)) if wrong else None,
        "good": len(good), "good_flagged": sum(r["verdict"] != "ok" for r in good),
        "false_alarm_rate": (sum(r["verdict"] != "ok" for r in good) / len(good)) if good
        else None,
        "coverage": cov,
        "verdict_cost_share": {"median": float(np.median(share)) if share else None,
                               "max": float(np.max(share)) if share else None},
        "by_case": by_case,
        "missed": [{"case": r["case"], "trial": r["trial"], "rot_deg": round(r["rot_deg"], 3),
                    "trans_cm": round(r["trans_cm"], 2)} for r in wrong if r["verdict"] == "ok"],
    }


def table(s: dict) -> str:
    lines = [f"{'case':<12} {'trials':>6} {'wrong':>6} {'flagged':>8} {'good flagged':>13}"]
    for name, c in s["by_case"].items():
        lines.append(f"{name:<12} {c['trials']:>6} {c['wrong']:>6} {c['wrong_flagged']:>8} "
                     f"{c['good_flagged']:>13}")
    rec = "n/a" if s["recall"] is None else f"{100 * s['recall']:.0f} %"
    fa = "n/a" if s["false_alarm_rate"] is None else f"{100 * s['false_alarm_rate']:.0f} %"
    lines.append(f"wrong results flagged: {s['wrong_flagged']}/{s['wrong']} ({rec}); good "
                 f"results flagged: {s['good_flagged']}/{s['good']} ({fa})")
    lines.append("interval coverage (good results): " + ", ".join(
        f"{a} {v['covered']}/{v['determined']}" + (f" ({v['undetermined']} undetermined)"
                                                   if v["undetermined"] else "")
        for a, v in s["coverage"].items()))
    vc = s["verdict_cost_share"]
    if vc["median"] is not None:
        lines.append(f"verdict cost: median {100 * vc['median']:.0f} %, max "
                     f"{100 * vc['max']:.0f} % of the rest of the calibration")
    if s["missed"]:
        lines.append("missed: " + "; ".join(f"{m['case']}#{m['trial']} {m['rot_deg']} deg / "
                                            f"{m['trans_cm']} cm" for m in s["missed"]))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", help="comma-separated case names (default: all)")
    ap.add_argument("--trials-scale", type=float, default=1.0)
    ap.add_argument("--json", type=Path, help="write every trial and the summary here")
    ap.add_argument("--resume", action="store_true", help="skip trials already in --json")
    args = ap.parse_args(argv)
    all_cases = cases()
    if args.cases:
        want = [c.strip() for c in args.cases.split(",") if c.strip()]
        unknown = [w for w in want if w not in {c.name for c in all_cases}]
        if unknown:
            ap.error(f"unknown case {unknown[0]!r} (one of "
                     f"{', '.join(c.name for c in all_cases)})")
        all_cases = [c for c in all_cases if c.name in want]
    rows = []
    if args.resume and args.json and args.json.exists():
        rows = json.loads(args.json.read_text())["trials"]
    done = {(r["case"], r["trial"]) for r in rows}
    with tempfile.TemporaryDirectory(prefix="paretocal-trust-") as work:
        for case in all_cases:
            n = max(1, int(round(case.trials * args.trials_scale)))
            for k in range(n):
                if (case.name, k) in done:
                    continue
                row = run_trial(case, k, Path(work))
                rows.append(row)
                flag = row.get("verdict", "error")
                print(f"{case.name:<11} #{k}: start {row['start_deg']:.1f} deg / "
                      f"{row['start_cm']:.0f} cm -> "
                      + (f"{row['rot_deg']:.3f} deg / {row['trans_cm']:.2f} cm, {flag}"
                         if "verdict" in row else f"error: {row['error']}")
                      + f" ({row['wall_s']:.0f} s)", file=sys.stderr, flush=True)
                if args.json:
                    args.json.parent.mkdir(parents=True, exist_ok=True)
                    tmp = args.json.with_suffix(".tmp")
                    tmp.write_text(json.dumps({"trials": rows, "summary": summarise(rows)},
                                              indent=1, default=float))
                    tmp.replace(args.json)
    s = summarise(rows)
    print(table(s))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
