"""Choosing one calibration from the Pareto front.

* ``knee`` (default): the knee of the front of *calibration deviation* against cost. Each
  solution's deviation is how far, in pixels, its extrinsic moves the projections of held-out
  LiDAR points from where the best-supported solution (the lowest f1, which uses the most
  points) puts them. The Chamfer value itself is a poor guide to a pose's accuracy: on the
  KITTI sample, cheap solutions sat in a neighbouring pitch / height basin (0.6 deg, 9 cm off)
  whose Chamfer, on search or held-out points alike, was within 0.01 px of the right one,
  while their deviation was 2-3 px. The knee of log10(deviation + 0.1 px) vs cost is where
  using fewer points starts to move the calibration (the log keeps one wild cheap solution
  from flattening the rest of the curve; 0.1 px is where differences stop mattering). Only
  solutions within ``max_deviation_px`` (1 px) of the best-supported one are candidates: on
  the sample, some seeds left most of the front in the neighbouring basin (2 px away, 0.5 deg
  off), and the knee of such a front is a cheap wrong answer.
* ``knee-chamfer``: the paper's rule, the knee of the Chamfer-vs-cost front itself.
* Knee: the solution farthest below the straight line joining the two ends of the front, in
  objectives min-max normalised over the front. On a convex front this is where a further
  gain starts to cost disproportionately more computation. (pymoo's ``HighTradeoffPoints`` is
  not used: in pymoo 0.6.2 it ignores its epsilon and can return nothing.)
* ``budget``: the lowest f1 whose modelled evaluation time is within ``budget_ms``.
* ``min-chamfer``: the lowest f1 regardless of cost.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .errors import SettingsError

if TYPE_CHECKING:  # pragma: no cover
    from .search.basin import BasinTest


@dataclass(frozen=True)
class Decision:
    """How the solution was chosen from the front (:func:`decide`), and what the run adds about
    it (:meth:`with_run`).

    Times are in milliseconds, the cost model's unit; deviations in pixels.

    Attributes
    ----------
    rule : str
        ``"knee"``, ``"knee-chamfer"``, ``"budget"`` or ``"min-chamfer"``.
    deviation_px : float
        The chosen solution's deviation from the best-supported one (px).
    method : str or None
        The knee rules' method (None for the others).
    figure : str or None
        What the ``knee`` rule reads (None for the others).
    max_deviation_px : float or None
        The ``knee`` rule's acceptance limit (px); None for the others.
    budget_ms : float or None
        The ``budget`` rule's budget (ms per evaluation); None for the others.
    solutions_within_budget : int or None
        Solutions of the front the budget admits (``budget`` only).
    n_points : int or None
        Points per frame of the chosen solution; this and the fields after it are set by the
        pipeline (:meth:`with_run`), None for a bare :func:`decide`.
    front_size : int or None
        Solutions of the front.
    polished : bool or None
        Whether the front was polished.
    best_supported_n : int or None
        Points per frame of the best-supported solution (the lowest f1).
    basin : BasinTest or None
        The near/far basin test (:func:`paretocal.search.basin.prefer_near`), None when the
        front was not polished.
    measured_ms : float or None
        The chosen solution's evaluation time measured at the end of the run (ms); the
        modelled time decides.
    """

    rule: str
    deviation_px: float
    method: str | None = None
    figure: str | None = None
    max_deviation_px: float | None = None
    budget_ms: float | None = None
    solutions_within_budget: int | None = None
    n_points: int | None = None
    front_size: int | None = None
    polished: bool | None = None
    best_supported_n: int | None = None
    basin: "BasinTest | None" = None
    measured_ms: float | None = None

    def with_run(self, n_points: int, front_size: int, polished: bool, best_supported_n: int,
               basin: "BasinTest | None", measured_ms: float) -> "Decision":
        """The decision with what the run knows of the chosen solution and its front."""
        return dataclasses.replace(self, n_points=int(n_points), front_size=int(front_size),
                                   polished=bool(polished),
                                   best_supported_n=int(best_supported_n), basin=basin,
                                   measured_ms=float(measured_ms))

    def to_dict(self) -> dict[str, Any]:
        """The decision as ``result.json`` writes it: the rule, what it used, then what the
        run adds (from ``n_points`` on, when set)."""
        out: dict[str, Any] = {"rule": self.rule}
        if self.method is not None:
            out["method"] = self.method
        if self.budget_ms is not None:
            out["budget_ms"] = float(self.budget_ms)
            out["solutions_within_budget"] = self.solutions_within_budget
        out["deviation_px"] = float(self.deviation_px)
        if self.figure is not None:
            out["figure"] = self.figure
        if self.max_deviation_px is not None:
            out["max_deviation_px"] = float(self.max_deviation_px)
        if self.n_points is not None:
            out.update(n_points=self.n_points, front_size=self.front_size,
                       polished=self.polished, best_supported_n=self.best_supported_n,
                       basin=None if self.basin is None else self.basin.to_dict())
        if self.measured_ms is not None:
            out["measured_ms"] = float(self.measured_ms)
        return out

    @classmethod
    def from_dict(cls, doc: dict[str, Any]) -> "Decision":
        """The decision read back from its :meth:`to_dict` form (``result.json``'s
        ``decision``); a figure it lacks reads as None (NaN for ``deviation_px``)."""
        from .search.basin import BasinTest

        def opt(key, kind):
            v = doc.get(key)
            return None if v is None else kind(v)

        return cls(rule=str(doc.get("rule", "")),
                   deviation_px=float(doc.get("deviation_px", np.nan)),
                   method=opt("method", str), figure=opt("figure", str),
                   max_deviation_px=opt("max_deviation_px", float),
                   budget_ms=opt("budget_ms", float),
                   solutions_within_budget=opt("solutions_within_budget", int),
                   n_points=opt("n_points", int), front_size=opt("front_size", int),
                   polished=opt("polished", bool),
                   best_supported_n=opt("best_supported_n", int),
                   basin=opt("basin", BasinTest.from_dict),
                   measured_ms=opt("measured_ms", float))


def chord_distance(F: np.ndarray) -> np.ndarray:
    """Distance of each solution of a two-objective front F (k, 2) below its chord.

    The chord joins the two extreme solutions in objectives min-max normalised over the
    front; distances are positive on the side of the ideal point, shape (k,). All zeros for a
    front of fewer than three solutions or a degenerate chord.
    """
    F = np.asarray(F, dtype=np.float64)
    if len(F) < 3:
        return np.zeros(len(F))
    lo, hi = F.min(axis=0), F.max(axis=0)
    Z = (F - lo) / np.where(hi > lo, hi - lo, 1.0)
    a = Z[np.argmin(Z[:, 0])]            # best accuracy end
    b = Z[np.argmin(Z[:, 1])]            # cheapest end
    d = b - a
    norm = np.hypot(*d)
    if norm == 0:
        return np.zeros(len(F))
    dist = ((Z[:, 0] - a[0]) * d[1] - (Z[:, 1] - a[1]) * d[0]) / norm
    ideal_side = np.sign((0 - a[0]) * d[1] - (0 - a[1]) * d[0]) or 1.0
    return dist * ideal_side


def knee_index(F: np.ndarray) -> int:
    """Index of the knee of a two-objective front F (k, 2), both minimised.

    Returns the solution of largest perpendicular distance below the chord between the
    extreme solutions in normalised objective space (:func:`chord_distance`); with fewer than
    three solutions, or a front with no point below its chord, the lowest-f1 solution.
    """
    F = np.asarray(F, dtype=np.float64)
    dist = chord_distance(F)
    i = int(np.argmax(dist)) if len(F) else 0
    return i if len(F) >= 3 and dist[i] > 0 else int(np.argmin(F[:, 0]))


def knee_region(F: np.ndarray, share: float = 0.5) -> np.ndarray:
    """Indices of the solutions at least ``share`` of the knee's distance below the chord."""
    dist = chord_distance(F)
    top = dist.max() if len(dist) else 0.0
    return np.flatnonzero(dist >= share * top) if top > 0 else np.array([], dtype=int)


def reprojection_deviation(T: np.ndarray, T_best: np.ndarray, points: list[np.ndarray],
                           cameras: list, z_min: float = 0.1) -> np.ndarray:
    """Mean pixel displacement of projected points between each extrinsic and ``T_best``.

    Parameters
    ----------
    T : ndarray, shape (k, 4, 4)
    T_best : ndarray, shape (4, 4)
    points : list of ndarray, shape (M_f, 3)
        LiDAR points per frame (metres).
    cameras : list of Camera
    z_min : float

    Returns
    -------
    ndarray, shape (k,)
        Mean over the points visible under ``T_best`` of ``|uv(T_i) - uv(T_best)|`` in pixels,
        projected through each camera's model; a point that leaves the model's domain under
        ``T_i`` (behind the camera, beyond the lens's monotonic radius) counts as the image
        diagonal.
    """
    from .camera import project

    T = np.asarray(T, dtype=np.float64)
    total = np.zeros(len(T))
    count = 0
    for pts, cam in zip(points, cameras):
        uv0, _, vis = project(pts, cam, T_best, z_min)
        if not vis.any():
            continue
        P = np.asarray(pts, dtype=np.float64)[vis, :3]
        diag = float(np.hypot(cam.width, cam.height))
        uv, _, _ = project(P, cam, T, z_min)                                 # (k, m, 2)
        valid = np.isfinite(uv[..., 0])
        d = np.linalg.norm(uv - uv0[vis][None], axis=-1)
        d = np.where(valid, np.minimum(d, diag), diag)
        total += d.sum(axis=1)
        count += int(vis.sum())
    return total / max(count, 1)


def choose(F: np.ndarray, ms: np.ndarray, rule: str = "knee",
           budget_ms: float | None = None) -> tuple[int, Decision]:
    """Pick a solution of the front.

    Parameters
    ----------
    F : ndarray, shape (k, 2)
        Front objectives ``[accuracy figure, f2]`` (the knee uses both; the budget and
        min-chamfer rules use column 0 as the figure to minimise).
    ms : ndarray, shape (k,)
        Modelled evaluation time of each solution in milliseconds.
    rule : {"knee", "knee-chamfer", "budget", "min-chamfer"}
    budget_ms : float, optional
        Required by ``budget``.

    Returns
    -------
    index : int
    decision : Decision
        The rule and what it used, ``deviation_px`` NaN (:func:`decide` sets it).
    """
    if rule in ("knee", "knee-chamfer"):
        i = knee_index(F)
        return i, Decision(rule=rule, deviation_px=np.nan,
                           method="max distance below the chord (normalised)")
    if rule == "min-chamfer":
        return int(np.argmin(F[:, 0])), Decision(rule="min-chamfer", deviation_px=np.nan)
    if rule == "budget":
        if budget_ms is None:
            raise SettingsError("--budget-ms is required by the budget rule")
        ok = np.flatnonzero(np.asarray(ms) <= budget_ms)
        if len(ok) == 0:
            raise SettingsError(f"--budget-ms {budget_ms:g}: no solution of the front fits; the "
                                f"cheapest needs {float(np.min(ms)):.4g} ms")
        i = int(ok[np.argmin(F[ok, 0])])
        return i, Decision(rule="budget", deviation_px=np.nan, budget_ms=float(budget_ms),
                           solutions_within_budget=int(len(ok)))
    raise SettingsError(f"unknown decision rule {rule!r}")


DEVIATION_FLOOR_PX = 0.1  # deviations below this are equally good for the knee


def knee_candidates(F: np.ndarray, deviation: np.ndarray,
                    max_deviation_px: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The solutions the ``knee`` rule chooses among, and the figure it reads.

    Returns the sorted indices of the solutions non-dominated in
    ``Fd = [log10(deviation + 0.1), f2]`` whose deviation is within ``max_deviation_px`` (the
    best-supported solution always included), and ``Fd`` itself, shape (k, 2).
    """
    from .search.nsga import front_indices

    best = int(np.argmin(F[:, 0]))
    # Deviations span orders of magnitude (tens of px at the cheapest end, hundredths at the
    # dearest): judge them on a log scale, floored where differences stop mattering.
    Fd = np.column_stack([np.log10(deviation + DEVIATION_FLOOR_PX), F[:, 1]])
    candidates = np.sort(front_indices(Fd))
    # A cheaper solution is acceptable only if its calibration agrees with the best-supported
    # one: a neighbouring minimum can win on a small sample.
    agree = deviation[candidates] <= max_deviation_px
    return candidates[agree | (candidates == best)], Fd


def decide(F: np.ndarray, ms: np.ndarray, deviation: np.ndarray, rule: str = "knee",
           budget_ms: float | None = None, max_deviation_px: float = 1.0
           ) -> tuple[int, Decision]:
    """Choose a solution of the front by ``rule`` (see the module docstring).

    Parameters
    ----------
    F : ndarray, shape (k, 2)
        ``[f1, f2]`` of the front.
    ms : ndarray, shape (k,)
        Modelled evaluation time per solution (ms).
    deviation : ndarray, shape (k,)
        Pixel deviation of each solution from the best-supported one (lowest f1).
    rule, budget_ms, max_deviation_px
        As in :class:`paretocal.config.DecisionSettings`.

    Returns
    -------
    index : int
    decision : Decision
        The rule, what it used and the chosen solution's deviation.
    """
    if rule == "knee":
        candidates, Fd = knee_candidates(F, deviation, max_deviation_px)
    else:
        Fd, candidates = F, np.arange(len(F))
    j, decision = choose(Fd[candidates], ms[candidates], rule, budget_ms)
    i = int(candidates[j])
    decision = dataclasses.replace(decision, deviation_px=float(deviation[i]))
    if rule == "knee":
        decision = dataclasses.replace(decision, figure="log10(deviation_px + 0.1) vs cost",
                                       max_deviation_px=float(max_deviation_px))
    return i, decision
