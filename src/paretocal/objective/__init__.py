"""Objectives: the alignment error (Chamfer) and the computational cost of an evaluation."""

from .chamfer import combine, group_weights
from .cost import CostModel, measure_cost_model
from .kernel import get_evaluator, sums_kdtree, sums_numba, sums_numpy
from .objective import AlignmentObjective, CalibrationObjective, FrameSubset, PopulationObjective
from .paper import paper_chamfer
from .scene import Scene, build_scene

__all__ = ["AlignmentObjective", "CalibrationObjective", "CostModel", "FrameSubset",
           "PopulationObjective", "Scene", "build_scene", "combine", "get_evaluator",
           "group_weights", "measure_cost_model", "paper_chamfer", "sums_kdtree", "sums_numba",
           "sums_numpy"]
