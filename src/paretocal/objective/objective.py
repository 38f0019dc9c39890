"""Both objectives for a population of candidates ``[x, y, z, yaw, pitch, roll, n]`` in one call."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..config import ObjectiveSettings
from ..geometry import apply_correction
from .chamfer import combine, group_weights
from .cost import CostModel, measure_per_candidate
from .kernel import get_evaluator
from .paper import paper_chamfer
from .scene import Scene


class AlignmentObjective(Protocol):
    """What the polish, the quality report and the verdict call: the alignment objective of a
    whole population of candidates ``X`` (C, 7), ``[x, y, z, yaw, pitch, roll, n]`` (m, deg,
    points per frame), in one call. :class:`CalibrationObjective` and :class:`FrameSubset`
    are two."""

    scene: Scene

    def transforms(self, X: np.ndarray) -> np.ndarray:
        """Candidate extrinsics ``T_cam_lidar``, shape (C, 4, 4).

        Parameters
        ----------
        X : ndarray, shape (C, 7)
            Candidates ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
        """
        ...

    def chamfer(self, X: np.ndarray, ucb_k: float | None = None) -> dict[str, np.ndarray]:
        """At least ``f1`` (C,) (px) and ``per_frame`` (C, F), the per-frame terms.

        Parameters
        ----------
        X : ndarray, shape (C, 7)
            Candidates ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
        ucb_k : float, optional
            The sampling-error multiplier for this call (0: the plain mean over the points).
        """
        ...


class PopulationObjective(AlignmentObjective, Protocol):
    """What the search calls besides: both objectives, ``F`` (C, 2) ``[f1, f2]``, and the
    cost alone."""

    def evaluate(self, X: np.ndarray) -> np.ndarray:
        """``F`` of shape (C, 2) for candidates ``X`` (C, 7).

        Parameters
        ----------
        X : ndarray, shape (C, 7)
            Candidates ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
        """
        ...

    def cost(self, X: np.ndarray) -> dict[str, np.ndarray]:
        """At least ``f2`` (C,), the modelled cost of evaluating each candidate.

        Parameters
        ----------
        X : ndarray, shape (C, 7)
            Candidates ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
        """
        ...


class CalibrationObjective:
    """Evaluates f1 (alignment) and f2 (cost) for whole populations.

    Parameters
    ----------
    scene : Scene
        The frames' feature points and distance transforms.
    T_init : ndarray, shape (4, 4)
        Initial extrinsic; candidates are corrections ``T_init @ D(x..roll)``.
    settings : ObjectiveSettings
        The ``objective`` section of the settings.
    cost_model : CostModel
        The affine cost model of this machine (the second objective).
    edge_uv : list of ndarray, optional
        Edge pixels per frame, needed only by the paper's Chamfer.
    ucb_k : float, optional
        Sampling-error multiplier; ``settings.ucb_k`` when omitted (0 if that is None).
    """

    def __init__(self, scene: Scene, T_init: np.ndarray, settings: ObjectiveSettings,
                 cost_model: CostModel, edge_uv: list[np.ndarray] | None = None,
                 ucb_k: float | None = None):
        self.scene = scene
        self.T_init = np.asarray(T_init, dtype=np.float64)
        self.settings = settings
        self.cost_model = cost_model
        self.edge_uv = edge_uv
        self.sums = get_evaluator(settings.evaluator)
        self.weights = group_weights(settings.w_edge, settings.contrast)
        self.evaluations = 0
        self.ucb_k = float(ucb_k if ucb_k is not None else (settings.ucb_k or 0.0))

    def transforms(self, X: np.ndarray) -> np.ndarray:
        """Candidate extrinsics ``T_init @ D``, shape (C, 4, 4).

        Parameters
        ----------
        X : ndarray, shape (C, 7) or (C, 6)
            Candidates ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
        """
        return apply_correction(self.T_init, np.asarray(X, dtype=np.float64)[:, :6])

    def chamfer(self, X: np.ndarray, ucb_k: float | None = None) -> dict[str, np.ndarray]:
        """First objective and its parts for candidates X, shape (C, 7).

        Parameters
        ----------
        X : ndarray, shape (C, 7)
            Candidates ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
        ucb_k : float, optional
            Overrides the sampling-error multiplier for this call (0: the plain mean over the
            points, as the quality report, the verdict and the basin test read it).

        Returns
        -------
        dict
            ``f1`` (C,), ``mean`` (C, G) per-group mean cost (px), ``se`` (C,) sampling error
            and ``in_view`` (C,) fraction of the evaluated points that landed in the image.
        """
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        n = np.rint(X[:, 6]).astype(np.int64)
        T = self.transforms(X)
        self.evaluations += len(X)
        S1, S2, n_in = self.sums(self.scene, T, n)
        W1, W2 = self.scene.group_weights(n)
        k = self.ucb_k if ucb_k is None else float(ucb_k)
        out = combine(S1, S2, W1, W2, self.scene.outside, self.weights, k)
        out["in_view"] = n_in.sum(axis=1) / np.maximum(self.scene.points_used(n), 1)
        if self.settings.chamfer == "paper":
            if self.edge_uv is None:
                raise ValueError("the paper's Chamfer needs the frames' edge pixels (edge_uv)")
            out["f1"] = paper_chamfer(self.scene, self.edge_uv, T, n)
        return out

    def cost(self, X: np.ndarray) -> dict[str, np.ndarray]:
        """Second objective: ``f2`` (C,), with ``ms`` and ``bytes`` per evaluation.

        Parameters
        ----------
        X : ndarray, shape (C, 7)
            Candidates ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).

        Returns
        -------
        dict
            ``f2`` (C,) = ``t_norm + m_norm``; ``ms`` (C,), the CPU ms of one evaluation
            (modelled, or measured with ``cost: psutil``), ``bytes`` (C,) and ``points`` (C,),
            the points evaluated over all frames.
        """
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        n = np.rint(X[:, 6]).astype(np.int64)
        pts = self.scene.points_used(n)
        cm = self.cost_model
        if self.settings.cost == "psutil":
            T = self.transforms(X)

            def one(i):
                self.sums(self.scene, T[i:i + 1], n[i:i + 1])

            ms, nbytes = measure_per_candidate(one, len(X))
            t = ms / self._psutil_reference_ms()
            m = nbytes / float(cm.nbytes(cm.points_max))
        else:
            ms, nbytes = cm.time_ms(pts), cm.nbytes(pts)
            t, m = cm.normalised(pts)
        return {"f2": t + m, "t_norm": t, "m_norm": m, "ms": ms, "bytes": nbytes, "points": pts}

    def _psutil_reference_ms(self) -> float:
        """Measured time of one candidate evaluated alone at the largest n (median of 5)."""
        if getattr(self, "_ref_ms", None) is None:
            n_max = int(self.scene.points_per_frame.max())
            ms, _ = measure_per_candidate(
                lambda i: self.sums(self.scene, self.T_init[None], np.array([n_max])), 5,
                repeats=3)
            self._ref_ms = float(np.median(ms))
        return self._ref_ms

    def evaluate(self, X: np.ndarray) -> np.ndarray:
        """``F`` of shape (C, 2): ``[f1, f2]`` for each candidate.

        Parameters
        ----------
        X : ndarray, shape (C, 7)
            Candidates ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
        """
        return np.column_stack([self.chamfer(X)["f1"], self.cost(X)["f2"]])


class FrameSubset:
    """The alignment objective over some of an objective's frames: ``f1`` the mean of their
    per-frame terms, without the sampling-error charge (as the local optimum, the verdict and
    the basin tests read it). For a joint calibration, one camera's frames alone.

    Parameters
    ----------
    objective : CalibrationObjective
        The objective over every frame.
    frames : array_like of int
        Indices of the frames in ``objective.scene``.
    """

    def __init__(self, objective: CalibrationObjective, frames):
        self.objective = objective
        self.frames = np.asarray(frames, dtype=np.int64)
        self.scene = objective.scene

    def transforms(self, X: np.ndarray) -> np.ndarray:
        """As :meth:`CalibrationObjective.transforms`.

        Parameters
        ----------
        X : ndarray, shape (C, 7)
            Candidates ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
        """
        return self.objective.transforms(X)

    def chamfer(self, X: np.ndarray, ucb_k: float | None = None) -> dict[str, np.ndarray]:
        """``f1`` (C,) and ``per_frame`` (C, len(frames)) for candidates X (C, 7).

        Parameters
        ----------
        X : ndarray, shape (C, 7)
            Candidates ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
        ucb_k : float, optional
            Ignored (always 0).
        """
        term = self.objective.chamfer(X, ucb_k=0.0)["per_frame"][:, self.frames]
        return {"f1": term.mean(axis=1), "per_frame": term}
