"""The calibration as a pymoo problem over ``[x, y, z, yaw, pitch, roll, n]``."""

from __future__ import annotations

import numpy as np
from pymoo.core.problem import Problem
from pymoo.core.repair import Repair
from pymoo.core.sampling import Sampling
from pymoo.operators.sampling.rnd import FloatRandomSampling

from ..config import SearchSettings

VARIABLES = ("x", "y", "z", "yaw", "pitch", "roll", "n")
UNITS = ("m", "m", "m", "deg", "deg", "deg", "points")


def bounds(settings: SearchSettings, n_min: int, n_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of the seven variables, shape (7,) each."""
    t, r = settings.bound_t, settings.bound_r
    xl = np.array([-t, -t, -t, -r, -r, -r, n_min], dtype=np.float64)
    xu = np.array([t, t, t, r, r, r, n_max], dtype=np.float64)
    return xl, xu


class CalibrationProblem(Problem):
    """Two objectives, both minimised, evaluated for the whole population in one call.

    ``objective`` is any object with ``evaluate(X) -> F`` (shape (C, 2)).
    """

    def __init__(self, objective, xl: np.ndarray, xu: np.ndarray):
        super().__init__(n_var=7, n_obj=2, xl=xl, xu=xu)
        self.objective = objective

    def _evaluate(self, X, out, *args, **kwargs):
        out["F"] = self.objective.evaluate(X)


class RoundN(Repair):
    """Round the point count (last column) to an integer; the pose stays continuous."""

    def _do(self, problem, X, **kwargs):
        X[:, 6] = np.clip(np.rint(X[:, 6]), problem.xl[6], problem.xu[6])
        return X


class SamplingWithInit(Sampling):
    """Uniform random sampling in the bounds (the paper's), plus given poses.

    The current extrinsic (the zero correction) and any seed poses are candidates worth
    keeping: each starts ``per_seed`` individuals, with ``n`` spread over its range.
    """

    def __init__(self, seeds: np.ndarray | None = None, per_seed: int = 4):
        super().__init__()
        zero = np.zeros((1, 6))
        self.seeds = zero if seeds is None or len(seeds) == 0 else np.vstack([zero, seeds])
        self.per_seed = per_seed

    def _do(self, problem, n_samples, **kwargs):
        X = FloatRandomSampling()._do(problem, n_samples, **kwargs)
        return place_seeds(X, problem.xl, problem.xu, self.seeds, self.per_seed)


def place_seeds(X: np.ndarray, xl: np.ndarray, xu: np.ndarray, seeds: np.ndarray,
                per_seed: int = 4) -> np.ndarray:
    """Overwrite the first rows of a sampled population (C, 7) with the poses ``seeds`` (k, 6),
    each at ``per_seed`` values of n spread over its range (at most half the population)."""
    ns = np.linspace(xl[6], xu[6], per_seed)
    rows = [np.r_[pose, n] for pose in seeds for n in ns][: len(X) // 2]
    if rows:
        X[: len(rows)] = np.clip(np.array(rows), xl, xu)
    return X
