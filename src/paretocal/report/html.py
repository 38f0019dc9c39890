"""A self-contained HTML report of a study (figures inlined, no network access needed).

The page's skeleton and style sheet are package data in ``report/templates/`` (``study.html``,
``study.css``), filled with :class:`string.Template`; :func:`template` also serves the
interactive page's templates.
"""

from __future__ import annotations

import base64
import functools
import html
import json
from importlib import resources
from pathlib import Path
from string import Template

from ..io.atomic import atomic_write_text

SECTIONS = [
    ("pareto_front", "1. Pareto front",
     "Chamfer objective f1 against normalised cost f2 after NSGA-II and the local polish; grey "
     "crosses are NSGA-II's own front. Right: each solution's error against the dataset's "
     "reference (when known)."),
    ("solution_space", "2. Solution space",
     "The decision variables of the Pareto set: the translation and rotation corrections to "
     "the initial extrinsic, coloured by the number of points per frame."),
    ("single_objective", "3. Single-objective verification",
     "The Chamfer alone at the largest n: differential evolution (pymoo, same population and "
     "generations as NSGA-II, same seed poses), then scipy's Powell from its best pose."),
    ("epsilon_constraint", "4. Epsilon-constraint verification",
     "For each cost limit eps, a GA minimises f1 subject to f2 <= eps (a pymoo inequality "
     "constraint), then the same local polish as the front. Right: the gap to the front's best "
     "f1 within the same limit."),
    ("decision", "5. Preference-based decision",
     "The knee rule reads the deviation of each calibration from the best-supported one "
     "against cost; the knee region holds the candidates at least half as far below the chord "
     "as the knee. Right: the paper's knee of the Chamfer front, for contrast."),
    ("projections", "",
     "LiDAR returns projected on the first frame with the initial, the chosen and the "
     "reference extrinsic."),
    ("innovization", "6. Innovization",
     "Relations between variables and objectives over the Pareto set, computed from it."),
    ("robustness", "7. Robustness to the Chamfer weights",
     "w1 weighs the depth-edge term and w2 = 1 - w1 the reflectance-edge term; each weight is "
     "calibrated with several seeds."),
]


@functools.lru_cache(maxsize=None)
def template(name: str) -> str:
    """The text of ``report/templates/<name>`` (package data, read once per process)."""
    return (resources.files("paretocal.report") / "templates" / name).read_text(encoding="utf-8")


def _img(path: Path) -> str:
    if not path.exists():
        return f'<p class="muted">({html.escape(path.name)} was not written)</p>'
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img alt="{html.escape(path.stem)}" src="data:image/png;base64,{data}">'


def _table(header: list[str], rows: list[list]) -> str:
    def cell(v):
        if isinstance(v, float):
            return f"{v:.4g}"
        return html.escape(str(v))

    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell(v)}</td>" for v in r) + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _facts(doc: dict) -> dict[str, str]:
    """A short table or text per section, from the study document."""
    cal = doc["calibration"]
    out = {}
    ref = cal.get("reference_error")
    rows = [["chosen n (points per frame)", cal["n_points"]],
            ["Chamfer f1", cal["objectives"]["chamfer"]],
            ["normalised cost f2", cal["objectives"]["cost"]],
            ["modelled time per evaluation (ms)", cal["objectives"].get("ms", "")],
            ["front size", cal["front_size"]], ["evaluations", cal["evaluations"]]]
    if ref:
        rows += [["rotation error vs reference (deg)", ref["rotation_deg"]],
                 ["translation error vs reference (cm)", ref["translation_cm"]]]
    ini = cal.get("initial_error")
    if ini:
        rows += [["initial rotation error (deg)", ini["rotation_deg"]],
                 ["initial translation error (cm)", ini["translation_cm"]]]
    out["pareto_front"] = _table(["figure", "value"], rows)
    so = doc["single_objective"]
    rows = [["DE best f1", so["f1_de"]], ["after Powell", so["f1"]],
            ["NSGA-II front best f1", so["front_best_f1"]],
            ["difference (single-objective - front)", so["f1"] - so["front_best_f1"]],
            ["evaluations", so["evaluations"]], ["wall time (s)", so["wall_s"]]]
    if "reference_error" in so:
        rows += [["single-objective result vs reference (deg / cm)",
                  f"{so['reference_error']['rotation_deg']:.3f} / "
                  f"{so['reference_error']['translation_cm']:.2f}"]]
    out["single_objective"] = _table(["figure", "value"], rows)
    ec = doc["epsilon_constraint"]
    out["epsilon_constraint"] = _table(
        ["eps", "n", "f1 (GA)", "f1 (polished)", "front f1 within eps", "gap (px)",
         "rotation error (deg)", "translation error (cm)"],
        [[r["eps"], int(round(r["x"][6])) if "x" in r else "", r.get("f1_ga", ""),
          r.get("f1", ""), r.get("front_f1", ""), r.get("gap", ""), r.get("rotation_deg", ""),
          r.get("translation_cm", "")] for r in ec])
    d = doc["decision"]
    out["decision"] = (f"<p>Rule <code>{html.escape(d['rule'])}</code>; knee region: "
                       f"{len(d['knee_region'])} solutions; chosen solution index "
                       f"{d['chosen']} with n = {d.get('n_points', '')} and deviation "
                       f"{d.get('deviation_px', float('nan')):.3f} px from the best-supported "
                       "solution.</p>")
    out["innovization"] = "<ul>" + "".join(f"<li>{html.escape(t)}</li>"
                                           for t in doc["innovization"]["findings"]) + "</ul>"
    rb = doc["robustness"]
    per = rb["per_weight"]
    keys = [k for k in ("f1_median", "rotation_deg_median", "rotation_deg_max",
                        "translation_cm_median", "translation_cm_max", "seed_spread")
            if per and k in per[0]]
    out["robustness"] = (f"<p>Best w1 = <b>{rb['best_w1']}</b> (by {html.escape(rb['basis'])})."
                         "</p>" + _table(["w1", "runs"] + keys,
                                         [[p["w1"], p["runs"]] + [p[k] for k in keys]
                                          for p in per]))
    return out


def study_report(doc: dict, fig_dir: Path, path: Path) -> None:
    """Write ``path``: every figure inlined, the key figures, settings, versions and timings."""
    fig_dir = Path(fig_dir)
    facts = _facts(doc)
    # The body between the heading and the data credit; study.html holds the rest of the page.
    parts = [f"<p class='muted'>paretocal {html.escape(doc['version'])}, Python "
             f"{html.escape(doc['python'])}; source <code>{html.escape(str(doc['source']))}</code>, "
             f"{len(doc['frames'])} frames; seed {doc['settings']['search']['seed']}; "
             f"total {doc['timings_s'].get('total', 0):.0f} s.</p>"]
    for key, title, caption in SECTIONS:
        if title:
            parts.append(f"<h2 id='{key}'>{html.escape(title)}</h2>")
        parts.append(f"<p>{html.escape(caption)}</p>")
        parts.append(_img(fig_dir / f"{key}.png"))
        if key in facts:
            parts.append(facts[key])
        csv_name = f"{key}.csv"
        if (fig_dir / csv_name).exists():
            parts.append(f"<p class='muted'>Data: <code>{csv_name}</code></p>")
    parts.append("<h2 id='rerun'>8. Settings, versions, timings</h2>")
    parts.append(_table(["step", "wall time (s)"], [[k, v] for k, v in doc["timings_s"].items()]))
    parts.append(_table(["library", "version"], [[k, v] for k, v in doc["libraries"].items()]))
    parts.append("<p>Frames: " + html.escape(", ".join(doc["frames"])) + "</p>")
    parts.append("<p>Rerun: <code>paretocal study SOURCE --out DIR "
                 "[--init INIT.yaml] [--quick]</code> with the plan and settings below "
                 "(<code>study.json</code> holds them all, with the initial extrinsic).</p>")
    parts.append("<details><summary>study plan and settings</summary><pre>"
                 + html.escape(json.dumps({"plan": doc["plan"], "settings": doc["settings"]},
                                          indent=1)) + "</pre></details>")
    # substitute() fails on a missing placeholder; the values themselves are not scanned for $.
    page = Template(template("study.html")).substitute(css=template("study.css"),
                                                       body="\n".join(parts))
    atomic_write_text(path, page)
