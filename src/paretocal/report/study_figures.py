"""Figures of ``paretocal study`` (one per study, matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from matplotlib.colors import Normalize

from .figures import data_credit, draw_overlay, new_figure, save_figure, subplots

STAR = dict(s=240, marker="*", color="tab:red", edgecolor="k", zorder=5)


def _front_line(ax, F, **kw):
    o = np.argsort(F[:, 1])
    ax.plot(F[o, 1], F[o, 0], **kw)


def pareto_front(result, path: Path) -> None:
    """Chamfer vs normalised cost (the paper's Pareto-front figure), coloured by the reference
    error when known; beside it, each solution's reference errors (or its deviation) vs cost."""
    F, cols, i = result.front.F, result.front.columns, result.chosen
    has_ref = "ref_rotation_deg" in cols
    fig, (a, b) = subplots(1, 2, figsize=(12.5, 4.8))
    _, Fn = result.nsga_front
    a.scatter(Fn[:, 1], Fn[:, 0], s=16, marker="x", color="0.6", lw=0.8,
              label=f"NSGA-II front before polish ({len(Fn)})")
    from matplotlib.colors import LogNorm

    c = cols["ref_rotation_deg"] if has_ref else result.front.X[:, 6]
    # Errors span decades (a few cheap solutions are degrees off): a log colour scale.
    sc = a.scatter(F[:, 1], F[:, 0], c=np.maximum(c, 1e-3), cmap="viridis", s=30, edgecolor="k",
                   lw=0.3, zorder=3, norm=LogNorm(), label=f"final front ({len(F)})")
    fig.colorbar(sc, ax=a, label="rotation error vs reference (deg, log)" if has_ref
                 else "n (points per frame, log)")
    a.scatter([F[i, 1]], [F[i, 0]], **STAR, label=f"chosen, n = {result.n_points}")
    a.set_xlabel("f2: normalised cost (t_norm + m_norm)")
    a.set_ylabel("f1: Chamfer objective (px)")
    a.set_title("Pareto front after NSGA-II and polish")
    a.grid(alpha=0.3)
    a.legend(fontsize=8)
    if has_ref:
        o = np.argsort(F[:, 1])
        b.plot(F[o, 1], cols["ref_rotation_deg"][o], "o-", ms=3.5, color="tab:blue",
               label="rotation error (deg)")
        b2 = b.twinx()
        b2.plot(F[o, 1], cols["ref_translation_cm"][o], "s--", ms=3.5, color="tab:orange",
                label="translation error (cm)")
        b.set_yscale("log")
        b2.set_yscale("log")
        b.set_ylabel("rotation error (deg, log)", color="tab:blue")
        b2.set_ylabel("translation error (cm, log)", color="tab:orange")
        h1, l1 = b.get_legend_handles_labels()
        h2, l2 = b2.get_legend_handles_labels()
        b.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper right")
        b.set_title("Error of each front solution against the reference")
    else:
        o = np.argsort(F[:, 1])
        b.plot(F[o, 1], cols["deviation_px"][o] + 0.1, "o-", ms=3.5)
        b.set_yscale("log")
        b.set_ylabel("deviation from best-supported solution + 0.1 (px)")
        b.set_title("Calibration deviation along the front")
    b.axvline(F[i, 1], color="tab:red", ls=":", lw=1)
    b.set_xlabel("f2: normalised cost")
    b.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path)


def solution_space(result, path: Path) -> None:
    """The Pareto set's translations (cm) and rotations (deg) in 3-D, coloured by n."""
    X = result.front.X
    Xn, _ = result.nsga_front
    fig = new_figure(figsize=(12.5, 5.4))
    norm = Normalize(np.log10(max(X[:, 6].min(), 1)), np.log10(X[:, 6].max()) + 1e-9)
    for k, (cols, unit, scale, title) in enumerate(
            (((0, 1, 2), "cm", 100.0, "translation correction"),
             ((3, 4, 5), "deg", 1.0, "rotation correction"))):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        ax.scatter(*(Xn[:, c] * scale for c in cols), s=10, marker="x", color="0.6",
                   label="NSGA-II front")
        sc = ax.scatter(*(X[:, c] * scale for c in cols), c=np.log10(X[:, 6]), cmap="viridis",
                        norm=norm, s=28, edgecolor="k", lw=0.3, depthshade=False,
                        label="final front")
        j = result.chosen
        ax.scatter(*([X[j, c] * scale] for c in cols), **{**STAR, "s": 200}, label="chosen")
        names = ("x", "y", "z") if k == 0 else ("yaw", "pitch", "roll")
        ax.set_xlabel(f"{names[0]} ({unit})", labelpad=6)
        ax.set_ylabel(f"{names[1]} ({unit})", labelpad=6)
        ax.set_zlabel(f"{names[2]} ({unit})", labelpad=6)
        ax.set_title(f"Pareto set: {title}")
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7, loc="upper left")
    fig.colorbar(sc, ax=fig.axes, shrink=0.6, label="log10 n (points per frame)")
    save_figure(fig, path)


def single_objective(so: dict, path: Path) -> None:
    """Convergence of the Chamfer-only runs: DE per generation, then Powell per iteration."""
    fig, (a, b) = subplots(1, 2, figsize=(12.5, 4.6))
    h = so["de_history"]
    ev = [r["evaluations"] for r in h]
    a.plot(ev, [r["best_f1"] for r in h], "-", color="tab:blue", label="DE best")
    a.plot(ev, [r["median_f1"] for r in h], "-", color="tab:blue", alpha=0.4,
           label="DE population median")
    a.axhline(so["front_best_f1"], color="tab:red", ls="--", lw=1,
              label=f"NSGA-II front best ({so['front_best_f1']:.4f})")
    lo = min(so["front_best_f1"], min(r["best_f1"] for r in h))
    hi = np.percentile([r["median_f1"] for r in h], 80)
    a.set_ylim(lo - 0.05 * (hi - lo) - 1e-3, hi)
    a.set_xlabel("objective evaluations")
    a.set_ylabel("f1: Chamfer objective (px)")
    a.set_title(f"Differential evolution (DE/rand/1/bin), n = {int(so['x'][6])}")
    a.grid(alpha=0.3)
    a.legend(fontsize=8)
    loc = so["local_history"]
    b.plot([0] + [r["evaluations"] for r in loc], [so["f1_de"]] + [r["f1"] for r in loc], "o-",
           ms=3.5, color="tab:green", label="Powell from the DE result")
    b.axhline(so["front_best_f1"], color="tab:red", ls="--", lw=1, label="NSGA-II front best")
    b.set_xlabel("evaluations of the local search")
    b.set_ylabel("f1: Chamfer objective (px)")
    b.set_title("Local refinement (scipy Powell)")
    b.grid(alpha=0.3)
    b.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


def epsilon_constraint(result, rows: list[dict], path: Path) -> None:
    """The epsilon-constraint solutions over the NSGA-II front, and their gap to it."""
    F = result.front.F
    fig, (a, b) = subplots(1, 2, figsize=(12.5, 4.6), gridspec_kw={"width_ratios": [3, 2]})
    _front_line(a, F, color="tab:blue", lw=1, marker="o", ms=3.5, label="NSGA-II front (final)")
    ok = [r for r in rows if r.get("feasible")]
    for r in rows:
        a.axvline(r["eps"], color="0.75", ls=":", lw=0.8)
    a.scatter([r["f2"] for r in ok], [r["f1_ga"] for r in ok], s=50, facecolor="none",
              edgecolor="tab:orange", lw=1.2, zorder=4, label="GA with f2 <= eps")
    a.scatter([r["f2"] for r in ok], [r["f1"] for r in ok], s=50, color="tab:orange",
              edgecolor="k", lw=0.5, zorder=5, label="the same, polished")
    a.set_xscale("log")
    a.set_xlabel("f2: normalised cost (log); dotted: the limits eps")
    a.set_ylabel("f1: Chamfer objective (px)")
    a.set_title("Epsilon-constraint points over the Pareto front")
    a.grid(alpha=0.3, which="both")
    a.legend(fontsize=8)
    lab = [f"{r['eps']:.3g}" for r in ok]
    b.bar(range(len(ok)), [r["gap"] for r in ok], color="tab:orange", edgecolor="k", lw=0.5)
    b.axhline(0, color="k", lw=0.8)
    b.set_xticks(range(len(ok)), lab, rotation=30, fontsize=8)
    b.set_xlabel("cost limit eps")
    b.set_ylabel("f1(eps point) - best front f1 within eps (px)")
    b.set_title("Gap to the front (below 0: beats the front)")
    b.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    save_figure(fig, path)


def decision(result, path: Path) -> dict:
    """The knee rule's figure with its knee region, and the paper's Chamfer knee for contrast.

    Returns ``{"region": [front indices in the knee region]}`` (at least half the knee's
    distance below the chord, among the rule's candidates).
    """
    from ..decide import knee_candidates, knee_index, knee_region

    F, cols, i = result.front.F, result.front.columns, result.chosen
    dev = cols["deviation_px"]
    cand, Fd = knee_candidates(F, dev, result.settings.decision.max_deviation_px)
    region = [int(cand[j]) for j in knee_region(Fd[cand])] if len(cand) >= 3 else []
    fig, (a, b) = subplots(1, 2, figsize=(12.5, 4.6))
    a.plot(F[:, 1], dev + 0.1, "o", ms=4, color="0.7", label="front solutions")
    o = cand[np.argsort(F[cand, 1])]
    a.plot(F[o, 1], dev[o] + 0.1, "o-", ms=4, color="tab:purple", lw=1,
           label="candidates (within the deviation limit)")
    if region:
        a.scatter(F[region, 1], dev[region] + 0.1, s=110, facecolor="none", edgecolor="tab:green",
                  lw=1.5, zorder=4, label="knee region")
    a.scatter([F[i, 1]], [dev[i] + 0.1], **STAR, label=f"chosen (knee), n = {result.n_points}")
    a.set_yscale("log")
    a.set_xlabel("f2: normalised cost")
    a.set_ylabel("deviation from best-supported solution + 0.1 (px, log)")
    a.set_title("Preference: knee of deviation vs cost")
    a.grid(alpha=0.3, which="both")
    a.legend(fontsize=8)
    k = knee_index(F)
    _front_line(b, F, color="tab:blue", marker="o", ms=3.5, lw=1, label="Pareto front")
    b.scatter([F[k, 1]], [F[k, 0]], s=140, marker="D", color="tab:cyan", edgecolor="k",
              zorder=4, label=f"paper's knee of the Chamfer front, n = {int(result.front.X[k, 6])}")
    b.scatter([F[i, 1]], [F[i, 0]], **STAR, label="chosen")
    b.set_xlabel("f2: normalised cost")
    b.set_ylabel("f1: Chamfer objective (px)")
    b.set_title("The same solutions on the Chamfer front")
    b.grid(alpha=0.3)
    b.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
    return {"region": region}


def projections(frame, result, path: Path, max_depth: float = 30.0) -> None:
    """LiDAR projected with the initial, the chosen and (if known) the reference extrinsic."""
    rows = [("initial extrinsic", result.T_init), ("chosen calibration", result.T_cam_lidar)]
    if result.T_ref is not None:
        rows.append(("dataset reference extrinsic", result.T_ref))
    h, w = frame.image.shape[:2]
    fig, axes = subplots(len(rows), 1, figsize=(w / 100, len(rows) * (h / 100 + 0.35)))
    for ax, (title, T) in zip(axes, rows):
        k = draw_overlay(ax, frame, T, result.settings.features.z_min, max_depth)
        ax.set_title(f"{title}: {k} points in view", fontsize=10, loc="left")
    fig.text(0.99, 0.005, f"frame {frame.name}; colour = depth 0-{max_depth:g} m; {data_credit(frame)}",
             ha="right", fontsize=7, color="0.3")
    fig.tight_layout()
    save_figure(fig, path, dpi=100)


def innovization(X: np.ndarray, F: np.ndarray, corr: list[dict], fits: dict, path: Path) -> None:
    """Rank correlations, and the fitted trends of f1, f2 and the pose against n."""
    from ..search.problem import VARIABLES

    fig, axes = subplots(2, 2, figsize=(12.5, 8.6))
    a = axes[0, 0]
    M = np.array([[next(r["spearman"] for r in corr if r["variable"] == v and r["objective"] == o)
                   for o in ("f1", "f2")] for v in VARIABLES])
    im = a.imshow(M, cmap="RdBu_r", vmin=-1, vmax=1, aspect="auto")
    for (r, c), v in np.ndenumerate(M):
        a.text(c, r, "n/a" if np.isnan(v) else f"{v:+.2f}", ha="center", va="center", fontsize=9)
    a.set_xticks([0, 1], ["f1 (Chamfer)", "f2 (cost)"])
    a.set_yticks(range(len(VARIABLES)), VARIABLES)
    a.set_title("Spearman rank correlation over the Pareto set")
    fig.colorbar(im, ax=a, label="rho")
    n = X[:, 6]
    ng = np.geomspace(n.min(), n.max(), 100)
    a = axes[0, 1]
    a.scatter(n, F[:, 0], s=20, color="tab:blue", label="front")
    if "chamfer_vs_n" in fits:
        c = fits["chamfer_vs_n"]
        a.plot(ng, c["a"] + c["b"] / np.sqrt(ng), color="tab:red", lw=1,
               label=f"f1 = {c['a']:.3f} + {c['b']:.3f}/sqrt(n), R^2 = {c['r2']:.2f}")
    a.set_xscale("log")
    a.set_xlabel("n (points per frame, log)")
    a.set_ylabel("f1: Chamfer objective (px)")
    a.set_title("Chamfer vs n")
    a.grid(alpha=0.3, which="both")
    a.legend(fontsize=8)
    a = axes[1, 0]
    a.scatter(n, F[:, 1], s=20, color="tab:blue", label="front")
    if "cost_vs_n" in fits:
        c = fits["cost_vs_n"]
        a.plot(ng, c["a"] + c["b"] * ng, color="tab:red", lw=1,
               label=f"f2 = {c['a']:.3g} + {c['b']:.3g} n, R^2 = {c['r2']:.3f}")
    a.set_xlabel("n (points per frame)")
    a.set_ylabel("f2: normalised cost")
    a.set_title("Cost vs n")
    a.grid(alpha=0.3)
    a.legend(fontsize=8)
    a = axes[1, 1]
    o = np.argsort(n)
    for j, v in enumerate(VARIABLES[:6]):
        scale, unit = (100.0, "cm") if j < 3 else (1.0, "deg")
        a.plot(n[o], (X[o, j] - X[o[-1], j]) * scale, "o-" if j < 3 else "s--", ms=3, lw=1,
               label=f"{v} ({unit})")
    a.set_xscale("log")
    a.set_yscale("symlog", linthresh=1.0)   # cheap solutions can be tens of cm off
    a.set_xlabel("n (points per frame, log)")
    a.set_ylabel("variable minus its value at the largest n\n(cm or deg, symmetric log)")
    a.set_title("Pose along the front")
    a.grid(alpha=0.3, which="both")
    a.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    save_figure(fig, path)


def robustness(rows: list[dict], summary: dict, path: Path) -> None:
    """Final objective and reference errors against w1, one point per seed."""
    has_ref = "rotation_deg" in rows[0]
    panels = [("f1", "f1 of the chosen solution (px)")]
    if has_ref:
        panels += [("rotation_deg", "rotation error vs reference (deg, log)"),
                   ("translation_cm", "translation error vs reference (cm, log)")]
    fig, axes = subplots(1, len(panels), figsize=(4.6 * len(panels), 4.2))
    axes = np.atleast_1d(axes)
    w = np.array([r["w1"] for r in rows])
    ws = sorted(set(w))
    for ax, (key, label) in zip(axes, panels):
        v = np.array([r[key] for r in rows])
        ax.scatter(w, v, s=22, color="tab:blue", alpha=0.7, label="one seed")
        ax.plot(ws, [np.median(v[w == x]) for x in ws], "-", color="tab:blue", lw=1.2,
                label="median over seeds")
        if summary.get("best_w1") is not None:
            ax.axvline(summary["best_w1"], color="tab:red", ls="--", lw=1,
                       label=f"best w1 = {summary['best_w1']:g}")
        if key != "f1":
            ax.set_yscale("log")          # failed weights are degrees off, good ones tenths
        ax.set_xlabel("w1 (depth-edge weight); w2 = 1 - w1")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_title("Robustness to the Chamfer weights", loc="left")
    fig.tight_layout()
    save_figure(fig, path)
