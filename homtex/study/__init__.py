"""Parameter studies: study files -> points run in parallel -> one xarray Dataset.

Files (:mod:`homtex.study.files`), the task registry (:mod:`homtex.study.tasks`: built-in
tasks and those installed packages declare in the ``homtex.tasks`` entry point group), the
runner with its executors, verified resume and summary (:mod:`homtex.study.runner`), and
combining the points (:mod:`homtex.study.combine`).
"""

from ..errors import StudyError
from .combine import combine_points
from .files import PARAMETER_UNITS, Study, guess_unit, load_study, sample_points
from .runner import point_checksum, run_study, summarize
from .tasks import ENTRY_POINT_GROUP, TASKS, analytic_task, get_task, register_task, task_names

__all__ = ["ENTRY_POINT_GROUP", "PARAMETER_UNITS", "TASKS", "Study", "StudyError", "analytic_task", "combine_points",
           "get_task", "guess_unit", "load_study", "point_checksum", "register_task", "run_study", "sample_points",
           "summarize", "task_names"]
