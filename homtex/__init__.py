"""homtex: yarn-level mechanics and homogenisation of technical textiles.

Units: mm, N, MPa inside the solver. Node DOFs: ux, uy, uz, rx, ry, rz.
"""

from .errors import InputError, SolverError
from .frame import Frame
from .sections import YarnType
from .solvers import LinearSolver, SolveReport
from .static import StaticResult, solve_static

__version__ = "0.1.0"

__all__ = ["Frame", "InputError", "LinearSolver", "SolveReport", "SolverError", "StaticResult",
           "YarnType", "solve_static", "__version__"]
