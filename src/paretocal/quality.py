"""How much to trust a calibration without ground truth.

Everything here comes from one batched evaluation of the objective on a finite-difference stencil
around the extrinsic (28 candidates), read frame by frame:

* **curvature per degree of freedom**: the Hessian of the objective (px per cm^2 or deg^2); the
  displacement along each axis that raises the objective by 0.01 px; and the flattest direction,
  the combination of axes the scene constrains least.
* **agreement across frames**: the jackknife standard error of each axis (deg, cm), linearised
  (each frame's gradient through the mean objective's Hessian); and each frame's own Newton
  step, which says which frames disagree.
* **miscalibration check** (after Levinson & Thrun, RSS 2013): a correct extrinsic is a local
  minimum of the objective, so few of its grid neighbours score better; and the local optimum
  found from it lies within a pixel or two of it. The verdict uses the pixel displacement of the
  local optimum, which is comparable across scenes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import correction_matrix
from .objective.objective import AlignmentObjective
from .search.polish import DEFAULT_FD_STEP, fd_stencil, newton_step, stencil_derivatives

#: The Newton steps' floor on the Hessian's eigenvalues, relative to the largest
#: (:func:`paretocal.search.polish.newton_step`'s default).
EIG_FLOOR = 1e-3

AXES = ("x", "y", "z", "yaw", "pitch", "roll")
UNITS = ("cm", "cm", "cm", "deg", "deg", "deg")
TO_REPORT = np.array([100.0, 100.0, 100.0, 1.0, 1.0, 1.0])   # m -> cm for display


def cm_written(m: float, digits: int) -> float:
    """A length ``m`` (metres) in centimetres rounded to ``digits``, as result.json writes it.

    A record holding a figure result.json writes in cm rounded to ``digits`` holds that
    figure / 100; this gives the written figure back exactly (``m * 100`` alone can miss it
    in the last bit, and rounding again to the same digits recovers it).

    Parameters
    ----------
    m : float
        A length in metres.
    digits : int
        The decimals of the figure written in cm.

    Returns
    -------
    float
        The length in cm.
    """
    return round(float(m) * 100.0, digits)

#: Finite-difference step of the run's quality report, in pixels: each axis is stepped by the
#: change that moves the projected feature points by this much on average. The objective reads
#: distance transforms of pixel-quantised edges, so differences over steps of about a pixel
#: measure that quantisation rather than the objective's shape: with the fixed 1 cm / 0.1 deg
#: steps (0.4-1.5 px on KITTI) the jackknife standard errors came out up to 10-50 times their
#: value with larger steps (z 10 cm for a result 1.1 cm off); from 2 to 8 times the fixed
#: steps they agree within a factor of 2 (14 KITTI results).
FD_STEP_PX = 2.0
#: ... and never beyond ten fixed steps (10 cm, 1 deg): an axis that hardly moves the points
#: is not determined, whatever the step.
MAX_FD_STEP = 10.0 * DEFAULT_FD_STEP


def _derivatives(values: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient (6,) and Hessian (6, 6) from the 28 stencil values of one candidate."""
    _, g, H = stencil_derivatives(values[None], h)
    return g[0], H[0]


def _newton_step(g: np.ndarray, H: np.ndarray, h: np.ndarray, max_units: float = 10.0):
    """Step (6,) in m and deg to the minimum of the local quadratic (|eigenvalues| floored)."""
    return newton_step(g[None], H[None], h, max_units)[0]


def _jackknife_se(per_frame: np.ndarray, H: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Jackknife standard errors (6,) in m and deg of the optimum of the mean over frames.

    Linearised (the infinitesimal jackknife): leaving frame f out moves the optimum by
    ``H^-1 (g_f - g_mean) / (F - 1)``, with ``g_f`` frame f's gradient (from the stencil
    values ``per_frame`` (28, F)) and ``H`` (6, 6) the Hessian of the mean, so the variance is
    ``H^-1 B H^-1`` with ``B = sum_f (g_f - g_mean)(g_f - g_mean)^T / (F (F - 1))``.

    A Newton step on each leave-one-out objective, each with its own Hessian, gives the same
    where the objective is well curved; but along its flattest direction (camera height
    against pitch, barely curved or slightly concave at the steps' scale) one frame more or
    less changes that Hessian's smallest eigenvalue enough to scatter the steps (2-10 times
    these errors, more the larger the steps). Even through the common Hessian, a curvature the
    frames do not pin down must not be divided by: each eigenvalue of ``H`` is taken in
    absolute value and raised to twice its standard error over the frames (the frames'
    curvatures along its eigenvector), and to :data:`EIG_FLOOR` times the largest, as the
    Newton steps floor it. Without that, a smallest eigenvalue near zero gave 14 cm in z for
    KITTI results 1-2 cm off. NaN with one frame.
    """
    F = per_frame.shape[1]
    if F < 2:
        return np.full(6, np.nan)
    _, G, Hf = stencil_derivatives(per_frame.T, h)                     # (F, 6), (F, 6, 6)
    D = G - G.mean(axis=0)
    B = D.T @ D / (F * (F - 1))
    scale = np.outer(h, h)                                              # to units of h
    w, V = np.linalg.eigh(H * scale)
    c = np.einsum("ik,fij,jk->fk", V, Hf * scale, V)                   # frames' curvatures
    w = np.maximum.reduce([np.abs(w), 2.0 * c.std(axis=0, ddof=1) / np.sqrt(F),
                           np.full(6, max(np.abs(w).max() * EIG_FLOOR, 1e-12))])
    Hi = (V / w) @ V.T * scale
    return np.sqrt(np.maximum(np.diag(Hi @ B @ Hi), 0.0))


def at_every_point(objective: AlignmentObjective, x: np.ndarray) -> np.ndarray:
    """A copy of the solution ``x`` (7,) (or solutions (k, 7)) with ``n`` set to every feature
    point of the frames.

    Parameters
    ----------
    objective : AlignmentObjective
        The objective whose frames count.
    x : array_like, shape (7,) or (k, 7)
        Solutions ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).

    Returns
    -------
    ndarray, of ``x``'s shape
    """
    x = np.array(x, dtype=np.float64, copy=True)
    x[..., 6] = int(objective.scene.points_per_frame.max())
    return x


@dataclass(frozen=True)
class Quality:
    """The quality report of an extrinsic (:func:`quality_report`), in SI units.

    Every per-axis array is on the correction's axes ``x, y, z, yaw, pitch, roll``
    (:data:`AXES`: translation in the LiDAR frame in metres, rotation in degrees).

    Attributes
    ----------
    frames : int
        Frames the report is over.
    fd_step : ndarray, shape (6,)
        Finite-difference steps (m, deg).
    curvature : ndarray, shape (6,)
        The objective's second derivative along each axis (px per m^2, px per deg^2).
    tolerance : ndarray, shape (6,)
        The change along each axis alone that raises the objective by 0.01 px (m, deg).
    flattest_direction : ndarray, shape (6,)
        The combination of axes the scene constrains least (m, deg), scaled so that its
        largest part is 1 cm or 0.1 deg; ``flattest_eigenvalue_ratio`` its curvature over the
        steepest direction's.
    flattest_eigenvalue_ratio : float
    jackknife_se : ndarray, shape (6,)
        Jackknife standard error of each axis over the frames (m, deg); NaN with one frame.
    step_to_local_optimum : ndarray, shape (6,)
        The Newton step to the minimum of the local quadratic (m, deg).
    frame_steps : ndarray, shape (F, 6)
        Each frame's own Newton step (m, deg): which frames disagree.
    well_observed : ndarray, shape (6,), bool
        Jackknife standard error under 3 cm or 0.2 deg.
    """

    frames: int
    fd_step: np.ndarray
    curvature: np.ndarray
    tolerance: np.ndarray
    flattest_direction: np.ndarray
    flattest_eigenvalue_ratio: float
    jackknife_se: np.ndarray
    step_to_local_optimum: np.ndarray
    frame_steps: np.ndarray
    well_observed: np.ndarray

    def to_dict(self) -> dict:
        """The report as ``result.json`` writes it: per axis by name, translation in cm (the
        curvature per cm^2), rotation in deg; ``frame`` ``"lidar"`` and ``units``."""
        def per_axis(v):
            return {a: float(val) for a, val in zip(AXES, np.asarray(v) * TO_REPORT)}

        return {
            "frame": "lidar",                 # the per-axis figures are the correction's axes
            "units": dict(zip(AXES, UNITS)),
            "frames": int(self.frames),
            "fd_step": per_axis(self.fd_step),
            "curvature_px_per_unit2": {a: float(c / TO_REPORT[i] ** 2)
                                       for i, (a, c) in enumerate(zip(AXES, self.curvature))},
            "tolerance_0p01px": per_axis(self.tolerance),
            "flattest_direction": per_axis(self.flattest_direction),
            "flattest_eigenvalue_ratio": float(self.flattest_eigenvalue_ratio),
            "jackknife_se": per_axis(self.jackknife_se),
            "step_to_local_optimum": per_axis(self.step_to_local_optimum),
            "frame_steps": [per_axis(s) for s in self.frame_steps],
            "well_observed": {a: bool(v) for a, v in zip(AXES, self.well_observed)},
        }

    @classmethod
    def from_dict(cls, doc: dict) -> "Quality":
        """The report read back from its :meth:`to_dict` form (``result.json``'s
        ``quality``); a key it lacks reads as NaN (False for ``well_observed``).

        Parameters
        ----------
        doc : dict
            The :meth:`to_dict` form (cm and deg).
        """
        def si(key):
            v = doc.get(key) or {}
            return np.array([v.get(a, np.nan) for a in AXES], dtype=np.float64) / TO_REPORT

        curv = doc.get("curvature_px_per_unit2") or {}
        return cls(
            frames=int(doc.get("frames", 0)), fd_step=si("fd_step"),
            curvature=np.array([curv.get(a, np.nan) for a in AXES], float) * TO_REPORT ** 2,
            tolerance=si("tolerance_0p01px"), flattest_direction=si("flattest_direction"),
            flattest_eigenvalue_ratio=float(doc.get("flattest_eigenvalue_ratio", np.nan)),
            jackknife_se=si("jackknife_se"), step_to_local_optimum=si("step_to_local_optimum"),
            frame_steps=np.array([[s.get(a, np.nan) for a in AXES]
                                  for s in doc.get("frame_steps") or []],
                                 dtype=np.float64).reshape(-1, 6) / TO_REPORT,
            well_observed=np.array([bool((doc.get("well_observed") or {}).get(a, False))
                                    for a in AXES]))


def quality_report(objective: AlignmentObjective, x: np.ndarray, h: np.ndarray = DEFAULT_FD_STEP) -> Quality:
    """Curvature, identifiability and frame agreement of the extrinsic ``x``.

    Parameters
    ----------
    objective : CalibrationObjective
        Evaluated with its sampling-error charge off (the plain mean over all points).
    x : ndarray, shape (7,)
        The solution ``[x, y, z, yaw, pitch, roll, n]``; evaluated with every point.
    h : ndarray, shape (6,)
        Finite-difference steps (m, deg); a run uses :func:`pixel_fd_step`.

    Returns
    -------
    Quality
        In metres and degrees (:meth:`Quality.to_dict` gives ``result.json``'s form).
    """
    x = at_every_point(objective, x)
    S = fd_stencil(h)
    cand = np.tile(x, (len(S), 1))
    cand[:, :6] += S
    per_frame = objective.chamfer(cand, ucb_k=0.0)["per_frame"]              # (28, F)
    F = per_frame.shape[1]
    g, H = _derivatives(per_frame.mean(axis=1), h)
    curv = np.diag(H)
    tol = np.sqrt(2 * 0.01 / np.maximum(curv, 1e-12))
    w, V = np.linalg.eigh(H * h[:, None] * h[None, :])
    flat = V[:, 0] * h
    flat /= np.abs(flat / np.r_[[0.01] * 3, [0.1] * 3]).max()         # largest part 1 cm / 0.1 deg
    steps = np.array([_newton_step(*_derivatives(per_frame[:, f], h), h) for f in range(F)])
    se = _jackknife_se(per_frame, H, h)
    well = np.isfinite(se) & (se < np.r_[[0.03] * 3, [0.2] * 3])
    return Quality(frames=int(F), fd_step=np.asarray(h, dtype=np.float64).copy(),
                   curvature=curv, tolerance=tol, flattest_direction=flat,
                   flattest_eigenvalue_ratio=float(w[0] / max(w[-1], 1e-12)),
                   jackknife_se=se, step_to_local_optimum=_newton_step(g, H, h),
                   frame_steps=steps.reshape(-1, 6), well_observed=well)


def axis_resolution(objective: AlignmentObjective, x: np.ndarray) -> np.ndarray:
    """Per-axis change (m, m, m, deg, deg, deg) that moves the projected feature points by one
    pixel on average at ``x`` (7,), the other axes held; inf for an axis that does not move
    them.

    Parameters
    ----------
    objective : AlignmentObjective
        The objective whose frames and feature points count.
    x : ndarray, shape (7,)
        The solution ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).

    Returns
    -------
    ndarray, shape (6,)
    """
    probe = np.r_[[0.01] * 3, [0.1] * 3]
    out = np.empty(6)
    for a in range(6):
        y = np.array(x, dtype=np.float64, copy=True)
        y[a] += probe[a]
        px = displacement_px(objective, x, y)
        out[a] = probe[a] / px if px > 0 else np.inf
    return out


def pixel_fd_step(objective: AlignmentObjective, x: np.ndarray) -> np.ndarray:
    """Finite-difference steps (6,) in m and deg for the quality report at ``x`` (7,): the
    change of each axis that moves the points by :data:`FD_STEP_PX` pixels, at most
    :data:`MAX_FD_STEP`.

    Parameters
    ----------
    objective : AlignmentObjective
        The objective whose frames and feature points count.
    x : ndarray, shape (7,)
        The solution ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).

    Returns
    -------
    ndarray, shape (6,)
    """
    return np.minimum(FD_STEP_PX * axis_resolution(objective, x), MAX_FD_STEP)


def neighbour_fraction(objective: AlignmentObjective, x: np.ndarray,
                       delta: np.ndarray) -> tuple[float, float]:
    """Levinson & Thrun's test: the share of the 3^6 - 1 grid neighbours of ``x`` (steps
    ``delta``, m and deg) that score lower than ``x`` itself, and the best improvement (px).

    Parameters
    ----------
    objective : AlignmentObjective
        The objective (read without the sampling-error charge).
    x : ndarray, shape (7,)
        The solution ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
    delta : ndarray, shape (6,)
        The grid's step per axis (m, deg).

    Returns
    -------
    fraction : float
        The share of neighbours scoring lower, in [0, 1].
    gain_px : float
        The best neighbour's improvement (px; 0 when none is better).
    """
    grid = np.stack(np.meshgrid(*[[-1.0, 0.0, 1.0]] * 6, indexing="ij"), -1).reshape(-1, 6)
    grid = grid[np.any(grid != 0, axis=1)]
    cand = np.tile(x, (len(grid) + 1, 1))
    cand[1:, :6] += grid * delta
    f = objective.chamfer(cand, ucb_k=0.0)["f1"]
    better = f[1:] < f[0]
    return float(better.mean()), float(max(0.0, f[0] - f[1:].min()))


def local_optimum(objective: AlignmentObjective, x: np.ndarray, iters: int = 15):
    """Polish ``x`` (7,) at every point, no sampling-error charge; returns the optimum (7,).

    ``x`` (k, 7): the k solutions are polished together (one objective call per step for all:
    the same optima as one by one, in less time), returning (k, 7).

    Parameters
    ----------
    objective : AlignmentObjective
        The objective.
    x : ndarray, shape (7,) or (k, 7)
        Solutions ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
    iters : int
        Newton iterations before the compass search.

    Returns
    -------
    ndarray, of ``x``'s shape
        The local optima, ``n`` at every point.
    """
    from .search.polish import newton_polish, polish

    x = at_every_point(objective, x)
    fun = lambda Z: objective.chamfer(Z, ucb_k=0.0)["f1"]  # noqa: E731
    Z, _, _ = newton_polish(fun, np.atleast_2d(x), iters=iters)
    Z, _, _ = polish(fun, Z, step=np.array([0.005] * 3 + [0.05] * 3))
    return Z[0] if x.ndim == 1 else Z


def displacement_px(objective: AlignmentObjective, x: np.ndarray, y: np.ndarray, frames=None):
    """Mean pixel distance between the feature points' projections under pose x (7,) and
    pose y (7,) (a float), or each of poses y (k, 7) (an array (k,)), over every frame or
    the frames of index ``frames``.

    Parameters
    ----------
    objective : AlignmentObjective
        The objective whose frames and feature points count.
    x : ndarray, shape (7,)
        The pose compared with (m, deg, points per frame).
    y : ndarray, shape (7,) or (k, 7)
        The pose or poses compared.
    frames : sequence of int, optional
        The frames' indices; every frame when omitted.

    Returns
    -------
    float or ndarray, shape (k,)
        The mean displacement (px).
    """
    from .decide import reprojection_deviation

    sc = objective.scene
    idx = range(sc.n_frames) if frames is None else frames
    y = np.asarray(y, dtype=np.float64)
    T = objective.transforms(np.vstack([x, np.atleast_2d(y)]))
    d = reprojection_deviation(T[1:], T[0], [sc.frame_xyz(f) for f in idx],
                               [sc.cameras[f] for f in idx], sc.z_min)
    return float(d[0]) if y.ndim == 1 else d


def correction_between(T_from: np.ndarray, T_to: np.ndarray) -> np.ndarray:
    """The correction D with ``T_to = T_from @ D``, as (x, y, z, yaw, pitch, roll).

    Parameters
    ----------
    T_from, T_to : ndarray, shape (..., 4, 4)
        Extrinsics ``T_cam_lidar`` (m).

    Returns
    -------
    ndarray, shape (..., 6)
        Metres and degrees, in ``T_from``'s LiDAR frame.
    """
    from .geometry import correction_params, invert

    return correction_params(invert(T_from) @ T_to)


__all__ = ["AXES", "at_every_point", "axis_resolution", "cm_written", "correction_between",
           "correction_matrix", "displacement_px", "local_optimum", "neighbour_fraction", "pixel_fd_step",
           "quality_report"]
