"""The search space ``[x, y, z, yaw, pitch, roll, n]``: bounds, the integer repair of ``n``, and
the initial population with the given poses."""

from __future__ import annotations

import numpy as np
from pymoo.core.repair import Repair
from pymoo.core.sampling import Sampling
from pymoo.operators.sampling.rnd import FloatRandomSampling

from ..config import SearchSettings

VARIABLES = ("x", "y", "z", "yaw", "pitch", "roll", "n")
UNITS = ("m", "m", "m", "deg", "deg", "deg", "points")


def bounds(settings: SearchSettings, n_min: int, n_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of the seven variables, shape (7,) each.

    Parameters
    ----------
    settings : SearchSettings
        ``bound_t`` (m) and ``bound_r`` (deg), the box in effect.
    n_min, n_max : int
        The range of points per frame.

    Returns
    -------
    xl, xu : ndarray, shape (7,)
        ``[x, y, z, yaw, pitch, roll, n]`` (m, deg, points per frame).
    """
    t, r = settings.bound_t, settings.bound_r
    xl = np.array([-t, -t, -t, -r, -r, -r, n_min], dtype=np.float64)
    xu = np.array([t, t, t, r, r, r, n_max], dtype=np.float64)
    return xl, xu


def round_n(X: np.ndarray, xl: np.ndarray, xu: np.ndarray) -> np.ndarray:
    """Round the point count (last column of X (C, 7)) to an integer within its bounds, in
    place; the pose stays continuous. Returns X."""
    X[:, 6] = np.clip(np.rint(X[:, 6]), xl[6], xu[6])
    return X


class RoundN(Repair):
    """:func:`round_n` as a pymoo repair (for pymoo's own algorithms: the study's GA)."""

    def _do(self, problem, X, **kwargs):
        return round_n(X, problem.xl, problem.xu)


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
