"""Parameter studies: study files -> points run in parallel -> one xarray Dataset.

Files (:mod:`homtex.study.files`), tasks (:mod:`homtex.study.tasks`), the runner with its
executors and resume (:mod:`homtex.study.runner`), and combining the points
(:mod:`homtex.study.combine`).
"""

from ..errors import StudyError
from .combine import combine_points
from .files import Study, load_study, sample_points
from .runner import run_study
from .tasks import TASKS, analytic_task, get_task, register_task

__all__ = ["TASKS", "Study", "StudyError", "analytic_task", "combine_points", "get_task", "load_study",
           "register_task", "run_study", "sample_points"]
