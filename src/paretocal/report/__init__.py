"""Figures and reports (the output edge of the pipeline)."""

from .figures import overlay_figure, pareto_figure

__all__ = ["overlay_figure", "pareto_figure"]
