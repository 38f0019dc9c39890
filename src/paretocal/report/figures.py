"""Figures of a calibration run (matplotlib, headless)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..camera import project
from ..io.atomic import atomic_path
from ..io.frame import Frame
from ..io.layouts import KITTI_CREDIT  # noqa: F401 - the credit's text, for callers

def data_credit(frame: Frame) -> str:
    """The credit line figures of ``frame`` carry: KITTI's for KITTI frames, calib.yaml's
    ``credit`` for a folder that states one, none otherwise."""
    return getattr(frame, "credit", None) or ""


def new_figure(figsize=None, dpi=None) -> Figure:
    """A matplotlib Figure of its own: no pyplot, no global backend or figure registry, so
    importing paretocal leaves a notebook's or an application's matplotlib set-up alone."""
    return Figure(figsize=figsize, dpi=dpi)


def subplots(nrows: int = 1, ncols: int = 1, figsize=None, dpi=None, **kw):
    """``(figure, axes)`` like ``pyplot.subplots``, on a :func:`new_figure`."""
    fig = new_figure(figsize, dpi)
    return fig, fig.subplots(nrows, ncols, **kw)


def save_figure(fig, path: Path, dpi: int = 120) -> None:
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png", bbox_inches="tight")


def pareto_figure(result, path: Path) -> None:
    """Write :func:`pareto_plot` of ``result`` to ``path`` (PNG).

    Parameters
    ----------
    result : CalibrationResult
        The calibration.
    path : Path
        The PNG to write (atomically).
    """
    save_figure(pareto_plot(result), path)


def searched_front(result) -> tuple[np.ndarray | None, str, str]:
    """The search's front before the polish as ``pareto.png`` draws it beside the final one:
    ``(F, label, caption)``, F (k, 2) or None without one.

    The polish re-chooses the feature points at the estimate (``features.reselect``) and the
    final front is polished and scored on those: the search scored its own front on the points
    chosen at the initial extrinsic, another point set, on which f1 is not comparable (on
    ``make demo``'s run the search's best f1 is -2.78 there, the final front's -2.61; on the
    final points the search's best scores -2.58). So that front is drawn re-scored on the
    final front's points when the run's objective is at hand, and said to be on other points
    when it is not.

    Parameters
    ----------
    result : CalibrationResult
        The calibration.

    Returns
    -------
    F : ndarray, shape (k, 2), or None
    label : str
        Its legend entry.
    caption : str
        A line under the figure saying what the two fronts' f1 are measured on ("" when they
        share one objective).
    """
    if result.nsga_front is None:
        return None, "", ""
    Xn, Fn = result.nsga_front
    s = result.settings
    if not (s.decision.polish and s.features.reselect):
        return Fn, "NSGA-II front (before polish)", ""
    objective = getattr(result, "objective", None)
    if objective is None:
        return (Fn, "NSGA-II front before polish (f1 on other points)",
                "f1 of the NSGA-II front is on the feature points chosen at the initial "
                "extrinsic; the final front's on those chosen again at the estimate after the "
                "polish (features.reselect): not comparable")
    X = np.array(Xn, dtype=np.float64, copy=True)
    X[:, 6] = np.clip(X[:, 6], *result.n_range)
    return (np.asarray(objective.evaluate(X), dtype=np.float64),
            "NSGA-II front before polish, re-scored on the final points",
            "Both fronts' f1 on the feature points chosen again at the estimate after the "
            "polish (features.reselect); the search scored its front on those chosen at the "
            "initial extrinsic, on which its f1 is not comparable with the final front's")


def pareto_plot(result) -> Figure:
    """The Pareto front (Chamfer vs normalised cost) with the chosen solution and the search's
    front before the polish (:func:`searched_front`); the deviation of each solution from the
    best-supported one against its cost (what the knee rule reads); and, when the reference is
    known, each solution's error against it; the verdict in the title.

    Parameters
    ----------
    result : CalibrationResult
        The calibration.

    Returns
    -------
    Figure
    """
    front = result.front
    F, cols = front.F, front.columns
    has_ref = "ref_rotation_deg" in cols
    panels = 3 if has_ref else 2
    fig, axes = subplots(1, panels, figsize=(5.6 * panels, 4.6))
    i = result.chosen
    ax = axes[0]
    Fn, searched, caption = searched_front(result)
    if Fn is not None:
        ax.scatter(Fn[:, 0], Fn[:, 1], s=14, marker="x", color="0.6", lw=0.8, label=searched)
    if has_ref:
        sc = ax.scatter(F[:, 0], F[:, 1], c=cols["ref_rotation_deg"], cmap="viridis", s=26,
                        edgecolor="k", lw=0.3, label="final front", zorder=3)
        fig.colorbar(sc, ax=ax, label="rotation error vs reference (deg)")
    else:
        ax.scatter(F[:, 0], F[:, 1], s=26, color="tab:blue", edgecolor="k", lw=0.3,
                   label="final front", zorder=3)
    ax.scatter([F[i, 0]], [F[i, 1]], s=220, marker="*", color="tab:red", edgecolor="k",
               zorder=4, label=f"chosen ({result.decision.rule}, n = {result.n_points})")
    ax.set_xlabel("f1: Chamfer objective (px, lower is better)")
    ax.set_ylabel("f2: normalised cost (t_norm + m_norm)")
    ax.set_title("Pareto front")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")

    ms = cols["ms"]
    ax = axes[1]
    dev = cols["deviation_px"]
    ax.plot(ms, dev + 0.1, "o-", ms=3.5, color="tab:purple", lw=1)
    ax.scatter([ms[i]], [dev[i] + 0.1], s=220, marker="*", color="tab:red", edgecolor="k",
               zorder=4, label=f"chosen, {dev[i]:.2f} px")
    limit = result.decision.max_deviation_px
    if limit is not None:
        ax.axhline(limit + 0.1, color="0.4", ls="--", lw=1, label=f"acceptance, {limit:g} px")
    ax.set_yscale("log")
    ax.set_xlabel("modelled evaluation time (ms)")
    ax.set_ylabel("deviation from best-supported solution + 0.1 (px, log)")
    ax.set_title("Calibration deviation vs cost (knee rule)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="best")

    if has_ref:
        ax2 = axes[2]
        ax2.plot(ms, cols["ref_rotation_deg"], "o-", color="tab:blue", ms=3.5, lw=1,
                 label="rotation error (deg)")
        ax2.set_xlabel("modelled evaluation time (ms)")
        ax2.set_ylabel("rotation error (deg)", color="tab:blue")
        ax3 = ax2.twinx()
        ax3.plot(ms, cols["ref_translation_cm"], "s--", color="tab:orange", ms=3.5, lw=1,
                 label="translation error (cm)")
        ax3.set_ylabel("translation error (cm)", color="tab:orange")
        ax2.axvline(ms[i], color="tab:red", lw=1, ls=":", label="chosen")
        ax2.set_title("Error against the dataset's reference")
        ax2.grid(alpha=0.3)
        h1, l1 = ax2.get_legend_handles_labels()
        h2, l2 = ax3.get_legend_handles_labels()
        ax2.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper center")
    rel = getattr(result, "reliability", None)
    if rel is not None:
        from ..verdict import verdict_text

        ok = rel.ok
        fig.suptitle(textwrap.fill(verdict_text(rel), 40 * panels), fontsize=10,
                     color="darkgreen" if ok else "darkred", fontweight="bold")
    fig.tight_layout()
    if caption:
        fig.text(0.01, -0.01, textwrap.fill(caption, 50 * panels), fontsize=8, va="top",
                 color="0.3")
    return fig


def draw_overlay(ax, frame: Frame, T: np.ndarray, z_min: float = 0.1,
                 max_depth: float = 30.0) -> int:
    """Draw the frame's image with every LiDAR return in view at its projection, coloured by
    depth (near on top); returns the number of points in view."""
    uv, z, vis = project(frame.points, frame.camera, T, z_min)
    rgb = frame.image[:, :, ::-1]
    h, w = rgb.shape[:2]
    ax.imshow(rgb)
    order = np.argsort(-z[vis])            # far first, near on top
    ax.scatter(uv[vis][order, 0], uv[vis][order, 1], c=np.clip(z[vis][order], 0, max_depth),
               cmap="turbo_r", s=1.2, lw=0, vmin=0, vmax=max_depth)
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.axis("off")
    return int(vis.sum())


def overlay_figure(frame: Frame, T: np.ndarray, path: Path, title: str,
                   z_min: float = 0.1, max_depth: float = 30.0) -> None:
    """The frame's image with every LiDAR return in view drawn at its projection, by depth."""
    h, w = frame.image.shape[:2]
    fig = new_figure(figsize=(w / 100, h / 100 + 0.45), dpi=100)
    ax = fig.add_axes((0, 0, 1, h / (h + 45)))
    k = draw_overlay(ax, frame, T, z_min, max_depth)
    fig.text(0.01, 1 - 0.3 * 45 / (h + 45), title, fontsize=11, va="center")
    fig.text(0.99, 1 - 0.3 * 45 / (h + 45), f"{k} points in view, colour = depth "
             f"0-{max_depth:g} m   {data_credit(frame)}", fontsize=7, va="center", ha="right",
             color="0.3")
    save_figure(fig, path, dpi=100)
