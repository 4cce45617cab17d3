"""The smoothed-aggregation hierarchy of beam-frame operators (:class:`ScaledAMG`).

Kept apart from :mod:`homtex.linalg.solvers` so that the parallel, GPU and reuse modules build
hierarchies without importing the solver front end (which imports them).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..config import option
from ..errors import SolverError

__all__ = ["ScaledAMG", "amg_hierarchy"]


#: the words every singular-matrix SolverError contains (callers that know the frame add a diagnosis)
SINGULAR = "the stiffness matrix is singular"


def singular_error(method: str, err: BaseException, *, coarse: bool = False) -> SolverError:
    """The SolverError for a factorisation that found the matrix singular (``err``: SuperLU's
    "Factor is exactly singular", also from pyamg's coarse grid), with the usual causes and the
    remedy. ``solve_static`` adds which parts and elements of the frame are to blame."""
    where = "the AMG coarse-grid factorisation" if coarse else f"the {method} factorisation"
    return SolverError(f"{where} failed ({err}): {SINGULAR} - a part of the structure that nothing holds "
                       "(add supports), or an element of (almost) zero stiffness: E, radius or length orders of "
                       "magnitude below the others (fix the element's properties or remove it)")



class ScaledAMG:
    """Smoothed-aggregation hierarchy of the symmetrically scaled operator D^-1/2 A D^-1/2.

    Beam frames mix translations (mm) and rotations (rad), so the diagonal of A spans many
    orders of magnitude; Chebyshev smoothing needs a good spectral bound and gets it only
    after scaling (measured: 131 -> 16 CG iterations on a 17k-DOF octet block). The near-null
    space is scaled the other way (D^1/2 B) so it stays the null space of the scaled operator.
    Used as a preconditioner for CG on the unscaled A, so residuals stay in physical units.
    """

    def __init__(self, A, B, *, max_coarse: int = 3000, degree: int = 3, setup: str | None = None,
                 node_graph=None):
        """max_coarse: largest coarse grid in unknowns (solved directly); degree: Chebyshev;
        setup: "fast" (:func:`homtex.linalg.parallel_amg.sa_levels`: the same smoothed aggregation
        with Lanczos spectral bounds on numba products) or "pyamg" (default: option ``amg_setup``);
        node_graph: (nodes, nodes) sparse graph aggregated on the finest level instead of the
        strength of A ("fast" setup; contact systems pass the beam elements' graph)."""
        import pyamg

        d = np.asarray(A.diagonal(), dtype=float)
        if np.any(d <= 0):
            i = int(np.flatnonzero(d <= 0)[0])
            raise SolverError(f"non-positive diagonal {d[i]:.3g} at DOF {i} (node {i // 6}, "
                              f"local DOF {i % 6}): the operator is not positive definite")
        self.scale = 1.0 / np.sqrt(d)
        S = sp.diags(self.scale)
        As = S @ A @ S
        if isinstance(A, sp.bsr_matrix):
            As = sp.bsr_matrix(As, blocksize=A.blocksize)
        Bs = None if B is None else np.asarray(B) / self.scale[:, None]
        cheb = ("chebyshev", {"degree": degree})
        # pyamg counts max_coarse in block rows (6x6 blocks here), not unknowns: without the
        # division the coarse splu got up to 6000 unknowns (measured on a 98k-DOF periodic octet
        # cell: 2 levels, a 5184-unknown coarse grid, 1.0 s lazy factorisation in the first
        # solve, V-cycles 1.8x slower). 3000 unknowns kept the iteration counts of a slender
        # tower (31) and a BCC block (368) that 1000 raised to 143 and 426.
        bs = A.blocksize[0] if isinstance(As, sp.bsr_matrix) else 1
        self.setup = option("amg_setup", setup)
        if self.setup == "fast" and isinstance(As, sp.bsr_matrix):
            from .parallel_amg import sa_levels

            self.ml = sa_levels(As, Bs if Bs is not None else np.ones((As.shape[0], 1)),
                                max_coarse=max_coarse, degree=degree, strength0=node_graph)
        else:
            self.setup = "pyamg"
            self.ml = pyamg.smoothed_aggregation_solver(
                As, B=Bs, symmetry="symmetric", strength=("symmetric", {"theta": 0.0}),
                presmoother=cheb, postsmoother=cheb, improve_candidates=None,
                max_coarse=max(1, int(max_coarse) // bs), coarse_solver="splu")
        # the coarse grid is factorised lazily, inside the first V-cycle, where a singular operator
        # escaped as a bare RuntimeError ("Factor is exactly singular"): factorise it now
        Ac = self.ml.levels[-1].A
        try:
            self.ml.coarse_solver(Ac, np.zeros(Ac.shape[0]))
        except RuntimeError as err:
            raise singular_error("amg", err, coarse=True) from err
        self.shape = A.shape
        self.degree = degree  # Chebyshev degree (homtex.krylov rebuilds the smoother from it)

    def operator_complexity(self) -> float:
        return float(self.ml.operator_complexity())

    @property
    def levels(self):
        return self.ml.levels

    def aspreconditioner(self, cycle: str = "V") -> spla.LinearOperator:
        inner = self.ml.aspreconditioner(cycle=cycle)
        s = self.scale

        def apply(r):
            return s * inner.matvec(s * np.ravel(r))

        return spla.LinearOperator(self.shape, matvec=apply, dtype=float)


def amg_hierarchy(A, B, *, max_coarse: int = 3000, degree: int = 3, setup: str | None = None,
                  node_graph=None) -> ScaledAMG:
    """pyamg smoothed aggregation tuned for beam frames (see :class:`ScaledAMG`)."""
    return ScaledAMG(A, B, max_coarse=max_coarse, degree=degree, setup=setup, node_graph=node_graph)


