"""Fast tangent solvers behind :mod:`homtex.linalg.tangent_solver`: CHOLMOD, PARDISO and AMG-PCG.

``"pardiso"`` (:class:`PardisoTangent`): MKL PARDISO's supernodal LDL^T with Bunch-Kaufman pivoting
(pypardiso), analysis once per pattern, the inertia counted by PARDISO. Measured on the tangents
of the 43 mm seam cell's press (13 032 DOF, one thread): 3.9 / 4.3 ms per factorisation (PARDISO /
qdldl) at first contact, 5.6 / 21.8 ms at 70 % where contacts have filled the factor; the same 24
negative eigenvalues and solves equal to 2e-11. Over whole runs (docs/performance.md): 12.0 / 33.5 ms
per factorisation on the 43 mm press, 21 / 121 ms on the relaxing 20-filament jersey.

``"cholmod"`` (:class:`CholmodTangent`): supernodal Cholesky (scikit-sparse; BLAS threads), the
symbolic analysis once per pattern, a numeric refactorisation per tangent. It proves positive
definiteness (negative = 0) or its absence; where the inertia count is asked for on a matrix that
is not positive definite it factors with qdldl instead (the count and the solve come from there).

``"amg"`` (:class:`AMGTangent`): CG preconditioned by smoothed-aggregation AMG on the positive
definite (PTC-shifted) tangent, embedded in the node-blocked 6N DOF space (constrained DOFs as
identity rows) with the rigid-body modes of the nodes as near-null space. The hierarchy is kept
across factorisations and rebuilt by the rule of :class:`ReuseRule`. Its inertia is a Krylov
test: ``factor`` runs ``probe`` PCG iterations on a fixed random right-hand side; a non-positive
curvature proves the matrix indefinite (positive_definite False, negative None: at least one);
otherwise it is taken as positive definite (negative 0). A CG solve that meets a non-positive
curvature later raises SolverError. Not a proof, so paths whose stability matters (arc length,
bifurcations) keep ``"ldl"``.

``"auto"``: the rule of option ``tangent_auto_dof``: from that many free DOFs on ``"cholmod"`` where
scikit-sparse imports, else ``"ldl"``. Measured on a 3D-loaded net of 1.01e5 DOF (5 load steps, 27
Newton iterations, the same in every method; 2-core EPYC, load 4.5-5.5, process CPU seconds per
Newton iteration): ldl 8.9 s, cholmod 1.86 s (4.8x; wall 8.7x), amg 6.0 s (1.5x; wall 2.0x), the
answers equal to 4e-15. AMG is not chosen by the rule: it gains less than CHOLMOD and its
inertia is a Krylov probe, not a count.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import time

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError
from .tangent_solver import QdldlTangent, TangentSolver, register_tangent_solver

log = logging.getLogger(__name__)

try:  # optional: scikit-sparse
    from sksparse import cholmod as _cholmod  # type: ignore
except Exception:  # pragma: no cover - depends on the machine
    _cholmod = None

try:  # optional: pypardiso (Intel MKL PARDISO)
    import pypardiso as _pypardiso  # type: ignore
except Exception:  # pragma: no cover - depends on the machine
    _pypardiso = None
else:
    # MKL is loaded now: the thread-pool controllers made before it (once, for speed) do not know
    # it, so a block limited to one BLAS thread would leave PARDISO on all cores (measured: the
    # 43 mm curve took 1123 s of CPU for 631 s of wall); make it anew
    from .. import config as _config

    _config._CONTROLLER.clear()

__all__ = ["AMGTangent", "CholmodTangent", "PardisoTangent", "ReuseRule", "auto_tangent_solver", "cholmod_available",
           "pardiso_available"]


_MKL_RT: str | None = None


def _pardiso_solver():
    """A pypardiso solver for a symmetric indefinite matrix. pypardiso looks for MKL's runtime
    library at every construction (a recursive glob under sys.prefix: 0.3-0.7 s, which a new
    contact pattern paid in every analysis); the library found first is handed to the later ones
    through pypardiso's own ``PYPARDISO_MKL_RT``."""
    global _MKL_RT
    if _MKL_RT is None or "PYPARDISO_MKL_RT" in os.environ:
        ps = _pypardiso.PyPardisoSolver(mtype=-2)
        _MKL_RT = getattr(ps.libmkl, "_name", None)
        return ps
    os.environ["PYPARDISO_MKL_RT"] = _MKL_RT
    try:
        return _pypardiso.PyPardisoSolver(mtype=-2)
    finally:
        del os.environ["PYPARDISO_MKL_RT"]


def cholmod_available() -> bool:
    return _cholmod is not None


def pardiso_available() -> bool:
    return _pypardiso is not None


class PardisoTangent(TangentSolver):
    """MKL PARDISO's supernodal LDL^T with Bunch-Kaufman pivoting of the symmetric indefinite
    tangent (matrix type -2, through pypardiso's ctypes binding): the analysis (ordering, symbolic
    factor) once per pattern, a numeric factorisation per tangent, and the inertia PARDISO counts
    (iparm 22 / 23: positive / negative eigenvalues). Every solve is checked against the assembled
    matrix and refined (as ``"ldl"``). Threads: MKL's, which homtex limits to one where it limits
    BLAS (a small frame's engine step)."""

    name = "pardiso"
    gives_inertia = True

    def __init__(self, *, refine_tol: float = 1e-9, max_refine: int = 3):
        if _pypardiso is None:
            raise ImportError("tangent solver 'pardiso' needs pypardiso (MKL PARDISO): pip install pypardiso")
        super().__init__()
        self.refine_tol, self.max_refine = float(refine_tol), int(max_refine)
        self._ps = None
        self._csr = None
        self._pos = self._perm = None

    def _analyse(self, A) -> None:
        # PARDISO takes the upper triangle row by row with every diagonal entry stored: the CSR of
        # the stored CSC upper triangle plus the diagonal, its values gathered through a fixed
        # map at every factorisation
        n = A.shape[0]
        cols = np.repeat(np.arange(n), np.diff(A.indptr))
        order = sp.coo_matrix((np.r_[np.arange(1, A.nnz + 1, dtype=float), np.zeros(n)],
                               (np.r_[A.indices, np.arange(n)], np.r_[cols, np.arange(n)])), shape=A.shape).tocsr()
        order.sum_duplicates()
        order.sort_indices()
        self._pos = np.flatnonzero(order.data > 0)
        self._perm = order.data[self._pos].astype(np.int64) - 1
        self._csr = sp.csr_matrix((np.zeros(len(order.data)), order.indices, order.indptr), shape=A.shape)
        if self._ps is not None:
            self._ps.free_memory(everything=True)
        self._ia = (self._csr.indptr + 1).astype(np.int32)
        self._ja = (self._csr.indices + 1).astype(np.int32)
        ps = _pardiso_solver()
        ps._check_A(self._csr)
        # no refinement steps inside PARDISO's solve (pypardiso sets up to 2, each a triangular solve
        # and a product): every solve is refined here against the assembled matrix anyway
        ps.set_iparm(8, 0)
        self._ps = ps
        self._analysed = False

    def __del__(self):
        # PARDISO's factor lives in MKL's memory until phase -1: an engine that changes its contact
        # pattern drops hundreds of these (483 over the 43 mm seam's press)
        ps = getattr(self, "_ps", None)
        if ps is not None:
            with contextlib.suppress(Exception):
                ps.free_memory(everything=True)

    def _call(self, phase: int, b: np.ndarray) -> np.ndarray:
        # pypardiso's own call converts the index arrays to 1-based int32 at every call (two copies
        # of the pattern per factorisation and per solve); they are made once per pattern here
        ps, A = self._ps, self._csr
        b = np.asfortranarray(b, dtype=float)
        x = np.zeros_like(b)
        err = ctypes.c_int32(0)
        i32 = ctypes.POINTER(ctypes.c_int32)
        f64 = ctypes.POINTER(ctypes.c_double)
        ps._mkl_pardiso(ps.pt.ctypes.data_as(ctypes.POINTER(ps._pt_type[0])), ctypes.byref(ctypes.c_int32(1)),
                        ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(ps.mtype)),
                        ctypes.byref(ctypes.c_int32(phase)), ctypes.byref(ctypes.c_int32(A.shape[0])),
                        A.data.ctypes.data_as(f64), self._ia.ctypes.data_as(i32), self._ja.ctypes.data_as(i32),
                        ps.perm.ctypes.data_as(i32), ctypes.byref(ctypes.c_int32(b.shape[1])),
                        ps.iparm.ctypes.data_as(i32), ctypes.byref(ctypes.c_int32(ps.msglvl)),
                        b.ctypes.data_as(f64), x.ctypes.data_as(f64), ctypes.byref(err))
        if err.value != 0:
            raise SolverError(f"PARDISO phase {phase} failed with error {err.value}")
        return x

    def _factor(self, A, inertia: bool) -> None:
        self._csr.data[:] = 0.0
        self._csr.data[self._pos] = A.data[self._perm]
        zero = np.zeros((A.shape[0], 1))
        try:
            if not self._analysed:
                self._call(11, zero)
                self._analysed = True
            self._call(22, zero)
        except Exception as err:       # PARDISO's error codes (e.g. -4 zero pivot, -2 memory)
            raise SolverError(f"PARDISO factorisation failed: {err}") from err
        neg = int(self._ps.get_iparm(23))
        self.report.negative = neg
        self.report.positive_definite = neg == 0 and int(self._ps.get_iparm(22)) == A.shape[0]

    def _solve(self, b) -> np.ndarray:
        return self._refined(lambda v: self._call(33, v.reshape(-1, 1)).ravel(), np.asarray(b, dtype=float))[0]


class CholmodTangent(TangentSolver):
    """CHOLMOD supernodal LL^T of the full symmetric tangent (see the module docstring)."""

    name = "cholmod"
    gives_inertia = True

    def __init__(self, mode: str = "supernodal"):
        if _cholmod is None:
            raise ImportError("tangent solver 'cholmod' needs scikit-sparse (CHOLMOD): pip install scikit-sparse")
        super().__init__()
        self.mode = mode
        self._f = None
        self._ldl = None
        self._use_ldl = False

    def _analyse(self, A) -> None:
        # the structural pattern (values of ones): the matrix may still be all zeros here, and a
        # sum of sparse matrices drops zeros
        U = sp.csc_matrix((np.ones(A.nnz), A.indices, A.indptr), shape=A.shape)
        self._f = _cholmod.analyze((U + U.T).tocsc(), mode=self.mode)
        self._ldl = None

    def _factor(self, A, inertia: bool) -> None:
        full = self.view.full()
        self._use_ldl = False
        try:
            self._f.cholesky_inplace(full)
            self.report.negative = 0
            self.report.positive_definite = True
            return
        except _cholmod.CholmodNotPositiveDefiniteError:
            self.report.positive_definite = False
        if inertia:
            # the count of negative eigenvalues: qdldl (same pattern, own symbolic analysis)
            if self._ldl is None:
                self._ldl = QdldlTangent()
                self._ldl.analyse(A, self.view)
            self._ldl.factor(A, inertia=True)
            self.report.negative = self._ldl.negative
            self._use_ldl = True

    def _solve(self, b):
        if self._use_ldl:
            x = self._ldl.solve(b)
            self.report.refinements = self._ldl.report.refinements
            self.report.fallbacks = self._ldl.report.fallbacks
            return x
        if self.report.positive_definite is False:
            raise SolverError("CHOLMOD: the tangent is not positive definite (factor with inertia=True for an "
                              "LDL^T solve)")
        x = self._f(b)
        r = b - self.view.matvec(x)
        nb = float(np.linalg.norm(b))
        if nb > 0 and float(np.linalg.norm(r)) > 1e-9 * nb:
            self.report.refinements += 1
            x = x + self._f(r)
        return x


class ReuseRule:
    """When to rebuild an AMG hierarchy that preconditions a changed matrix.

    Reusing costs extra CG iterations; rebuilding costs a setup. With t_setup the measured setup
    time, t_it the measured time per iteration and n0 the iterations right after a rebuild, the
    hierarchy is rebuilt before the next solve once the iterations lost since then,
    sum(n_k - n0), exceed ``weight`` x t_setup / t_it (the break-even of the two costs; weight 1),
    or a solve needed more than ``max_ratio`` x n0 (a hierarchy far from its matrix), or the
    matrix's diagonal moved by more than ``max_diag_change`` (relative, max norm) from the
    one it was built for.
    """

    def __init__(self, weight: float = 1.0, max_ratio: float = 3.0, max_diag_change: float = 0.5):
        self.weight, self.max_ratio, self.max_diag_change = weight, max_ratio, max_diag_change
        self.reset(0.0)

    def reset(self, setup_seconds: float) -> None:
        self.setup_seconds = setup_seconds
        self.n0 = None
        self.lost = 0.0
        self.t_it = None
        self.last_ratio = 1.0

    def record(self, iterations: int, seconds: float) -> None:
        if iterations <= 0:
            return
        if self.n0 is None:
            self.n0 = iterations
        self.t_it = seconds / iterations
        self.lost += max(iterations - self.n0, 0)
        self.last_ratio = iterations / max(self.n0, 1)

    def rebuild(self, diag_change: float = 0.0) -> bool:
        if diag_change > self.max_diag_change:
            return True
        if self.n0 is None or self.t_it is None:
            return False
        if self.last_ratio > self.max_ratio:
            return True
        return self.lost * self.t_it > self.weight * self.setup_seconds


class AMGTangent(TangentSolver):
    """AMG-preconditioned CG on the positive definite tangent (see the module docstring).

    Parameters
    ----------
    nodes : (N, 3) node coordinates (the near-null space; plates and other extra nodes may be
        given any position). mask : (6N,) constrained DOFs (the free DOFs are ``~mask`` in order,
        as FreeSystem numbers them). tol : relative residual of each solve. probe : PCG iterations
        of the positive-definiteness test in ``factor`` (0: none, the tangent is assumed PD).
    rule : :class:`ReuseRule` for the hierarchy.
    """

    name = "amg"
    gives_inertia = False

    def __init__(self, nodes, mask, *, tol: float = 1e-10, maxiter: int = 2000, probe: int = 8,
                 rule: ReuseRule | None = None):
        super().__init__()
        self.nodes = np.asarray(nodes, dtype=float)
        self.mask = np.asarray(mask, dtype=bool)
        self.free = np.flatnonzero(~self.mask)
        self.tol, self.maxiter, self.probe = float(tol), int(maxiter), int(probe)
        self.rule = rule or ReuseRule()
        self.hierarchy = None
        self.builds = 0
        self._diag0 = None
        self.K6 = None

    def _embed(self, A) -> sp.bsr_matrix:
        """The 6N x 6N BSR matrix with the free block A (full symmetric) and identity rows on the
        constrained DOFs (scaled to the mean free diagonal)."""
        full = self.view.full().tocoo()
        n6 = self.mask.size
        f = self.free
        d = full.diagonal()
        dm = float(np.mean(np.abs(d))) if d.size else 1.0
        c = np.flatnonzero(self.mask)
        rows = np.concatenate([f[full.row], c])
        cols = np.concatenate([f[full.col], c])
        vals = np.concatenate([full.data, np.full(c.size, dm)])
        M = sp.csr_matrix((vals, (rows, cols)), shape=(n6, n6))
        return sp.bsr_matrix(M, blocksize=(6, 6))

    def _analyse(self, A) -> None:
        self.hierarchy = None
        self._diag0 = None

    def _factor(self, A, inertia: bool) -> None:
        from .amg import ScaledAMG
        from .nullspace import rigid_body_modes
        from .parallel_amg import BSROperator, VCycle, pcg

        d = A.diagonal()
        if np.any(d <= 0.0):              # a non-positive diagonal entry proves indefiniteness
            self.report.positive_definite = False
            self.report.negative = None
            self.K6 = None
            return
        K6 = self._embed(A)
        change = 0.0 if self._diag0 is None else float(np.max(np.abs(d - self._diag0)) /
                                                       max(np.max(np.abs(self._diag0)), 1e-300))
        if self.hierarchy is None or self.rule.rebuild(change):
            t0 = time.perf_counter()
            self.hierarchy = ScaledAMG(K6, rigid_body_modes(self.nodes[: self.mask.size // 6]))
            self.vcycle = VCycle(self.hierarchy)
            self.rule.reset(time.perf_counter() - t0)
            self._diag0 = d.copy()
            self.builds += 1
        self.K6 = BSROperator(K6)
        self.report.method = f"amg ({self.builds} hierarchies)"
        if self.probe > 0:
            rng = np.random.default_rng(12345)
            b = rng.standard_normal(self.mask.size)
            b[self.mask] = 0.0
            try:
                pcg(self.K6, b, self.vcycle, tol=1e-30, maxiter=self.probe)
                self.report.positive_definite = True
                self.report.negative = 0
            except SolverError:
                self.report.positive_definite = False
                self.report.negative = None
        else:
            self.report.positive_definite = True
            self.report.negative = 0

    def _solve(self, b):
        from .parallel_amg import pcg

        if self.K6 is None:
            raise SolverError("AMG-CG tangent solve: the tangent is not positive definite (a PTC shift or "
                              "tangent_solver='ldl' is needed)")
        bf = np.zeros(self.mask.size)
        bf[self.free] = b
        nb = float(np.linalg.norm(b))
        if nb == 0.0:
            return np.zeros_like(b)
        t0 = time.perf_counter()
        x, hist = pcg(self.K6, bf, self.vcycle, tol=self.tol, maxiter=self.maxiter)
        its = len(hist) - 1
        self.report.iterations += its
        self.rule.record(its, time.perf_counter() - t0)
        xf = x[self.free]
        res = float(np.linalg.norm(b - self.view.matvec(xf))) / nb
        if not res <= max(10 * self.tol, 1e-8):
            raise SolverError(f"AMG-CG tangent solve missed its tolerance: relative residual {res:.2e} after "
                              f"{its} iterations", history=hist)
        return xf


def auto_tangent_solver(nf: int, nodes=None, mask=None) -> TangentSolver:
    """The rule of option ``tangent_auto_dof`` (see the module docstring)."""
    from ..config import option

    if nf >= option("tangent_auto_dof") and cholmod_available():
        return CholmodTangent()
    return QdldlTangent()


register_tangent_solver("cholmod", CholmodTangent)
register_tangent_solver("amg", AMGTangent)
register_tangent_solver("pardiso", PardisoTangent)
