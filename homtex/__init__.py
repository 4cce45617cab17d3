"""homtex: yarn-level mechanics and homogenisation of technical textiles.

Units: mm, N, MPa inside the solver. Node DOFs: ux, uy, uz, rx, ry, rz.

The public API is re-exported here; everything behind it (the Frame and numpy included, the
periodic homogenisation, contact, spacer-fabric geometry, seams, macro layer, studies) is
imported on first use, so ``import homtex`` stays light (no numpy: the ``homtex`` command
imports its heavy modules inside its own error handling, where an interrupt is one line).
"""

from importlib import import_module

from ._version import __version__
from .config import get_options, set_options
from .errors import CellError, InputError, SolverError, StrainWarning, StudyError

# name -> module that defines it (imported on first use)
_LAZY = {
    "Frame": ".model.frame",
    "StaticResult": ".model.results",
    "Status": ".model.results",
    "YarnType": ".model.sections",
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
    "Lattice": ".contact.lattice",
    "RestState": ".model.rest",
    "YarnCompression": ".model.compression",
    "relax": ".knits",
    "tensile": ".knits",
    "RelaxedCell": ".knits",
    "clear_cache": ".cache",
}

__all__ = ["CellError", "InputError", "SolverError", "StrainWarning", "StudyError",
           "__version__", "get_options", "set_options", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'homtex' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
