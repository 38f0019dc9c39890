"""The paper's studies of a calibration front (see :mod:`paretocal.study.run`)."""

from .run import STUDIES, StudyPlan, run_study

__all__ = ["STUDIES", "StudyPlan", "run_study"]
