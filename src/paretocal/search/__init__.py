"""The search: NSGA-II over the 6-DoF correction and the number of points."""

from .nsga import SearchResult, front_of, make_algorithm, run_nsga2
from .problem import UNITS, VARIABLES, CalibrationProblem, bounds

__all__ = ["CalibrationProblem", "SearchResult", "UNITS", "VARIABLES", "bounds", "front_of",
           "make_algorithm", "run_nsga2"]
