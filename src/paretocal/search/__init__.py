"""The search: NSGA-II over the 6-DoF correction and the number of points."""

from .nsga import SearchResult, front_indices, front_of, initial_population, run_nsga2
from .problem import UNITS, VARIABLES, bounds
from .front_polish import polish_front
from .seeding import coarse_seeds

__all__ = ["SearchResult", "UNITS", "VARIABLES", "bounds", "coarse_seeds", "front_indices",
           "front_of", "initial_population", "polish_front", "run_nsga2"]
