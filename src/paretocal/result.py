"""The result of a calibration run: the final front, the chosen solution and everything the
run measured (:class:`CalibrationResult`), and its ``result.json`` document."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from . import __version__
from .config import Settings
from .decide import Decision
from .geometry import pose_error
from .objective import CalibrationObjective
from .objective.cost import CostModel
from .quality import Quality
from .search import VARIABLES
from .verdict import Evidence, Reliability, reliability

if TYPE_CHECKING:  # pragma: no cover
    from .board import BoardStart
    from .inputs import InputsReport, MotionReport
    from .stage import FeatureCounts
    from .wide import WideStart


@dataclass
class Front:
    """The final non-dominated set, sorted by cost.

    Attributes
    ----------
    X : ndarray, shape (k, 7)
        ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
    F : ndarray, shape (k, 2)
        ``[f1, f2]``.
    T : ndarray, shape (k, 4, 4)
        The extrinsics.
    columns : dict of str -> ndarray (k,)
        Per-solution figures: chamfer parts, ``ms``, ``bytes``, ``in_view`` and, when a
        reference is known, the reference errors.
    """

    X: np.ndarray
    F: np.ndarray
    T: np.ndarray
    columns: dict


@dataclass
class CalibrationResult:
    """Everything a calibration run produced (see :func:`calibrate`).

    Lengths are in metres and angles in degrees (``result.json``, :meth:`to_dict`, writes
    some of them in cm).

    Attributes
    ----------
    T_cam_lidar : ndarray, shape (4, 4)
        The chosen extrinsic (LiDAR -> camera).
    T_init : ndarray, shape (4, 4)
        The initial extrinsic (after a wide start: the start it found).
    T_ref : ndarray, shape (4, 4) or None
        The dataset's reference extrinsic, when ``--init`` gave another start.
    chosen : int
        The chosen solution's index in ``front``.
    front : Front
        The final Pareto front: ``X`` (k, 7), ``F`` (k, 2), ``T`` (k, 4, 4), per-solution
        columns.
    decision : Decision
        How the solution was chosen.
    cost_model : CostModel
        The affine cost model of this machine (CPU ms and bytes per evaluation).
    settings : Settings
        The settings used.
    evaluations : int
        Objective evaluations spent.
    wall_s : float
        Wall time of the run (s).
    timings : dict
        Wall time per phase (s).
    frames : list of str
        The frames' names.
    feature_counts : FeatureCounts
        The feature points per group and frame, and the frames that contribute
        (:func:`paretocal.stage.feature_counts`).
    n_range : tuple of int
        ``(n_min, n_max)``, the searched range of points per frame.
    history : list
        Per NSGA-II generation: the best f1 and the front's size.
    nsga_front : tuple or None
        ``(X, F)`` of the NSGA-II front before the polish.
    quality : Quality or None
        The quality report at the result.
    reliability : Reliability or None
        The verdict: ``"ok"`` or ``"unreliable"``, the reasons, the evidence.
    motion : dict or None
        What was done about motion during the sweeps.
    inputs : InputsReport or None
        What the input files offered: the point fields used, the camera model, notes
        (:func:`paretocal.inputs.describe_inputs`).
    evidence : Evidence or None
        The verdict's own checks (restart, image-cloud agreement, per-axis intervals).
    wide : dict or None
        What the wide start did; None when the stated error did not ask for it.
    board : BoardStart or None
        What the board stage found (:class:`paretocal.board.BoardStart`); None for a recording
        without a board.
    sweeps : list or None
        The frames as calibrated (de-skewed when the motion was compensated).
    objective : CalibrationObjective or None
        The final objective (feature points chosen at the estimate).
    seed_poses : ndarray, shape (k, 6) or None
        The search's grid seeds (m, deg).
    """

    T_cam_lidar: np.ndarray
    T_init: np.ndarray
    T_ref: np.ndarray | None
    chosen: int
    front: Front
    decision: Decision
    cost_model: CostModel
    settings: Settings
    evaluations: int
    wall_s: float
    timings: dict
    frames: list[str]
    feature_counts: FeatureCounts
    n_range: tuple[int, int]
    history: list = field(default_factory=list)
    nsga_front: tuple | None = None
    #: The quality report at the result (metres and degrees; ``result.json`` writes it in cm).
    quality: Quality | None = None
    #: The verdict: ``"ok"`` or ``"unreliable"``, the reasons, the evidence (see
    #: :func:`reliability`).
    reliability: Reliability | None = None
    #: What was done about motion during the sweeps (:func:`paretocal.inputs.compensate_motion`).
    motion: MotionReport | None = None
    #: What the input files offered: the point fields used, the camera model, notes.
    inputs: InputsReport | None = None
    #: The verdict's own checks (restart, image-cloud agreement, per-axis intervals; see
    #: :func:`paretocal.verdict.gather_evidence`); written inside ``reliability``.
    evidence: Evidence | None = None
    #: What the wide start did (written by :meth:`paretocal.wide.WideStart.to_dict`), None
    #: when the stated error did not ask for it. When it applied, ``T_init`` is the start it
    #: found and the settings hold the narrower stated error the calibration used from there.
    wide: WideStart | None = None
    #: What the board stage found (:class:`paretocal.board.BoardStart`), None for a recording
    #: without a board; written as ``board`` only when there is one. When it applied,
    #: ``T_init`` is the start it found, with the narrower stated error of a wide start.
    board: BoardStart | None = None
    #: The frames as calibrated (de-skewed when the motion was compensated); not in JSON.
    sweeps: list | None = None
    #: The final objective (feature points chosen at the estimate) and the grid seeds of the
    #: search, for studies that evaluate more candidates; not written to result.json.
    objective: CalibrationObjective | None = None
    seed_poses: np.ndarray | None = None

    @property
    def correction(self) -> dict[str, float]:
        x = self.front.X[self.chosen]
        return {k: float(v) for k, v in zip(VARIABLES[:6], x[:6])}

    @property
    def n_points(self) -> int:
        return int(round(self.front.X[self.chosen, 6]))

    @property
    def reference_error(self) -> dict | None:
        return self._against_reference(self.T_cam_lidar)

    @property
    def initial_error(self) -> dict | None:
        return self._against_reference(self.T_init)

    def _against_reference(self, T: np.ndarray) -> dict | None:
        """:func:`pose_error` of ``T`` against the reference, None without one."""
        if self.T_ref is None:
            return None
        return {k: float(v) for k, v in pose_error(T, self.T_ref).items()}

    def objectives(self) -> dict[str, float]:
        """The chosen solution's objectives and their parts: ``chamfer`` (f1, px), ``cost``
        (f2), and those of its front columns that are known (``ms``, ``bytes``, ``in_view``,
        ``deviation_px``, ...), as ``result.json`` writes them."""
        i, c = self.chosen, self.front.columns
        out = {"chamfer": float(self.front.F[i, 0]), "cost": float(self.front.F[i, 1])}
        for k in ("chamfer_holdout", "deviation_px", "t_norm", "m_norm", "ms", "bytes", "edge_px",
                  "intensity_px", "smooth_px", "sampling_se", "in_view"):
            if k in c:
                out[k] = float(c[k][i])
        return out

    def to_dict(self) -> dict:
        """The ``result.json`` document (docs/conventions.md section 3)."""
        doc = self._document()
        if self.board is not None:
            doc["board"] = self.board.to_dict()
        return doc

    def _document(self) -> dict:
        return {
            "T_cam_lidar": self.T_cam_lidar.tolist(),
            "T_init": self.T_init.tolist(),
            "correction": self.correction,
            # x, y, z of the correction (and of the intervals and the quality report) are in
            # the LiDAR frame: T_cam_lidar = T_init @ D(correction).
            "correction_frame": "lidar",
            "n_points": self.n_points,
            "objectives": self.objectives(),
            "decision": self.decision.to_dict(),
            "reference_error": self.reference_error,
            "initial_error": self.initial_error,
            "evaluations": int(self.evaluations),
            "wall_s": round(float(self.wall_s), 3),
            "seed": int(self.settings.search.seed),
            "version": __version__,
            "config": self.settings.to_dict(),
            "frames": self.frames,
            "n_range": list(self.n_range),
            "front_size": int(len(self.front.X)),
            "features": self.feature_counts.to_dict(),
            "cost_model": self.cost_model.to_dict(),
            "timings_s": {k: round(float(v), 3) for k, v in self.timings.items()},
            "ucb_k": round(float(self.settings.ucb_k), 4),
            "quality": None if self.quality is None else self.quality.to_dict(),
            "motion": None if self.motion is None else self.motion.to_dict(),
            "inputs": None if self.inputs is None else self.inputs.to_dict(),
            "wide_start": None if self.wide is None else self.wide.to_dict(),
            "reliability": (self.reliability if self.reliability is not None
                            else reliability(self)).to_dict(),
        }
