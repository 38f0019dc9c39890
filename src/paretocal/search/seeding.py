"""Seeds for the search: a coarse, exhaustive look at the rotations before NSGA-II starts.

With the paper's bounds (+-25 deg, +-1.5 m) the basin of the right pose is a needle: the edge
objective only sees a point within its truncation distance (10 px, under 1 deg at KITTI's focal
length) of an image edge, and from a start several degrees off, NSGA-II can settle in a false
basin. A misalignment is mostly rotation, so every rotation of a grid over the bounds is scored
at zero translation on a coarse objective (distance transform truncated at 30 px, a few hundred
points per frame), in one batched call; the best few are polished in all six degrees of freedom
and join the initial population. Costs about a second for 9,261 rotations on 20 frames.
"""

from __future__ import annotations

import numpy as np

from ..config import SEED_JOINT_STEP_DEG, ObjectiveSettings, SearchSettings, grid_half_steps
from .polish import newton_polish

JOINT_FRAMES = 6  # frames scoring the joint rotation x translation grid


def rotation_grid(bound_deg: float, step_deg: float) -> np.ndarray:
    """All (yaw, pitch, roll) on a regular grid within +-bound, shape (G, 3), degrees."""
    k = grid_half_steps(bound_deg, step_deg)
    axis = np.arange(-k, k + 1) * step_deg
    g = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    return g


def translation_grid(bound_m: float, step_m: float) -> np.ndarray:
    """All (x, y, z) on a regular grid within +-bound, shape (G, 3), metres."""
    k = grid_half_steps(bound_m, step_m)
    axis = np.arange(-k, k + 1) * step_m
    return np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)


def grid_seeds(  # noqa: PLR0913 - the grid, then keyword-only options
        chamfer, bound_r_deg: float, bound_t_m: float, step_deg: float, n: int, keep: int, *,
        chunk: int = 4096, step_t_m: float | None = None,
        joint_step_deg: float = SEED_JOINT_STEP_DEG,
        joint_n: int = 30, joint_chamfer=None) -> tuple[np.ndarray, np.ndarray]:
    """The ``keep`` best poses from a rotation grid, polished on the same objective.

    Parameters
    ----------
    chamfer : callable
        ``chamfer(X) -> f1`` for X of shape (C, 7) (the coarse objective).
    bound_r_deg, bound_t_m : float
        Search bounds; the grid spans the rotation bounds, the polish stays in all bounds.
    step_deg : float
        Grid spacing in degrees.
    n : int
        Points per frame for the coarse evaluation.
    keep : int
        Number of seeds returned.
    step_t_m : float, optional
        When given (wide translation bounds), a joint grid of rotations (``joint_step_deg``)
        and translations (``step_t_m``) is scored too, on ``joint_n`` points per frame: a
        translation error of a metre shifts the image by several degrees, and rotations scored
        at zero translation alone then point the wrong way. ``joint_chamfer`` (default
        ``chamfer``) scores that grid, for example on a few of the frames.

    Returns
    -------
    poses : ndarray, shape (keep, 6)
        ``(x, y, z, yaw, pitch, roll)``, best first.
    f1 : ndarray, shape (keep,)
    """
    rot = rotation_grid(bound_r_deg, step_deg)
    X = np.zeros((len(rot), 7))
    X[:, 3:6] = rot
    X[:, 6] = n
    f = np.concatenate([chamfer(X[i:i + chunk]) for i in range(0, len(X), chunk)])
    # Keep distinct local winners: the best of each 3x3x3 neighbourhood is enough, so take a
    # generous shortlist and let the polish merge neighbours.
    short = np.argsort(f)[: max(4 * keep, keep)]
    if step_t_m:
        rj = rotation_grid(bound_r_deg, joint_step_deg)
        tj = translation_grid(bound_t_m, step_t_m)
        J = np.zeros((len(rj) * len(tj), 7))
        J[:, :3] = np.repeat(tj, len(rj), axis=0)
        J[:, 3:6] = np.tile(rj, (len(tj), 1))
        J[:, 6] = min(joint_n, n)
        jc = joint_chamfer or chamfer
        fj = np.concatenate([jc(J[i:i + 4 * chunk]) for i in range(0, len(J), 4 * chunk)])
        best_j = J[np.argsort(fj)[: 4 * keep]]
        best_j[:, 6] = n
        X = np.vstack([X[short], best_j])
        f = np.concatenate([f[short], chamfer(best_j)])
        short = np.argsort(f)[: 6 * keep]
    lo = np.r_[[-bound_t_m] * 3, [-bound_r_deg] * 3, n]
    hi = np.r_[[bound_t_m] * 3, [bound_r_deg] * 3, n]
    P, fP, _ = newton_polish(chamfer, X[short], iters=8, lower=lo, upper=hi,
                             h=np.array([0.03, 0.03, 0.03, 0.5, 0.5, 0.5]), max_step=4.0)
    order = np.argsort(fP)
    P, fP = P[order], fP[order]
    # Drop near-duplicates (within 0.5 deg and 5 cm of a better seed).
    chosen: list[int] = []
    for i in range(len(P)):
        if all(np.abs(P[i, 3:6] - P[j, 3:6]).max() > 0.5 or
               np.abs(P[i, :3] - P[j, :3]).max() > 0.05 for j in chosen):
            chosen.append(i)
        if len(chosen) == keep:
            break
    return P[chosen, :6], fP[chosen]


def coarse_seeds(feats, T_init: np.ndarray, search: SearchSettings, objective: ObjectiveSettings,
                 z_min: float, cost_model, n_max: int) -> np.ndarray:
    """Seed poses for the search, shape (k, 6): the prepared frames ``feats`` are scored with
    their distance transforms truncated at ``search.seed_truncation_px`` on a rotation grid
    (:func:`grid_seeds`) with the objective's settings.

    Parameters
    ----------
    feats : list of FrameFeatures
        The prepared frames.
    T_init : ndarray, shape (4, 4)
        The initial extrinsic ``T_cam_lidar`` (m); the seeds are corrections of it.
    search : SearchSettings
        The grid (``seed_grid_deg``, ``seed_grid_t_m``), its truncation, points and count, and
        the box.
    objective : ObjectiveSettings
        The objective's settings.
    z_min : float
        The smallest depth or range of a valid point (m), as the features'.
    cost_model : CostModel
        The cost model (the coarse objective needs one; its cost is not used).
    n_max : int
        The most points per frame.

    Returns
    -------
    ndarray, shape (k, 6)
        Corrections ``(x, y, z, yaw, pitch, roll)`` (m, deg); empty without a grid.
    """
    import dataclasses

    from ..features.image import distance_transform
    from ..objective import CalibrationObjective, build_scene

    s = search
    if not s.seed_grid_deg:
        return np.empty((0, 6))                       # no grid, no seeds (search.seed_grid_deg)
    tau = s.seed_truncation_px
    coarse = []
    for f in feats:
        dt = distance_transform(f.image.edges, tau)
        img = dataclasses.replace(f.image, dt=dt, truncation_px=tau,
                                  mean_dt=float(dt.mean(dtype=np.float64)))
        coarse.append(dataclasses.replace(f, image=img))
    outside = objective.outside
    scene = build_scene(coarse, z_min, outside)
    obj = CalibrationObjective(scene, T_init, objective, cost_model, ucb_k=0.0)
    step_t = s.seed_grid_t_m if s.seed_grid_t_m and s.bound_t > s.seed_grid_t_m else None
    joint = None
    if step_t and len(coarse) > JOINT_FRAMES:
        # The joint grid is large: score it on a few frames spread over the sequence.
        pick = np.unique(np.linspace(0, len(coarse) - 1, JOINT_FRAMES).round().astype(int))
        few = build_scene([coarse[i] for i in pick], z_min, outside)
        jobj = CalibrationObjective(few, T_init, objective, cost_model, ucb_k=0.0)
        joint = lambda Z: jobj.chamfer(Z)["f1"]  # noqa: E731
    poses, _ = grid_seeds(lambda Z: obj.chamfer(Z)["f1"], s.bound_r, s.bound_t,
                          s.seed_grid_deg, min(s.seed_points, n_max), s.seed_count,
                          step_t_m=step_t, joint_chamfer=joint)
    return poses
