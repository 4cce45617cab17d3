"""homtex: yarn-level mechanics and homogenisation of technical textiles.

Units: mm, N, MPa inside the solver. Node DOFs: ux, uy, uz, rx, ry, rz.

The public API is re-exported here; heavier parts (periodic homogenisation, contact,
spacer-fabric geometry, macro layer, studies) are imported on first use.
"""

from importlib import import_module

from .errors import InputError, SolverError
from .model.frame import Frame
from .model.sections import YarnType
from .linalg.solvers import LinearSolver, SolveReport
from .analysis.static import StaticResult, solve_static

__version__ = "0.1.0"

# name -> module that defines it (imported lazily so `import homtex` stays light)
_LAZY = {
    "homogenize": ".analysis.periodic",
    "Homogenization": ".analysis.periodic",
    "periodize": ".analysis.periodic",
    "load_cell": ".cells",
    "Cell": ".cells",
    "Contact": ".contact",
    "compress": ".contact",
    "seam_profile": ".seams",
    "seam_compression": ".seams",
    "Plate": ".contact",
    "macro_curve": ".macro",
    "run_study": ".study",
    "Lookup": ".lookup",
    "solve_nonlinear": ".analysis.nonlinear",
    "Corotational": ".analysis.nonlinear",
}

__all__ = ["Frame", "InputError", "LinearSolver", "SolveReport", "SolverError", "StaticResult",
           "YarnType", "solve_static", "__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'homtex' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
