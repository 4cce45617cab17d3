"""homtex: yarn-level mechanics and homogenisation of technical textiles.

Units: mm, N, MPa inside the solver. Node DOFs: ux, uy, uz, rx, ry, rz.

The public API is re-exported here; the stages behind it (periodic homogenisation, contact,
spacer-fabric geometry, seams, macro layer, studies) are imported on first use, so
``import homtex`` stays light.
"""

from importlib import import_module

from ._version import __version__
from .config import get_options, set_options
from .errors import CellError, InputError, SolverError, StrainWarning, StudyError
from .model.frame import Frame
from .model.results import StaticResult, Status
from .model.sections import YarnType

# name -> module that defines it (imported on first use)
_LAZY = {
    "solve_static": ".api",
    "compress": ".api",
    "LinearSolver": ".linalg.solvers",
    "SolveReport": ".linalg.solvers",
    "homogenize": ".analysis.homogenize",
    "Homogenization": ".analysis.homogenize",
    "periodize": ".geometry.tiling",
    "load_cell": ".cells",
    "Cell": ".cells",
    "Contact": ".contact.options",
    "Plate": ".model.scene",
    "seam_profile": ".seams",
    "seam_compression": ".seams",
    "macro_curve": ".macro",
    "run_study": ".study",
    "Lookup": ".lookup",
    "solve_nonlinear": ".api",
    "Corotational": ".analysis.nonlinear",
}

__all__ = ["CellError", "Frame", "InputError", "SolverError", "StaticResult", "Status", "StrainWarning", "StudyError",
           "YarnType",
           "__version__", "get_options", "set_options", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'homtex' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
