"""The paper's studies of a calibration front (see :mod:`paretocal.apps.study.run`)."""

from .run import STUDIES, STUDY_MARKS, StudyPlan, run_study

__all__ = ["STUDIES", "STUDY_MARKS", "StudyPlan", "run_study"]
