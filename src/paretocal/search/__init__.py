"""The search: NSGA-II over the 6-DoF correction and the number of points."""

from .nsga import SearchResult, front_indices, front_of, make_algorithm, run_nsga2
from .refine import polish_front
from .seeding import coarse_seeds
from .problem import UNITS, VARIABLES, CalibrationProblem, bounds

__all__ = ["CalibrationProblem", "SearchResult", "UNITS", "VARIABLES", "bounds", "coarse_seeds",
           "front_indices", "front_of", "make_algorithm", "polish_front", "run_nsga2"]
