"""``paretocal study``: every study of the paper's "Simulation Results" on real frames.

One call runs the calibration at the paper's population and generations, then the checks and
analyses of its front, and writes each study's data (CSV), figure (PNG), ``study.json`` and a
self-contained ``report.html``:

==========================  ==========================================================
``pareto_front``            the front, Chamfer vs normalised cost, with reference errors
``solution_space``          the decision variables of the Pareto set in 3-D
``single_objective``        DE on the Chamfer alone, then Powell, with convergence
``epsilon_constraint``      min Chamfer s.t. cost <= eps, against the front
``decision``                knee region, chosen point, reference vs chosen projections
``innovization``            correlations and fitted trends over the Pareto set
``robustness``              the w1 / w2 weight sweep over seeds
==========================  ==========================================================
"""

from __future__ import annotations

import csv
import dataclasses
import io
import platform
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ... import __version__
from ...config import Settings, dataset_settings
from ...errors import InputError, ParetocalError
from ...geometry import pose_error
from ...io.atomic import atomic_write_text
from ...io.layouts import load_frames, source_options
from ...report.results import dumps, write_outputs
from ...search.problem import VARIABLES, bounds
from .epsilon import epsilon_constraint
from .innovization import correlations, findings, trends
from .robustness import summarise_sweep, weight_sweep
from .single import single_objective

STUDIES = ("pareto_front", "solution_space", "single_objective", "epsilon_constraint",
           "decision", "innovization", "robustness")
#: Names a study folder holds (calibration/ is written first): the CLI refuses to write a study
#: into a non-empty folder holding none of them unless told to (``--force``).
STUDY_MARKS = ("calibration", "study.json", "report.html")


@dataclass(frozen=True)
class StudyPlan:
    """How much work each study does.

    The main NSGA-II run and the single-objective DE use the paper's population and
    generations (1000 x 200). The epsilon-constraint GA runs (200 x 100 each) and the 27
    robustness calibrations (200 x 60, every 4th frame) use smaller budgets, so that the whole
    study fits in 15 minutes on two cores (with every other frame the robustness sweep alone
    took 14 minutes); each is still seeded with the same rotation-grid poses and polished like
    the front.

    Attributes
    ----------
    pop, gens : int
        The main NSGA-II run's and the single-objective DE's population and generations.
    frame_stride : int
        Use every k-th selected frame.
    eps_count : int
        Cost limits of the epsilon-constraint study, geometric in f2 between the front's ends.
    eps_pop, eps_gens : int
        Population and generations of each epsilon-constraint GA run.
    weights : tuple of float
        The ``w1`` values of the robustness study (``w2 = 1 - w1``).
    robust_seeds : tuple of int
        The seeds of each weight's robustness runs.
    robust_pop, robust_gens : int
        Population and generations of each robustness run.
    robust_frame_stride : int
        The robustness runs use every k-th frame of the study.
    """

    pop: int = 1000
    gens: int = 200
    frame_stride: int = 1                 #: use every k-th selected frame
    eps_count: int = 6                    #: cost limits, geometric in f2 between the ends
    eps_pop: int = 200
    eps_gens: int = 100
    weights: tuple[float, ...] = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
    robust_seeds: tuple[int, ...] = (0, 1, 2)
    robust_pop: int = 200
    robust_gens: int = 60
    robust_frame_stride: int = 4          #: robustness runs use every k-th frame of the study

    @classmethod
    def quick(cls) -> "StudyPlan":
        """A smoke-test plan (about a minute): every study, on a quarter of the frames."""
        return cls(pop=100, gens=30, frame_stride=4, eps_count=3, eps_pop=40, eps_gens=15,
                   weights=(0.1, 0.5, 0.9), robust_seeds=(0,), robust_pop=40, robust_gens=15,
                   robust_frame_stride=1)


def _csv(header: list[str], rows: list[list]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in r])
    return buf.getvalue()


def _eps_values(F: np.ndarray, count: int) -> np.ndarray:
    """``count`` cost limits spread geometrically over the front's f2 range (above its minimum)."""
    lo, hi = float(F[:, 1].min()), float(F[:, 1].max())
    floor = max(lo, 1e-3) if hi > 1e-3 else 1e-3
    hi = max(hi, floor)                      # a front of one solution at the cheapest cost
    return np.geomspace(max(floor, hi / 100), hi, count)


def run_study(source, out_dir, T_init: np.ndarray | None = None,  # noqa: PLR0913
              settings: Settings | None = None, plan: StudyPlan | None = None, progress=None,
              dataset_options: bool = True) -> dict:
    """Run every study and write its files to ``out_dir``.

    Parameters
    ----------
    source : path or list of Frame
    out_dir : path
    T_init : ndarray, shape (4, 4), optional
        Initial extrinsic (the dataset's when omitted; then no reference errors are reported).
    settings : Settings, optional
        Base settings; the plan's population and generations replace the search's.
    plan : StudyPlan, optional
    progress : callable, optional
        ``progress(stage, done, total)``; stages are the study names.
    dataset_options : bool
        What the dataset states (calib.yaml's ``init_error``) replaces the defaults the
        settings leave, for every study (:func:`~paretocal.config.dataset_settings`, as
        :func:`~paretocal.calibrate` does); False: the settings are final.

    Returns
    -------
    dict
        The ``study.json`` document.
    """
    from ...pipeline import calibrate, resolve_init
    from ...report import study_figures as figs
    from ...report.html import study_report

    plan = plan or StudyPlan()
    settings = (settings or Settings()).replace(search={"pop": plan.pop, "gens": plan.gens})
    settings = settings.validate()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t_all = time.perf_counter()
    frames = (load_frames(source, settings.frames, settings.camera)
              if isinstance(source, (str, Path)) else list(source))
    frames = frames[:: plan.frame_stride]
    if not frames:
        raise InputError(f"{source}: no frames to study")
    # Decided once, for every study: their boxes are the calibration's.
    settings = dataset_settings(settings, source_options(frames) if dataset_options else {})
    T_init, T_ref = resolve_init(frames, T_init)
    T_arg = T_init if T_ref is not None else None
    timings: dict[str, float] = {}

    def tick(name, done=1, total=1):
        if progress is not None:
            progress(name, done, total)

    # 1, 2, 5: the calibration itself.
    t0 = time.perf_counter()
    tick("pareto_front", 0)
    result = calibrate(frames, T_arg, settings, dataset_options=False,
                       progress=(lambda s, d, t: progress(f"calibration: {s}", d, t))
                       if progress else None)
    write_outputs(result, out / "calibration", frames)
    timings["calibration"] = time.perf_counter() - t0
    tick("pareto_front")
    obj, nsga_front = result.objective, result.nsga_front
    if obj is None or nsga_front is None:      # the pipeline returns both
        raise ParetocalError("the calibration kept no objective or search front to study")
    F, X, cols = result.front.F, result.front.X, result.front.columns
    n_lo, n_hi = result.n_range
    xl, xu = bounds(settings.search, n_lo, n_hi)
    ref_keys = [k for k in cols if k.startswith("ref_")]

    front_rows = [list(X[i, :6]) + [int(round(X[i, 6])), float(F[i, 0]), float(F[i, 1]),
                                    float(cols["ms"][i]), int(cols["bytes"][i]),
                                    float(cols["deviation_px"][i])]
                  + [float(cols[k][i]) for k in ref_keys] + [int(i == result.chosen)]
                  for i in range(len(X))]
    atomic_write_text(out / "pareto_front.csv", _csv(
        list(VARIABLES) + ["f1", "f2", "ms", "bytes", "deviation_px"] + ref_keys + ["chosen"],
        front_rows))
    figs.pareto_front(result, out / "pareto_front.png")
    Xn, Fn = nsga_front
    space_rows = ([["final"] + list(X[i, :6]) + [int(round(X[i, 6])), float(F[i, 0])]
                   for i in range(len(X))]
                  + [["nsga2"] + list(Xn[i, :6]) + [int(round(Xn[i, 6])), float(Fn[i, 0])]
                     for i in range(len(Xn))])
    atomic_write_text(out / "solution_space.csv",
                      _csv(["set"] + list(VARIABLES) + ["f1"], space_rows))
    figs.solution_space(result, out / "solution_space.png")
    tick("solution_space")

    # 3: single-objective verification at the largest n.
    t0 = time.perf_counter()
    tick("single_objective", 0)
    so = single_objective(lambda Z: obj.chamfer(Z)["f1"], n_hi, xl, xu, plan.pop, plan.gens,
                          seed=settings.search.seed, seeds=result.seed_poses)
    timings["single_objective"] = time.perf_counter() - t0
    so["front_best_f1"] = float(F[:, 0].min())
    so["T"] = obj.transforms(so["x"][None])[0]
    if T_ref is not None:
        so["reference_error"] = {k: float(v) for k, v in pose_error(so["T"], T_ref).items()}
    rows = ([["de", r["generation"], r["evaluations"], r["best_f1"], r["median_f1"]]
             for r in so["de_history"]]
            + [["powell", r["iteration"], so["de_history"][-1]["evaluations"] + r["evaluations"],
                r["f1"], ""] for r in so["local_history"]])
    atomic_write_text(out / "single_objective.csv",
                      _csv(["method", "iteration", "evaluations", "best_f1", "median_f1"], rows))
    figs.single_objective(so, out / "single_objective.png")
    tick("single_objective")

    # 4: epsilon-constraint verification.
    t0 = time.perf_counter()
    eps = _eps_values(F, plan.eps_count)
    tick("epsilon_constraint", 0, len(eps))
    ec = epsilon_constraint(obj, eps, xl, xu, plan.eps_pop, plan.eps_gens,
                            seed=settings.search.seed, seeds=result.seed_poses, F_front=F,
                            polish_iters=settings.decision.polish_iters
                            if settings.decision.polish else 0)
    timings["epsilon_constraint"] = time.perf_counter() - t0
    if T_ref is not None:
        for r in ec:
            if "x" in r:
                e = pose_error(obj.transforms(r["x"][None])[0], T_ref)
                r["rotation_deg"], r["translation_cm"] = (float(e["rotation_deg"]),
                                                          float(e["translation_cm"]))
    atomic_write_text(out / "epsilon_constraint.csv", _csv(
        ["eps", "feasible", "n", "f1", "f2", "f1_ga", "front_f1", "gap", "rotation_deg",
         "translation_cm", "evaluations"],
        [[r["eps"], int(r["feasible"]), int(round(r["x"][6])) if "x" in r else "",
          r.get("f1", ""), r.get("f2", ""), r.get("f1_ga", ""), r.get("front_f1", ""),
          r.get("gap", ""), r.get("rotation_deg", ""), r.get("translation_cm", ""),
          r["evaluations"]] for r in ec]))
    figs.epsilon_constraint(result, ec, out / "epsilon_constraint.png")
    tick("epsilon_constraint", len(eps), len(eps))

    # 5: preference-based decision.
    knee = figs.decision(result, out / "decision.png")
    figs.projections(frames[0], result, out / "projections.png")
    atomic_write_text(out / "decision.csv", _csv(
        ["index", "n", "ms", "f2", "deviation_px", "knee_region", "chosen"],
        [[i, int(round(X[i, 6])), float(cols["ms"][i]), float(F[i, 1]),
          float(cols["deviation_px"][i]), int(i in knee["region"]), int(i == result.chosen)]
         for i in range(len(X))]))
    tick("decision")

    # 6: innovization over the final front.
    half = np.r_[xu[:6], (xu[6] - xl[6]) / 2]
    corr = correlations(X, F)
    fits = trends(X, F)
    text = findings(X, F, half, corr, fits)
    atomic_write_text(out / "innovization.csv", _csv(
        ["variable", "objective", "pearson", "spearman", "spearman_p"],
        [[r["variable"], r["objective"], r["pearson"], r["spearman"], r["spearman_p"]]
         for r in corr]))
    atomic_write_text(out / "innovization.txt", "\n".join(text) + "\n")
    figs.innovization(X, F, corr, fits, out / "innovization.png")
    tick("innovization")

    # 7: robustness to the edge / intensity weights.
    t0 = time.perf_counter()
    rframes = frames[:: plan.robust_frame_stride]
    rset = settings.replace(search={"pop": plan.robust_pop, "gens": plan.robust_gens})
    total = len(plan.weights) * len(plan.robust_seeds)
    tick("robustness", 0, total)
    sweep = weight_sweep(rframes, T_arg if T_arg is not None else T_init, rset, plan.weights,
                         plan.robust_seeds,
                         progress=(lambda d, t: progress("robustness", d, t)) if progress else None)
    timings["robustness"] = time.perf_counter() - t0
    rsum = summarise_sweep(sweep)
    err = ["rotation_deg", "translation_cm"] if "rotation_deg" in sweep[0] else []
    atomic_write_text(out / "robustness.csv", _csv(
        ["w1", "w2", "seed", "f1", "n"] + err + [f"correction_{v}" for v in VARIABLES[:6]]
        + ["wall_s"],
        [[r["w1"], r["w2"], r["seed"], r["f1"], r["n"]] + [r[k] for k in err] + list(r["x"])
         + [r["wall_s"]] for r in sweep]))
    figs.robustness(sweep, rsum, out / "robustness.png")
    timings["total"] = time.perf_counter() - t_all

    doc = {
        "version": __version__,
        "python": platform.python_version(),
        "libraries": _versions(),
        "source": str(source) if isinstance(source, (str, Path)) else None,
        "frames": [f.name for f in frames],
        "robustness_frames": [f.name for f in rframes],
        "plan": dataclasses.asdict(plan),
        "settings": settings.to_dict(),
        "T_init": T_init,
        "reference_known": T_ref is not None,
        "timings_s": {k: round(v, 2) for k, v in timings.items()},
        "calibration": {k: v for k, v in result.to_dict().items() if k not in ("config",)},
        "single_objective": {k: v for k, v in so.items() if k not in ("de_history",
                                                                       "local_history")},
        "epsilon_constraint": ec,
        "decision": {"knee_region": knee["region"], "chosen": int(result.chosen),
                     **result.decision.to_dict()},
        "innovization": {"findings": text, "trends": fits},
        "robustness": rsum,
    }
    atomic_write_text(out / "study.json", dumps(doc, indent=1))
    study_report(doc, out, out / "report.html")
    return doc


def _versions() -> dict:
    import cv2
    import matplotlib
    import numba
    import pymoo
    import scipy

    return {"numpy": np.__version__, "scipy": scipy.__version__, "pymoo": pymoo.__version__,
            "numba": numba.__version__, "opencv": cv2.__version__,
            "matplotlib": matplotlib.__version__, "platform": platform.platform()}
