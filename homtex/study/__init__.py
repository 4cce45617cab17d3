"""Parameter studies: study files -> points run in parallel -> one xarray Dataset."""

from .runner import (TASKS, Study, StudyError, analytic_task, combine_points, get_task, load_study,
                     register_task, run_study, sample_points)

__all__ = ["TASKS", "Study", "StudyError", "analytic_task", "combine_points", "get_task", "load_study",
           "register_task", "run_study", "sample_points"]
