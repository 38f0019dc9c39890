"""Figures and reports (the output edge of the pipeline).

The figure functions import matplotlib on first use (PEP 562), so that writing a run without
figures does not load it.
"""

__all__ = ["overlay_figure", "pareto_figure"]


def __getattr__(name):
    if name in __all__:
        from . import figures

        return getattr(figures, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
